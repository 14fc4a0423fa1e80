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
with fewer than ``--min-inliers`` inliers, or one another rotation explains nearly as well, is not
written (exit status 2) unless ``--force`` is given. A guess whose precision is in doubt (its
bounds times ``--precision-scale`` beyond fine registration's start) is written and recorded as
``precise: false``: fine registration refines it and the report judges the result.
"""

from __future__ import annotations

import argparse
from pathlib import Path

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


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``initial-guess`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.commands._args import add_force_argument
    from nbcalib.commands._options import INITIAL_GUESS, MATCHING, add_options

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
    group = p.add_argument_group("initial guess")
    add_options(group, INITIAL_GUESS)
    add_options(group, [o for o in MATCHING if o.flag == "--search-radius"])
    add_force_argument(
        p,
        "write the guess even when it fails its test, and run even when WORKDIR holds a "
        "finished result (T_lidar_camera): it goes, with the report and exports made from it",
    )
    return p


def run(args: argparse.Namespace) -> int:
    """Estimate the guess, print it, and write it to calib.json; returns the exit status."""
    import numpy as np

    from nbcalib.commands._args import stage_calibrator

    calibrator = stage_calibrator(args, ("initial_guess", "seed"))
    manual = getattr(args, "manual", None)
    calibrator.run(
        manual=manual, only="initial-guess", accept_failed_guess=args.force, overwrite=args.force
    )
    guess, corr = calibrator.guess, calibrator._guess_corr
    if manual is not None:
        print(f"{len(corr)} manual correspondences from {manual}")
    else:
        for part in calibrator._guess_parts:
            print(f"{part.names[0]}: {part.n_matches} matches, {len(part)} lifted to 3-D points")
    print(guess.summary())
    if manual is not None:
        threshold = calibrator.config.initial_guess.ransac_threshold
        for k, error in enumerate(guess.errors):
            flag = "" if error < threshold else "   <- outlier: check this pick"
            print(f"  pick {k}: reprojection error {error:.2f} px{flag}")
    if len(corr.names) > 1:
        for name, count in corr.count_per_pair().items():
            inliers = int(np.count_nonzero(guess.inliers[corr.pair == corr.names.index(name)]))
            print(f"  {name}: {count} correspondences, {inliers} inliers")
    stage = calibrator.start.source
    values = calibrator.work.read_calib().results[stage]
    print(f"{stage} = [" + ", ".join(f"{x:.6f}" for x in values) + "]")
    print(f"  (x, y, z, qx, qy, qz, qw of T_lidar_camera) written to {calibrator.work.calib_path}")
    return 0
