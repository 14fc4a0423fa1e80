"""The guess from many frames of one recording: screen them all, let them vote, match a few.

Every frame of a recording shares one extrinsic, and one frame's matches rarely show it alone:
a single real scan against a photograph gives a few correct matches among hundreds
(docs/BENCHMARKS.md 4), and matching each frame on its own, with retries at finer inpainted
views until it passes its own test, took 36 s a frame on ten KITTI frames and still failed on
most recordings (issue 45). The frames' evidence adds up only where they agree, so
:func:`match_recording` lets them agree first:

1. **Screen** (:func:`screen_frame`): every frame's camera-shaped views at ``views`` level
   headings, matched by the XFeat descriptors' mutual nearest neighbours (a tenth of
   LighterGlue's cost), each view scored by rotation-only RANSAC; at the finer, inpainted views
   (``frames_pixels_per_degree``, ``frames_inpaint_deg``) that sparse real scans need.
2. **Vote** (:func:`vote_rotations`): every screened view's rotation is a hypothesis, scored by
   the screened correspondences of *all* frames it explains. Wrong matches scatter over
   rotations, right ones pile up on one: on 13 KITTI odometry frames the best-supported
   rotations lie within 1.5 degrees of KITTI's calibration while each frame's own best view
   was right in 5 of 13.
3. **Match** the frames in the order of their support for the winner, each with the learned
   matcher on one view at the voted rotation (seen from the LiDAR, :attr:`~nbcalib.products.
   VirtualCamera.origin`), pool their correspondences and estimate the pose after each: stop
   once the pooled pose is found (:attr:`~nbcalib.initial_guess.InitialGuess.found`) and
   ``guess_pairs`` frames agree with it (``min_pool_support`` inliers each). When the frames
   of the vote's winner find no pose, its runner-up (a rotation at least
   :data:`VOTE_SEPARATION_DEG` away) is tried.
4. **Refine**: every matched frame is matched once more on a view rendered from the pooled pose
   (its rotation and camera position: the camera image's own geometry up to the pose's error),
   and those correspondences join the frame's.

The frames not matched keep empty matching products that say why (:func:`~nbcalib.matching.
find.unmatched_pair`). Precision is the initial-guess stage's business, not this one's.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.matching.config import MatchConfig
from nbcalib.matching.correspondences import Correspondences, pool_correspondences
from nbcalib.transforms import make_T, rotation_angle_deg

__all__ = [
    "VOTE_SEPARATION_DEG",
    "RecordingMatches",
    "RotationVote",
    "attempt_settings",
    "match_recording",
    "screen_frame",
    "vote_rotations",
]

log = logging.getLogger(__name__)

#: Candidates of the vote are at least this far apart, degrees (the views are 30 apart).
VOTE_SEPARATION_DEG = 10.0
#: Candidates of the vote tried in turn when the frames of one find no pose.
VOTE_CANDIDATES = 2
#: A screened view needs this many RANSAC inliers for its rotation to be a hypothesis.
_MIN_HYPOTHESIS_SUPPORT = 4


@dataclass(frozen=True)
class RotationVote:
    """One rotation the frames voted for.

    Attributes
    ----------
    R_camera_lidar : ndarray of shape (3, 3)
        The hypothesis (a screened view's RANSAC rotation), the camera taken to be at the
        LiDAR.
    support : int
        Screened correspondences of all frames it explains (rotation-only, within the RANSAC
        threshold).
    per_frame : tuple of int
        Those of each frame.
    """

    R_camera_lidar: np.ndarray
    support: int
    per_frame: tuple[int, ...]


@dataclass(frozen=True)
class RecordingMatches:
    """What :func:`match_recording` found.

    Attributes
    ----------
    found : dict of str to PairMatches
        Every matched frame's matches, by pair name (the others are absent).
    votes : list of RotationVote
        The vote's candidates, best first.
    tried : int
        Candidates tried.
    guess : InitialGuess or None
        The pooled pose of the matched frames' correspondences (before the refined views).
    agreeing : list of str
        Frames with ``min_pool_support`` inliers under it.
    seconds : dict of str to float
        Wall time of the screen, the matching and the refined views.
    screened : int
        Frames screened before the vote was clear.
    attempt : int
        Which of :func:`attempt_settings` it is.
    """

    found: dict
    votes: list
    tried: int
    guess: object
    agreeing: list
    seconds: dict
    screened: int = 0
    attempt: int = 0

    def rank(self) -> tuple:
        """Better attempts rank higher: a pose found, then its support."""
        if self.guess is None:
            return (False, 0)
        return (bool(self.guess.found), int(self.guess.support))

    def summary(self) -> str:
        """One line: the vote, the frames matched and how many agree."""
        if not self.votes:
            return "the screen found no rotation the frames share"
        top = self.votes[0]
        other = self.votes[1].support if len(self.votes) > 1 else 0
        n = len(self.found)
        agree = f"{len(self.agreeing)} of {n} matched frames agree on the pose"
        if self.guess is None or not self.guess.found:
            agree = f"the {n} matched frames found no pose they agree on"
        if not self.screened:
            return f"views at the prior; {agree}"
        return (
            f"{self.screened} frames screened vote for a rotation ({top.support} correspondences "
            f"explained, the best other {VOTE_SEPARATION_DEG:g}+ deg away {other}); {agree}"
        )


def attempt_settings(config: MatchConfig) -> list[MatchConfig]:
    """The views a recording is matched with, in turn until its frames find a pose.

    The views as configured (``pixels_per_degree``, ``inpaint_deg``), then finer inpainted ones
    (``frames_pixels_per_degree``, ``frames_inpaint_deg``) with keypoints lifted tightly
    (``lift_inpainted`` off); every view at ``fine_max_keypoints``. Measured on the real
    recordings of docs/BENCHMARKS.md: the first gave KITTI odometry's and ACFR's poses, the
    second KITTI raw's and Waymo's.
    """
    first = replace(config, max_keypoints=config.fine_max_keypoints)
    finer = replace(
        first,
        pixels_per_degree=config.frames_pixels_per_degree,
        inpaint_deg=config.frames_inpaint_deg,
        lift_inpainted=False,
    )
    return [first] if finer == first else [first, finer]


def screen_frame(
    camera: CameraModel,
    pair,
    config: MatchConfig,
    *,
    ransac_threshold: float,
    origin=None,
    seed: int = 0,
    model_dir: str | os.PathLike | None = None,
) -> list:
    """One frame's views at ``config.views`` headings, matched by the screen only.

    Returns the :class:`~nbcalib.matching.multiview.ViewMatches` of the views that show enough
    (``min_fill``), each with its rotation-only RANSAC rotation and support.
    """
    from nbcalib.matching.match import pixels_per_radian
    from nbcalib.matching.multiview import _view_matches
    from nbcalib.matching.views import (
        DEFAULT_PIXELS_PER_DEGREE,
        heading_rotations,
        render_view,
        view_scale,
    )

    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    points = np.ascontiguousarray(pair.points_lidar, dtype=np.float64)
    values = np.ascontiguousarray(pair.intensities, dtype=np.float64)
    scale = view_scale(camera, config.pixels_per_degree or DEFAULT_PIXELS_PER_DEGREE)
    view_ppd = pixels_per_radian(camera) * scale * math.pi / 180.0
    inpaint = 2 * round(config.inpaint_deg * view_ppd / 2) + 1 if config.inpaint_deg > 0 else 0
    radius = max(float(config.search_radius), float(config.fill_radius))
    if inpaint and config.lift_inpainted:
        radius = max(radius, inpaint / 2)
    cache: dict = {}
    out = []
    for R in heading_rotations(config.views):
        view = render_view(
            camera,
            R,
            points,
            values,
            scale=scale,
            t_vcam_lidar=-R @ o if o.any() else None,
            fill_radius=config.fill_radius,
            splat_pixels_at_1m=config.splat_pixels_at_1m,
            median=config.median,
            inpaint=inpaint,
        )
        if view.fill_fraction < config.min_fill:
            continue
        out.append(
            _view_matches(
                camera,
                pair.image,
                view,
                points,
                config,
                model_dir,
                radius,
                pair.name,
                ransac_threshold,
                seed,
                screen=config.matcher != "sift",
                cache=cache,
                origin=o if o.any() else None,
            )
        )
    return out


def _supporters(camera, R, corr: Correspondences, origin, threshold: float) -> int:
    """Correspondences the rotation ``R`` (camera at ``origin``) projects within ``threshold``."""
    if len(corr) == 0:
        return 0
    proj, valid = camera.project((corr.points_lidar - origin) @ np.asarray(R).T)
    error = np.linalg.norm(proj - corr.uv_camera, axis=1)
    return int(np.count_nonzero(valid & (error < threshold)))


def vote_rotations(
    camera: CameraModel,
    screens: Sequence[Sequence],
    *,
    threshold: float,
    origin=None,
    count: int = VOTE_CANDIDATES,
) -> list[RotationVote]:
    """The rotations the frames' screened matches support most, best first.

    Parameters
    ----------
    camera : CameraModel
    screens : sequence of sequences of ViewMatches
        Per frame, its screened views (:func:`screen_frame`).
    threshold : float
        Inlier threshold, pixels (the RANSAC threshold).
    origin : array_like of shape (3,), optional
        The LiDAR's position in the clouds' frame (where the camera is taken to be).
    count : int, optional
        Candidates returned, each at least :data:`VOTE_SEPARATION_DEG` from the better ones.

    Returns
    -------
    list of RotationVote
    """
    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    pooled = [pool_correspondences([v.correspondences for v in views]) for views in screens]
    hypotheses = [
        v.R_camera_lidar
        for views in screens
        for v in views
        if v.R_camera_lidar is not None and v.ransac_inliers >= _MIN_HYPOTHESIS_SUPPORT
    ]
    scored = []
    for R in hypotheses:
        per_frame = tuple(_supporters(camera, R, corr, o, threshold) for corr in pooled)
        scored.append(RotationVote(R, sum(per_frame), per_frame))
    scored.sort(key=lambda v: -v.support)  # stable: the first of equals
    chosen: list[RotationVote] = []
    for vote in scored:
        if len(chosen) >= count:
            break
        if all(
            rotation_angle_deg(c.R_camera_lidar.T @ vote.R_camera_lidar) >= VOTE_SEPARATION_DEG
            for c in chosen
        ):
            chosen.append(vote)
    return chosen


def _match_view(camera, pair, config, T, *, guess_config, origin, seed, model_dir):
    """The learned matcher on one view of ``pair`` rendered at pose ``T`` (MultiViewMatches)."""
    from nbcalib.matching.multiview import match_views

    return match_views(
        camera,
        pair.image,
        pair.points_lidar,
        pair.intensities,
        config,
        guess_config=guess_config,
        T_camera_lidar_prior=T,
        seed=seed,
        name=pair.name,
        model_dir=model_dir,
        origin=origin,
        prior_yaw_offsets_deg=(0.0,),
        refine_view=False,
        screen_views=0,
    )


def _estimate(camera, parts, guess_config, seed, origin):
    from nbcalib.errors import InputError
    from nbcalib.initial_guess.estimate import MIN_CORRESPONDENCES, estimate_initial_guess

    corr = pool_correspondences(parts)
    if len(corr) < MIN_CORRESPONDENCES:
        return None, corr
    try:
        guess = estimate_initial_guess(
            camera,
            corr.uv_camera,
            corr.points_lidar,
            guess_config,
            seed=seed,
            weights=corr.weights if guess_config.confidence_weights else None,
            origin=origin,
        )
    except InputError:
        return None, corr
    return guess, corr


def _agreeing(guess, corr: Correspondences, min_support: int) -> list[str]:
    """Names of the frames with ``min_support`` inliers under the pooled guess."""
    if guess is None:
        return []
    counts = np.bincount(corr.pair[guess.inliers], minlength=len(corr.names))
    return [name for name, n in zip(corr.names, counts) if n >= min_support]


def match_recording(
    camera: CameraModel,
    pairs: Sequence,
    config: MatchConfig,
    guess_config,
    *,
    origin=None,
    T_camera_lidar_prior=None,
    seed: int = 0,
    model_dir: str | os.PathLike | None = None,
    log_line: Callable[[str], None] | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> RecordingMatches:
    """Match a recording's frames as the module docstring says.

    Parameters
    ----------
    camera : CameraModel
    pairs : sequence of PairData
        The frames, preprocessed and rendered.
    config : MatchConfig
        With the matcher resolved.
    guess_config : InitialGuessConfig
        Its RANSAC threshold scores views and the vote; the pooled pose is estimated with it.
    origin : array_like of shape (3,), optional
        The LiDAR's position in the clouds' frame.
    T_camera_lidar_prior : array_like of shape (4, 4), optional
        A rough extrinsic: every frame's view is rendered from it, instead of the screen and
        the vote.
    seed : int, optional
    model_dir : str or os.PathLike, optional
    log_line : callable, optional
        Receives a line per step.
    progress : callable, optional
        ``progress(what, done, total)`` after each frame of each step.

    Returns
    -------
    RecordingMatches
        Of the first attempt (:func:`attempt_settings`) whose frames find a pose, else of the
        one whose pose the most correspondences support.
    """
    say = log_line or (lambda line: None)
    best = None
    for k, settings in enumerate(attempt_settings(config)):
        found = _attempt(camera, pairs, settings, guess_config, origin=origin,
                         T_camera_lidar_prior=T_camera_lidar_prior, seed=seed,
                         model_dir=model_dir, progress=progress)  # fmt: skip
        found = replace(found, attempt=k)
        say(f"attempt {k + 1} ({_describe(settings)}): {found.summary()}")
        if best is None or found.rank() > best.rank():
            best = found
        if found.guess is not None and found.guess.found:
            break
    return best


def _describe(settings: MatchConfig) -> str:
    ppd = settings.pixels_per_degree
    what = "views at the LiDAR's resolution" if ppd is None else f"views at {ppd:g} px/deg"
    if settings.inpaint_deg > 0:
        what += f", inpainted {settings.inpaint_deg:g} deg"
    return what


def _moved(T_a, T_b) -> tuple[float, float]:
    from nbcalib.transforms import invert_T, pose_error

    return pose_error(invert_T(T_a), invert_T(T_b))


#: Matching a recording's frames stops once adding a frame moves the pooled pose less than this
#: (metres, degrees) and ``guess_pairs`` frames agree with it.
STABLE = (0.05, 0.25)
#: The screen stops once the vote's winner explains this many times its runner-up's
#: correspondences, and at least this many.
CLEAR_VOTE = (3.0, 40)


def _attempt(camera, pairs, cfg, guess_config, *, origin, T_camera_lidar_prior, seed, model_dir,
             progress) -> RecordingMatches:  # fmt: skip
    """One attempt of :func:`match_recording` with the views of ``cfg``."""
    from nbcalib.matching.find import PairMatches, reference_matches
    from nbcalib.matching.multiview import MultiViewMatches

    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    o_or_none = o if o.any() else None
    threshold = guess_config.ransac_threshold
    seconds: dict[str, float] = {}

    def tick(what, done, total):
        if progress is not None:
            progress(what, done, total)

    # 1-2: screen the frames until their vote is clear
    t0 = time.perf_counter()
    screened = 0
    if T_camera_lidar_prior is not None:  # the user's rough pose: no screen, no vote
        T_prior = np.asarray(T_camera_lidar_prior, dtype=np.float64)
        votes = [RotationVote(T_prior[:3, :3], 0, (0,) * len(pairs))]
    else:
        screens, votes = [], []
        for k, pair in enumerate(pairs):
            screens.append(
                screen_frame(
                    camera,
                    pair,
                    cfg,
                    ransac_threshold=threshold,
                    origin=o_or_none,
                    seed=seed,
                    model_dir=model_dir,
                )
            )
            tick("screen", k + 1, len(pairs))
            votes = vote_rotations(camera, screens, threshold=threshold, origin=o)
            screened = k + 1
            if _clear(votes):
                break
        votes = [replace(v, per_frame=v.per_frame + (0,) * (len(pairs) - screened)) for v in votes]
    seconds["screen"] = round(time.perf_counter() - t0, 3)

    # 3: match the frames at the vote's rotation until the pooled pose is stable
    t0 = time.perf_counter()
    need = max(int(cfg.guess_pairs), 1) if cfg.guess_pairs > 0 else len(pairs)
    state = ({}, {}, None, [])
    tried = 0
    for vote in votes:
        tried += 1
        T_view = make_T(vote.R_camera_lidar, -vote.R_camera_lidar @ o)
        if T_camera_lidar_prior is not None:
            T_view = np.asarray(T_camera_lidar_prior, dtype=np.float64)
        views, parts, guess, agreeing = {}, {}, None, []
        order = sorted(range(len(pairs)), key=lambda k: -vote.per_frame[k])
        for n, k in enumerate(order):
            pair = pairs[k]
            found = _match_view(camera, pair, cfg, T_view, guess_config=guess_config,
                                origin=o_or_none, seed=seed, model_dir=model_dir)  # fmt: skip
            views[pair.name], parts[pair.name] = list(found.views), found.correspondences
            tick("match", n + 1, len(pairs))
            if len(parts) < min(2, len(pairs)):
                continue
            previous = guess
            guess, corr = _estimate(camera, list(parts.values()), guess_config, seed, o_or_none)
            agreeing = _agreeing(guess, corr, cfg.min_pool_support)
            if (
                guess is not None
                and guess.found
                and previous is not None
                and previous.found
                and len(agreeing) >= min(need, len(pairs))
                and all(np.less(_moved(guess.T_camera_lidar, previous.T_camera_lidar), STABLE))
            ):
                break
        state = (views, parts, guess, agreeing)
        if guess is not None and guess.found:
            break
    views, parts, guess, agreeing = state
    seconds["match"] = round(time.perf_counter() - t0, 3)

    # 4: each matched frame once more, seen from the pooled pose (the camera's own geometry)
    t0 = time.perf_counter()
    if guess is not None and guess.n_inliers >= guess.min_inliers and cfg.refine_view:
        for n, name in enumerate(list(parts)):
            pair = next(p for p in pairs if p.name == name)
            found = _match_view(camera, pair, cfg, guess.T_camera_lidar, guess_config=guess_config,
                                origin=o_or_none, seed=seed, model_dir=model_dir)  # fmt: skip
            views[name] += list(found.views)
            parts[name] = pool_correspondences([parts[name], found.correspondences])
            tick("refine", n + 1, len(parts))
        guess, corr = _estimate(camera, list(parts.values()), guess_config, seed, o_or_none)
        agreeing = _agreeing(guess, corr, cfg.min_pool_support)
    seconds["refine"] = round(time.perf_counter() - t0, 3)

    matcher = cfg.matcher
    out = {}
    for name, part in parts.items():
        pair = next(p for p in pairs if p.name == name)
        record = MultiViewMatches(
            views[name], 0 if views[name] else -1, tuple(range(len(views[name]))), part, 0.0
        )
        info = {
            "mode": "recording",
            "pixels_per_degree": cfg.pixels_per_degree,
            "inpaint_deg": cfg.inpaint_deg,
            "views": [
                {
                    "heading_deg": round(v.view.heading_deg, 2),
                    "matches": v.matches.num_matches,
                    "lifted": len(v.correspondences),
                    "ransac_inliers": v.ransac_inliers,
                }
                for v in views[name]
            ],
            "agrees": name in agreeing,
        }
        out[name] = PairMatches(
            name,
            part,
            reference_matches(part, pair.lidar_index, matcher=matcher, info=info),
            matcher,
            record,
        )
    return RecordingMatches(out, votes, tried, guess, agreeing, seconds, screened)


def _clear(votes) -> bool:
    """The vote's winner stands out (:data:`CLEAR_VOTE`)."""
    if not votes or votes[0].support < CLEAR_VOTE[1]:
        return False
    runner_up = votes[1].support if len(votes) > 1 else 0
    return votes[0].support >= CLEAR_VOTE[0] * max(runner_up, 1)
