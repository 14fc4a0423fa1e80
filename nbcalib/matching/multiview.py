"""Match the camera image against several camera-shaped LiDAR views and keep the one that fits.

The matchers need the LiDAR image in the camera's geometry and scale (:mod:`nbcalib.matching.
views`). Without a prior the camera may look anywhere around a spinning LiDAR, so the dense
cloud is rendered through the (scaled) real camera at ``views`` level headings, evenly
spaced about LiDAR z (12 views 30 degrees apart overlap for any camera wider than 30 degrees);
with a prior ``T_camera_lidar`` a few views around its orientation replace them. Views that
show almost nothing (a Livox's back side) are skipped.

Each view is matched with the camera image (:func:`nbcalib.matching.match_images`), its
keypoints are lifted through the view's own index map (nearest filled pixel within
``search_radius``), and rotation-only RANSAC (:func:`~nbcalib.initial_guess.ransac.
estimate_rotation_ransac`) counts the view's support. A learned matcher's attention costs about
a second a view; with ``screen_views`` (default 4) every view is first matched by its
descriptors' mutual nearest neighbours (a tenth of that), and the matcher runs on the
``screen_views`` views with the most RANSAC support of that screen, and on the views whose
screened rotation agrees with the first's (the views the pool will keep), only. The camera
image's features are extracted once for all views. The view with the most RANSAC inliers
wins; the views whose own RANSAC rotation agrees with the winner's (within ``pool_angle_deg``)
add their correspondences (``pool=True``): overlapping views see the same structures at other
places of their images. With ``refine=True`` the pose those correspondences give is estimated,
and one more view is rendered from it (its rotation *and* camera position, so the view has the
camera image's geometry up to the guess's error, without parallax) and matched; its
correspondences are added.

:func:`match_views` returns the per-view record (for the benchmark and the pictures) and the
selected correspondences, ready for :func:`~nbcalib.initial_guess.estimate.
estimate_initial_guess`.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.initial_guess.config import InitialGuessConfig
from nbcalib.matching.config import MatchConfig
from nbcalib.matching.correspondences import (
    Correspondences,
    lift_matches,
    pool_correspondences,
)
from nbcalib.transforms import rotation_angle_deg

__all__ = ["MultiViewMatches", "ViewMatches", "match_views"]


@dataclass(frozen=True)
class ViewMatches:
    """One view's matches, correspondences and RANSAC support.

    Attributes
    ----------
    view : LidarView
        The rendered view.
    matches : Matches
        Camera keypoints (original camera pixels) and view keypoints (view pixels).
    correspondences : Correspondences
        The matches lifted through the view's index map.
    R_camera_lidar : ndarray of shape (3, 3), float64 or None
        The view's RANSAC rotation (None with fewer than 3 correspondences).
    ransac_inliers : int
        Its RANSAC support (0 without).
    screened : bool
        Matched only by the sweep's screen (descriptors' mutual nearest neighbours,
        ``MatchConfig.screen_views``): its numbers rank the views, its correspondences are
        never kept.
    """

    view: object
    matches: object
    correspondences: Correspondences
    R_camera_lidar: np.ndarray | None
    ransac_inliers: int
    screened: bool = False


@dataclass(frozen=True)
class MultiViewMatches:
    """What :func:`match_views` found.

    Attributes
    ----------
    views : list of ViewMatches
        Every rendered (non-empty) view, in heading order.
    best : int
        Index of the winning view in ``views`` (-1 when no view had correspondences).
    pooled : tuple of int
        Views whose correspondences were kept (the best first).
    correspondences : Correspondences
        The kept correspondences (``names`` = the data name; ``pair`` all 0).
    seconds : float
        Wall time of rendering, matching and RANSAC.
    """

    views: list[ViewMatches]
    best: int
    pooled: tuple[int, ...]
    correspondences: Correspondences
    seconds: float

    def summary(self) -> str:
        """One line per view: heading, fill, matches, lifted, RANSAC inliers; the winner marked."""
        lines = []
        for k, v in enumerate(self.views):
            mark = " <- best" if k == self.best else (" (pooled)" if k in self.pooled else "")
            if v.screened:
                mark = " (screened out)"
            lines.append(
                f"view {k:2d} heading {v.view.heading_deg:7.1f} deg, fill "
                f"{v.view.fill_fraction:4.2f}: {v.matches.num_matches:4d} matches, "
                f"{len(v.correspondences):4d} lifted, RANSAC inliers {v.ransac_inliers:4d}{mark}"
            )
        return "\n".join(lines)


def _view_matches(
    camera,
    image,
    view,
    points,
    config,
    model_dir,
    search_radius,
    name,
    ransac_threshold,
    seed,
    *,
    screen=False,
    cache=None,
    origin=None,
) -> ViewMatches:
    """Match one view, lift its keypoints, count its rotation-only RANSAC support.

    ``screen``: by the descriptors' mutual nearest neighbours (:func:`~nbcalib.matching.match.
    match_images`); ``cache``: the camera image's features, shared by the views; ``origin``:
    the LiDAR's position in the cloud's frame, where RANSAC takes the camera to be.
    """
    from nbcalib.errors import InputError
    from nbcalib.initial_guess.ransac import estimate_rotation_ransac
    from nbcalib.matching.match import match_images

    m = match_images(
        image,
        view.intensity,
        config,
        camera_scale=view.scale,
        lidar_fill_radius=0,  # the view is filled already, with its index map
        model_dir=model_dir,
        screen=screen,
        cache=cache,
    )
    uv_c, uv_v, conf = m.matched()
    corr = lift_matches(
        uv_c, uv_v, view.index, points, search_radius=search_radius, name=name, confidence=conf
    )
    R_best, support = None, 0
    if len(corr) >= 3:
        try:
            ransac = estimate_rotation_ransac(
                camera,
                corr.uv_camera,
                corr.points_lidar if origin is None else corr.points_lidar - origin,
                iterations=config.view_ransac_iterations,
                threshold=ransac_threshold,
                seed=seed,
            )
            R_best, support = ransac.R_camera_lidar, ransac.n_inliers
        except InputError:  # too few usable correspondences
            pass
    return ViewMatches(view, m, corr, R_best, support, screened=bool(m.info.get("screen")))


def _screened_choice(results: list[ViewMatches], cfg: MatchConfig) -> set[int]:
    """The screened views the learned matcher then runs on.

    The ``screen_views`` with the most RANSAC support of the screen, and every view whose own
    RANSAC rotation agrees with the first's as the pool asks (``pool_angle_deg``,
    ``min_pool_support``): the views the pool will keep. A camera that sees all around (an
    equirectangular one) agrees in every view: pooling four of its twelve left too few
    correspondences for a precise guess, one synthetic guess of 35 refused (docs/BENCHMARKS.md
    10).
    """
    ranked = sorted(range(len(results)), key=lambda k: -results[k].ransac_inliers)
    chosen = set(ranked[: cfg.screen_views])
    if ranked:
        chosen.update(_agreeing(results, ranked[0], cfg))
    if cfg.matched_views > 0:  # the best supported of them only
        chosen = set([k for k in ranked if k in chosen][: cfg.matched_views])
    return chosen


def _agreeing(results: list[ViewMatches], first: int, cfg: MatchConfig) -> list[int]:
    """The views other than ``first`` whose RANSAC rotation agrees with its rotation.

    The pool's rule: within ``pool_angle_deg``, with ``min_pool_support`` inliers at least;
    none when ``pool`` is off or ``first`` has no rotation.
    """
    R0 = results[first].R_camera_lidar
    if not cfg.pool or R0 is None:
        return []
    return [
        k
        for k, v in enumerate(results)
        if k != first
        and v.R_camera_lidar is not None
        and v.ransac_inliers >= cfg.min_pool_support
        and rotation_angle_deg(R0.T @ v.R_camera_lidar) < cfg.pool_angle_deg
    ]


def _refined_view(camera, corr, guess_config, seed, render, match, origin=None):
    """One more view rendered from the pose the kept correspondences give (None if none).

    ``render(R_vcam_lidar, t_vcam_lidar)`` and ``match(view, fine)`` are :func:`match_views`'s
    own rendering and matching, with its settings (``fine``: at ``fine_max_keypoints``).
    Returns a :class:`ViewMatches` or None.
    """
    from nbcalib.errors import InputError
    from nbcalib.initial_guess.estimate import estimate_initial_guess

    try:
        guess = estimate_initial_guess(
            camera,
            corr.uv_camera,
            corr.points_lidar,
            guess_config,
            weights=corr.weights,
            seed=seed,
            origin=origin,
        )
    except InputError:
        return None
    # the view is rendered from a roughly right pose to make the matches precise: a found pose
    # is enough, the precision test is for fine registration's start
    if not guess.found:
        return None
    T = guess.T_camera_lidar
    return match(render(T[:3, :3], T[:3, 3]), fine=True)


def match_views(
    camera: CameraModel,
    camera_image: np.ndarray,
    points_lidar,
    intensities,
    config: MatchConfig | None = None,
    *,
    guess_config: InitialGuessConfig | None = None,
    T_camera_lidar_prior=None,
    seed: int = 0,
    name: str = "",
    model_dir: str | os.PathLike | None = None,
    progress=None,
    origin=None,
    **overrides,
) -> MultiViewMatches:
    """Match the camera image with camera-shaped LiDAR views (module docstring).

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    camera_image : ndarray of shape (H, W), uint8
        Its grey image (equalised, as stored by preprocessing).
    points_lidar : array_like of shape (N, 3)
        Dense cloud, LiDAR frame, metres.
    intensities : array_like of shape (N,)
        Equalised intensities in [0, 1].
    config : MatchConfig, optional
        The matcher and its settings, and those of the views (``views`` headings,
        ``prior_yaw_offsets_deg``, ``pixels_per_degree``, ``min_fill``, ``fill_radius``,
        ``splat_pixels_at_1m``, ``median``, ``search_radius``, ``view_ransac_iterations``,
        ``pool``, ``pool_angle_deg``, ``min_pool_support``, ``refine_view``: documented there).
    guess_config : InitialGuessConfig, optional
        The initial guess's settings: its ``ransac_threshold`` scores the views, and the pose
        of the refined view (``config.refine_view``) is estimated with them.
    T_camera_lidar_prior : array_like of shape (4, 4), optional
        A rough extrinsic: views at its orientation turned by ``prior_yaw_offsets_deg`` instead
        of the heading sweep.
    seed : int, optional
        RANSAC seed.
    name : str, optional
        Data name recorded in the correspondences.
    model_dir : str or os.PathLike, optional
        Exported models.
    progress : callable, optional
        Called as ``progress(done, total)`` after each heading (rendered, and matched unless
        it shows too little), then after each view the screen sends to the matcher.
    origin : array_like of shape (3,), optional
        The LiDAR's position in the cloud's frame (:mod:`nbcalib.preprocess.origin`; default:
        the cloud's origin): the heading views are rendered from there, and rotation-only
        RANSAC takes the camera to be there.
    **overrides
        Attributes of :class:`MatchConfig` to change for this call.

    Returns
    -------
    MultiViewMatches
    """
    from nbcalib.matching.match import pixels_per_radian, resolve_matcher
    from nbcalib.matching.views import (
        DEFAULT_PIXELS_PER_DEGREE,
        heading_rotations,
        prior_rotations,
        render_view,
        view_scale,
    )

    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    image = np.asarray(camera_image)
    if image.shape != (camera.height, camera.width) or image.dtype != np.uint8:
        raise ValueError(
            f"camera_image must be ({camera.height}, {camera.width}) uint8, "
            f"got {image.dtype} {image.shape}"
        )
    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    values = np.ascontiguousarray(intensities, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or values.shape != (len(points),):
        raise ValueError(
            f"points_lidar (N, 3) and intensities (N,) expected, got {points.shape}, {values.shape}"
        )
    t0 = time.perf_counter()
    cfg = replace(config or MatchConfig(), **overrides)
    cfg = replace(cfg, matcher=resolve_matcher(cfg.matcher, model_dir))
    guess_config = guess_config or InitialGuessConfig()
    # the views' index maps are not hole-filled: reach the nearest point across a filled hole
    search_radius = max(float(cfg.search_radius), float(cfg.fill_radius))
    ppd = cfg.pixels_per_degree or DEFAULT_PIXELS_PER_DEGREE
    scale = view_scale(camera, ppd)
    # the coverage gaps to inpaint, in view pixels (odd); the views have min(ppd, camera's)
    view_ppd = pixels_per_radian(camera) * scale * math.pi / 180.0
    inpaint = 2 * round(cfg.inpaint_deg * view_ppd / 2) + 1 if cfg.inpaint_deg > 0 else 0
    if inpaint and cfg.lift_inpainted:
        search_radius = max(search_radius, inpaint / 2)
    o = None if origin is None else np.asarray(origin, dtype=np.float64)
    o = o if o is not None and o.any() else None  # the cloud's own origin: as without one
    translations = None
    if T_camera_lidar_prior is not None:
        T_prior = np.asarray(T_camera_lidar_prior, dtype=np.float64)
        if T_prior.shape != (4, 4) or not np.all(np.isfinite(T_prior)):
            raise ValueError("T_camera_lidar_prior must be a finite 4 x 4 matrix")
        rotations = prior_rotations(T_prior[:3, :3], cfg.prior_yaw_offsets_deg)
        # the prior's own view is rendered from the prior camera position
        translations = [T_prior[:3, 3] if off == 0.0 else None for off in cfg.prior_yaw_offsets_deg]
    else:
        rotations = heading_rotations(cfg.views)
    if o is not None:  # the other views from the LiDAR: p_vcam = R (p - o)
        translations = translations or [None] * len(rotations)
        translations = [-R @ o if t is None else t for R, t in zip(rotations, translations)]

    def render(R, t=None):
        return render_view(
            camera,
            R,
            points,
            values,
            scale=scale,
            t_vcam_lidar=t,
            fill_radius=cfg.fill_radius,
            splat_pixels_at_1m=cfg.splat_pixels_at_1m,
            median=cfg.median,
            inpaint=inpaint,
        )

    fine_cfg = replace(cfg, max_keypoints=cfg.fine_max_keypoints)

    cache: dict = {}  # the camera image's features, extracted once for every view

    def match(view, fine=False, screen=False):
        return _view_matches(
            camera,
            image,
            view,
            points,
            fine_cfg if fine else cfg,
            model_dir,
            search_radius,
            name,
            guess_config.ransac_threshold,
            seed,
            screen=screen,
            cache=cache,
            origin=o,
        )

    screen = cfg.screen_views > 0 and len(rotations) > cfg.screen_views and cfg.matcher != "sift"
    total = len(rotations) + (cfg.screen_views if screen else 0)
    results: list[ViewMatches] = []
    for k, R in enumerate(rotations):
        view = render(R, None if translations is None else translations[k])
        if view.fill_fraction >= cfg.min_fill:
            results.append(match(view, screen=screen))
        if progress is not None:
            progress(k + 1, total)
    if screen:  # the matcher on the views the screen ranks first, and on those agreeing
        chosen = sorted(_screened_choice(results, cfg))
        for n, k in enumerate(chosen):
            results[k] = match(results[k].view)
            if progress is not None:
                progress(len(rotations) + n + 1, len(rotations) + len(chosen))
    matched = [k for k, v in enumerate(results) if not v.screened]
    best = -1
    if matched:
        best = max(matched, key=lambda k: results[k].ransac_inliers)  # the first of equals
        if results[best].ransac_inliers == 0 and len(results[best].correspondences) == 0:
            best = -1
    pooled: tuple[int, ...] = ()
    if best >= 0:
        # the views the pool keeps: those agreeing with the best, matched in full
        keep = [best, *(k for k in _agreeing(results, best, cfg) if not results[k].screened)]
        pooled = tuple(keep)
        corr = pool_correspondences([results[k].correspondences for k in keep])
        if cfg.refine_view:
            extra = _refined_view(camera, corr, guess_config, seed, render, match, o)
            if extra is not None:
                results.append(extra)
                pooled = (*pooled, len(results) - 1)
                corr = pool_correspondences([corr, extra.correspondences])
    else:
        corr = Correspondences.empty([name])
    return MultiViewMatches(results, best, pooled, corr, time.perf_counter() - t0)
