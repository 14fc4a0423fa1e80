"""``nbcalib initial-guess WORKDIR [--manual FILE]``: the initial extrinsic from correspondences.

Automatic (default): the matches of every pair (``<name>_matches.json``, written by
``nbcalib find-matches``) are lifted to 2D-3D correspondences through the index maps, pooled,
and passed to rotation-only RANSAC and robust LM (:mod:`nbcalib.initial_guess`); the result goes
to ``results.init_T_lidar_camera_auto`` of ``calib.json``.

Manual (``--manual FILE``): the picked correspondences of FILE
(:mod:`nbcalib.initial_guess.manual`) go through the same estimation; the result goes to
``results.init_T_lidar_camera``, which ``calibrate`` prefers when it is the more recent guess.

The matcher's confidences weigh the matches in the LM cost (``--no-confidence-weights``: all
equal, as paper Eq. 1 and the reference toolbox). Quality figures (correspondences, inliers,
RMS, success) are stored under ``nbcalib.initial_guess.<stage>`` of ``calib.json``. A guess
with fewer than ``--min-inliers`` inliers is not written (exit status 2) unless ``--force`` is
given.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nbcalib.errors import InputError

DESCRIPTION = """\
Estimate the initial LiDAR-camera extrinsic of WORKDIR (paper section III-D): 2D-3D
correspondences -> rotation-only RANSAC -> Levenberg-Marquardt with a Cauchy kernel on the
reprojection error. Without --manual, the correspondences are the keypoint matches of every
pair (<name>_matches.json from 'nbcalib find-matches'), lifted to 3-D points through the
LiDAR index maps and weighted by the matcher's confidence in the LM cost (--no-confidence-weights
for the paper's equal weights); the result is written to results.init_T_lidar_camera_auto.
With --manual FILE, they are hand-picked pairs (camera pixel <-> LiDAR-image pixel or 3-D
LiDAR point; JSON, see nbcalib.initial_guess.manual or the picker in a notebook) and the result
is written to results.init_T_lidar_camera. Prints the inlier counts and the pose."""

EPILOG = """\
examples:
  nbcalib find-matches work && nbcalib initial-guess work
  nbcalib initial-guess work --ransac-iterations 20000 --ransac-threshold 8 --seed 3
  nbcalib initial-guess work --manual work/manual_correspondences.json

manual file:
  {"format": "nbcalib-manual-correspondences", "version": 1, "correspondences": [
     {"name": "000000", "camera_uv": [812.4, 377.0], "lidar_uv": [640.0, 512.5]},
     {"name": "000000", "camera_uv": [101.0, 220.5], "point_lidar": [4.21, -1.03, 0.3]}]}
