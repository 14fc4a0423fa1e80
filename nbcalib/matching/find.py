"""The matching stage: 2D-3D correspondences between a camera image and its dense cloud.

:func:`find_correspondences` is what ``nbcalib find-matches``, ``nbcalib run`` and
:func:`nbcalib.calibrate` run for each pair (paper section III-D, first step):

- ``views > 0`` (default): the camera image is matched against camera-shaped LiDAR views, the
  dense cloud rendered through the real camera's model (:mod:`nbcalib.matching.multiview`);
  each view's keypoints are lifted through its own index map, so the matches *are* 2D-3D
  correspondences;
- ``views == 0``: the reference toolbox's way, the camera image against the stored LiDAR image
  of the virtual camera, its keypoints lifted through the stored index map.

Either way the result is a :class:`PairMatches`: the correspondences, and the same matches as
the reference toolbox's ``<name>_matches.json`` holds them (:func:`reference_matches`), whose
LiDAR keypoints are the integer pixels of the stored index map that show each point, so that
the reference's ``initial_guess_auto`` (which truncates keypoints to pixels and reads the index
map there) finds exactly these points.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.matching.config import MatchConfig
from nbcalib.matching.correspondences import Correspondences, correspondences_from_matches
from nbcalib.matching.matches import Matches

__all__ = [
    "PairMatches",
    "find_correspondences",
    "reference_matches",
    "unmatched_pair",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PairMatches:
    """What matching found for one pair.

    Attributes
    ----------
    name : str
        The pair's data name.
    correspondences : Correspondences
        Camera pixels and the cloud rows / 3-D points they match.
    matches : Matches
        The same as keypoint matches against the stored LiDAR image (``<name>_matches.json``,
        :func:`reference_matches`).
    matcher : str
        The matcher that ran.
    views : MultiViewMatches or None
        The per-view record with ``views > 0``.
    seconds : float
        Wall time.
    attempts : tuple of dict
        With views: each attempt's resolution, inpainting, correspondences and whether their
        guess passed (``MatchConfig.retry_pixels_per_degree``).
    kept_attempt : int or None
        The attempt whose correspondences were kept.
    """

    name: str
    correspondences: Correspondences
    matches: Matches
    matcher: str
    views: object = None
    seconds: float = 0.0
    attempts: tuple = ()
    kept_attempt: int | None = None

    @property
    def matched(self) -> bool:
        """False for a pair left unmatched (:func:`unmatched_pair`)."""
        return self.matches.info.get("mode") != "skipped"

    def summary(self) -> str:
        """One line: what was matched and kept."""
        corr = self.correspondences
        if not self.matched:
            return f"{self.name}: not matched ({self.matches.info.get('reason', '')})"
        if self.views is not None:
            mv = self.views
            best = mv.views[mv.best] if mv.best >= 0 else None
            heading = "n/a" if best is None else f"{best.view.heading_deg:.0f} deg"
            inliers = 0 if best is None else best.ransac_inliers
            retried = ""
            if len(self.attempts) > 1 and self.kept_attempt is not None:
                kept = self.attempts[self.kept_attempt]
                if self.kept_attempt:
                    retried = (
                        f", retry {self.kept_attempt}: {kept['pixels_per_degree']:g} px/deg, "
                        f"inpainted {kept['inpaint_deg']:g} deg"
                    )
                else:
                    retried = f", first of {len(self.attempts)} attempts"
            return (
                f"{self.name}: {len(mv.views)} views, best heading {heading} (RANSAC inliers "
                f"{inliers}), {len(corr)} correspondences kept ({self.matcher}, "
                f"{self.seconds:.1f} s{retried})"
            )
        return (
            f"{self.name}: {corr.n_matches} matches, {len(corr)} lifted to 3-D points "
            f"({self.matcher}, {self.seconds:.1f} s)"
        )


def reference_matches(
    corr: Correspondences, index_map, *, matcher: str = "", info: dict | None = None
) -> Matches:
    """Correspondences as keypoint matches of the stored LiDAR image (reference file format).

    Each correspondence's LiDAR keypoint is the pixel ``(u, v)`` (integers) of ``index_map``
    that holds its cloud row, so that a reader that truncates the keypoint and looks the index
    map up there (the reference's ``initial_guess_auto``) finds exactly that point.
    Correspondences whose point the LiDAR image does not show (hidden behind a nearer point,
    outside the virtual camera, or an explicit 3-D point) are left out (they stay in nbcalib's
    ``<name>_correspondences.json``).

    Parameters
    ----------
    corr : Correspondences
        One pair's correspondences.
    index_map : ndarray of shape (H, W), int32
        The stored LiDAR image's index map (-1 empty).
    matcher : str, optional
        Recorded in the file.
    info : dict, optional
        Recorded under ``nbcalib`` in the file.

    Returns
    -------
    Matches
        One LiDAR keypoint per kept correspondence, matched in order.
    """
    index = np.asarray(index_map)
    flat = index.reshape(-1)
    filled = np.flatnonzero(flat >= 0)
    rows = np.asarray(corr.point_index, dtype=np.int64)
    size = int(max(flat.max(initial=-1), rows.max(initial=-1))) + 1
    pixel_of = np.full(size, -1, dtype=np.int64)
    pixel_of[flat[filled]] = filled
    pixel = np.where(rows >= 0, pixel_of[np.clip(rows, 0, None)], -1) if size else rows
    keep = pixel >= 0
    v, u = np.divmod(pixel[keep], index.shape[1])
    n = int(np.count_nonzero(keep))
    confidence = corr.weights[keep] if corr.confidence is not None else np.ones(n)
    return Matches(
        corr.uv_camera[keep],
        np.column_stack([u, v]).astype(np.float64),
        np.arange(n, dtype=np.int64),
        confidence,
        matcher=matcher,
        info=dict(info or {}),
    )


def find_correspondences(
    camera: CameraModel,
    pair,
    config: MatchConfig | None = None,
    *,
    guess_config=None,
    virtual_camera=None,
    T_camera_lidar_prior=None,
    seed: int = 0,
    model_dir: str | os.PathLike | None = None,
    progress: bool = False,
) -> PairMatches:
    """Match one pair's camera image with its LiDAR data (module docstring).

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    pair : PairData
        The pair after preprocessing and rendering (:mod:`nbcalib.products`).
    config : MatchConfig, optional
        Matcher and views.
    guess_config : InitialGuessConfig, optional
        Its ``ransac_threshold`` scores the views (:func:`~nbcalib.matching.multiview.
        match_views`).
    virtual_camera : VirtualCamera, optional
        The camera of the stored LiDAR image: with ``views == 0`` its resolution sets the
        camera image's scale (else ``config.camera_scale``, else 1, with a warning); its
        position is the LiDAR's origin, from which the views are rendered
        (:attr:`nbcalib.products.VirtualCamera.origin`).
    T_camera_lidar_prior : array_like of shape (4, 4), optional
        A rough extrinsic: views around it instead of the heading sweep.
    seed : int, optional
        RANSAC seed of the views.
    model_dir : str or os.PathLike, optional
        Exported models.
    progress : bool, optional
        Show the views matched (:class:`nbcalib.progress.Progress`).

    Returns
    -------
    PairMatches
    """
    from nbcalib.matching.match import camera_scale_for, match_images, resolve_matcher
    from nbcalib.matching.multiview import match_views
    from nbcalib.progress import Progress

    cfg = config or MatchConfig()
    t0 = time.perf_counter()
    matcher = resolve_matcher(cfg.matcher, model_dir)
    origin = None if virtual_camera is None else virtual_camera.origin
    views = None
    attempts = []
    if cfg.views > 0 or T_camera_lidar_prior is not None:
        # the views as configured, then finer inpainted ones until a guess passes its test
        settings = [cfg] + [
            replace(
                cfg,
                pixels_per_degree=ppd,
                inpaint_deg=cfg.retry_inpaint_deg,
                max_keypoints=cfg.fine_max_keypoints,
            )
            for ppd in cfg.retry_pixels_per_degree
        ]
        best = None
        with Progress(label=f"find-matches {pair.name}", enabled=progress) as display:
            for i, attempt in enumerate(settings):
                offset = display.done

                def view_done(k, n, i=i, offset=offset):
                    display.total = offset + n  # a retry's views are added as it starts
                    display.update(what=f"views (attempt {i + 1})")

                found = match_views(
                    camera,
                    pair.image,
                    pair.points_lidar,
                    pair.intensities,
                    attempt,
                    matcher=matcher,
                    guess_config=guess_config,
                    T_camera_lidar_prior=T_camera_lidar_prior,
                    seed=seed,
                    name=pair.name,
                    model_dir=model_dir,
                    progress=view_done,
                    origin=origin,
                )
                ok, support = _guess_passes(
                    camera, found.correspondences, guess_config, seed, origin
                )
                attempts.append(
                    {
                        "pixels_per_degree": attempt.pixels_per_degree,
                        "inpaint_deg": attempt.inpaint_deg,
                        "max_keypoints": attempt.max_keypoints,
                        "correspondences": len(found.correspondences),
                        "guess_ok": ok,
                        "support": support,
                    }
                )
                if best is None or (ok, support) > best[0]:
                    best = ((ok, support), len(attempts) - 1, found)
                if ok:
                    break
        _, kept, views = best
        corr = views.correspondences
        info = {
            "mode": "views",
            "attempts": attempts,
            "kept_attempt": kept,
            "views": [
                {
                    "heading_deg": round(v.view.heading_deg, 2),
                    "matches": v.matches.num_matches,
                    "lifted": len(v.correspondences),
                    "ransac_inliers": v.ransac_inliers,
                    "screened": v.screened,
                }
                for v in views.views
            ],
            "best_view": views.best,
            "pooled_views": list(views.pooled),
        }
    else:
        scale = cfg.camera_scale
        if scale is None and virtual_camera is not None:
            scale = camera_scale_for(camera, virtual_camera.camera)
        elif scale is None:
            log.warning(
                "%s: the camera of the stored LiDAR image is unknown: matching it with the "
                "camera image at its own scale (matching.camera_scale sets one)",
                pair.name,
            )
        m = match_images(
            pair.image,
            pair.lidar_image.intensity,
            cfg,
            matcher=matcher,
            camera_scale=scale,
            model_dir=model_dir,
        )
        corr = correspondences_from_matches(
            m, pair.lidar_index, pair.points_lidar, search_radius=cfg.search_radius, name=pair.name
        )
        info = {"mode": "lidar_image", **m.info}
    seconds = time.perf_counter() - t0
    info["seconds"] = round(seconds, 3)
    matches = reference_matches(corr, pair.lidar_index, matcher=matcher, info=info)
    kept = info.get("kept_attempt")
    return PairMatches(
        pair.name,
        corr,
        matches,
        matcher,
        views,
        seconds,
        tuple(attempts),
        kept,
    )


def unmatched_pair(pair, matcher: str, reason: str) -> PairMatches:
    """The record of a pair that was not matched: no correspondences, ``reason`` in its info.

    The frames of a recording are matched until a few agree (:mod:`nbcalib.matching.
    recording`, ``MatchConfig.guess_pairs``); the rest keep empty matching products, so that
    the work directory is complete (the reference toolbox's ``initial_guess_auto`` reads a
    matches file per pair) and says why they are empty.
    """
    corr = Correspondences.empty([pair.name])
    info = {"mode": "skipped", "reason": reason, "seconds": 0.0}
    matches = reference_matches(corr, pair.lidar_index, matcher=matcher, info=info)
    return PairMatches(pair.name, corr, matches, matcher)


def _guess_passes(camera, corr: Correspondences, guess_config, seed: int, origin=None):
    """(found the pose, support) of the initial guess from one pair's matches."""
    from nbcalib.initial_guess.config import InitialGuessConfig
    from nbcalib.initial_guess.estimate import MIN_CORRESPONDENCES, estimate_initial_guess

    cfg = guess_config or InitialGuessConfig()
    if len(corr) < MIN_CORRESPONDENCES:
        return False, 0
    guess = estimate_initial_guess(
        camera,
        corr.uv_camera,
        corr.points_lidar,
        cfg,
        seed=seed,
        weights=corr.weights if cfg.confidence_weights else None,
        origin=origin,
    )
    # did this attempt find the pose? (precision is the initial-guess stage's test)
    return bool(guess.found), int(guess.support)