"""


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value >= 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not 0 <= value < 2**64:
        raise argparse.ArgumentTypeError(f"expected an integer in [0, 2**64), got {text!r}")
    return value


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``initial-guess`` on the ``nbcalib`` subcommand parser."""
    p = subparsers.add_parser(
        "initial-guess",
        help="initial extrinsic from keypoint matches (or manual picks)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("workdir", metavar="WORKDIR", type=Path, help="work directory")
    p.add_argument(
        "--manual",
        metavar="CORRESPONDENCES",
        type=Path,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="manual correspondences file; writes init_T_lidar_camera instead of "
        "init_T_lidar_camera_auto",
    )
    p.add_argument(
        "--ransac-iterations", type=_positive_int, default=8192, metavar="N", help="hypotheses"
    )
    p.add_argument(
        "--ransac-threshold",
        type=_positive_float,
        default=5.0,
        metavar="PX",
        help="inlier threshold on the reprojection error, pixels",
    )
    p.add_argument(
        "--robust-kernel-width",
        type=_positive_float,
        default=10.0,
        metavar="PX",
        help="Cauchy kernel width of the LM refinement, pixels",
    )
    p.add_argument("--seed", type=_seed, default=0, metavar="S", help="RANSAC seed")
    p.add_argument(
        "--search-radius",
        type=_non_negative_float,
        default=2.0,
        metavar="PX",
        help="LiDAR keypoints on empty pixels take the nearest LiDAR point within this radius",
    )
    p.add_argument(
        "--min-inliers",
        type=_positive_int,
        default=argparse.SUPPRESS,
        metavar="N",
        help="inliers needed to accept the guess (default: 10 automatic, 3 manual)",
    )
    p.add_argument(
        "--no-confidence-weights",
        dest="confidence_weights",
        action="store_false",
        help="weigh every match equally in the LM cost (paper Eq. 1, the reference) instead of "
        "by the matcher's confidence",
    )
    p.add_argument(
        "--force", action="store_true", help="write the guess even when it has too few inliers"
    )
    return p


def _automatic_correspondences(wd, names, search_radius):
    from nbcalib.initial_guess.correspondences import (
        correspondences_from_matches,
        pool_correspondences,
    )
    from nbcalib.matching.matches import read_matches_json

    parts = []
    for name in names:
        matches_path = wd.matches_path(name)
        if not matches_path.is_file():
            raise InputError("no matches: run 'nbcalib find-matches' first", matches_path)
        matches = read_matches_json(matches_path)
        pair = wd.load_pair(name)
        part = correspondences_from_matches(
            matches, pair.lidar_index, pair.points_lidar, search_radius=search_radius, name=name
        )
        print(f"{name}: {matches.num_matches} matches, {len(part)} lifted to 3-D points")
        parts.append(part)
    return pool_correspondences(parts)


def run(args: argparse.Namespace) -> int:
    """Estimate the guess, print it, and write it to calib.json; returns the exit status."""
    import numpy as np

    from nbcalib.initial_guess.estimate import MIN_CORRESPONDENCES, estimate_initial_guess
    from nbcalib.io.calib_json import AUTO_STAGE, MANUAL_STAGE, write_calib_json
    from nbcalib.workdir import WorkDir

    wd = WorkDir(args.workdir)
    if not wd.path.is_dir():
        raise InputError("work directory not found", wd.path)
    if not wd.calib_path.is_file():
        raise InputError("no calib.json: run 'nbcalib preprocess' first", wd.calib_path)
    calib = wd.read_calib()
    names = wd.names()
    if not names:
        raise InputError("meta.bag_names is empty: nothing to use", wd.calib_path)
    camera = calib.camera_model()

    manual_path = getattr(args, "manual", None)
    min_inliers = getattr(args, "min_inliers", None)
    manual = manual_path is not None
    if manual:
        from nbcalib.initial_guess.manual import (
            read_manual_correspondences,
            resolve_manual_correspondences,
        )

        entries = read_manual_correspondences(manual_path)
        corr = resolve_manual_correspondences(
            entries, wd, search_radius=args.search_radius, path=manual_path
        )
        print(f"{len(corr)} manual correspondences from {manual_path}")
        where, stage = manual_path, MANUAL_STAGE
        min_inliers = MIN_CORRESPONDENCES if min_inliers is None else min_inliers
    else:
        corr = _automatic_correspondences(wd, names, args.search_radius)
        where, stage = wd.path, AUTO_STAGE
        min_inliers = 10 if min_inliers is None else min_inliers

    if len(corr) < MIN_CORRESPONDENCES:
        hint = (
            "add more picks"
            if manual
            else "check the matches (nbcalib find-matches) or pick correspondences by hand "
            "with --manual"
        )
        raise InputError(
            f"too few correspondences: {len(corr)} (need at least {MIN_CORRESPONDENCES}); {hint}",
            where,
        )

    guess = estimate_initial_guess(
        camera,
        corr.uv_camera,
        corr.points_lidar,
        ransac_iterations=args.ransac_iterations,
        ransac_threshold=args.ransac_threshold,
        robust_kernel_width=args.robust_kernel_width,
        seed=args.seed,
        weights=corr.weights if args.confidence_weights else None,
        min_inliers=min_inliers,
    )
    print(guess.summary())
    if manual:
        for k, error in enumerate(guess.errors):
            flag = "" if error < args.ransac_threshold else "   <- outlier: check this pick"
            print(f"  pick {k}: reprojection error {error:.2f} px{flag}")
    for name, count in corr.count_per_pair().items():
        inliers = int(np.count_nonzero(guess.inliers[corr.pair == corr.names.index(name)]))
        if len(corr.names) > 1:
            print(f"  {name}: {count} correspondences, {inliers} inliers")

    quality = {
        "correspondences": len(corr),
        "ransac_inliers": guess.ransac.n_inliers,
        "inliers": guess.n_inliers,
        "rms_px": None if not np.isfinite(guess.rms_px) else round(guess.rms_px, 4),
        "support": guess.support,
        "runner_up": guess.runner_up,
        "success": bool(guess.success),
        "ransac_iterations": args.ransac_iterations,
        "ransac_threshold_px": args.ransac_threshold,
        "robust_kernel_width_px": args.robust_kernel_width,
        "seed": args.seed,
        "confidence_weights": bool(args.confidence_weights and corr.confidence is not None),
        "source": str(manual_path) if manual else "matches",
    }
    if not guess.success and not args.force:
        hint = "--force writes it anyway" if manual else "pick correspondences with --manual"
        raise InputError(
            f"initial guess not written: {guess.failure} ({hint})",
            where,
        )
    calib.set_T_camera_lidar(stage, guess.T_camera_lidar)
    calib.nbcalib.setdefault("initial_guess", {})[stage] = quality
    write_calib_json(wd.calib_path, calib)
    values = calib.results[stage]
    print(f"{stage} = [" + ", ".join(f"{x:.6f}" for x in values) + "]")
    print(f"  (x, y, z, qx, qy, qz, qw of T_lidar_camera) written to {wd.calib_path}")
    return 0
