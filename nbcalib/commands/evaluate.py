"""``nbcalib evaluate WORKDIR --ground-truth FILE``: compare a work directory's result to the truth.

Prints exactly one JSON line on stdout::

    {"translation_error_m": 0.0123, "rotation_error_deg": 0.0456, "stage": "T_lidar_camera"}

``stage`` is the ``calib.json`` result judged: the final ``T_lidar_camera`` if present, else the
most recent initial guess (:meth:`nbcalib.io.calib_json.CalibFile.latest_stage`), or the one
named by ``--stage``. Errors are defined in :mod:`nbcalib.metrics`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from nbcalib.errors import InputError

DESCRIPTION = """\
Compare the extrinsic in WORKDIR/calib.json with a known answer and print one JSON line:
{"translation_error_m": ..., "rotation_error_deg": ..., "stage": ...}.
The translation error is the camera-centre displacement in the LiDAR frame (metres), the
rotation error the angle of R_est R_true^T (degrees); "stage" is the calib.json result judged
(the final T_lidar_camera if present, else the most recent initial guess)."""

EPILOG = """\
examples:
  nbcalib evaluate work --ground-truth synth/ground_truth.json
  nbcalib evaluate work --ground-truth other_work/calib.json     # compare with another result
  nbcalib evaluate work --ground-truth gt.json --stage init_T_lidar_camera_auto
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``evaluate`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.io.calib_json import STAGES

    parser = subparsers.add_parser(
        "evaluate",
        help="errors of a calibration against a known answer (one JSON line)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument("workdir", metavar="WORKDIR", type=Path, help="work directory")
    parser.add_argument(
        "--ground-truth",
        metavar="FILE",
        type=Path,
        required=True,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="ground_truth.json as written by 'nbcalib synth' ({T_lidar_camera: [x,y,z,qx,qy,"
        "qz,qw]} and/or {T_camera_lidar: 4x4}), or a calib.json with results.T_lidar_camera",
    )
    parser.add_argument(
        "--stage",
        choices=STAGES,
        default=argparse.SUPPRESS,
        help="result to judge (default: T_lidar_camera if present, else the latest initial guess)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Print the errors of the work directory's result as one JSON line; returns 0."""
    from nbcalib.io.calib_json import read_calib_json, read_ground_truth
    from nbcalib.metrics import pose_errors

    workdir = Path(args.workdir)
    if not workdir.is_dir():
        raise InputError("work directory not found", workdir)
    calib_path = workdir / "calib.json"
    if not calib_path.is_file():
        raise InputError("no calib.json: run 'nbcalib preprocess' first", calib_path)
    calib = read_calib_json(calib_path)
    stage = getattr(args, "stage", None) or calib.latest_stage()
    if stage is None:
        raise InputError(
            "no result to evaluate (run 'nbcalib initial-guess' or 'nbcalib calibrate')",
            calib_path,
        )
    if not calib.has_result(stage):
        raise InputError(f"no result '{stage}' in results", calib_path)
    T_camera_lidar_est = calib.get_T_camera_lidar(stage)
    T_camera_lidar_true = read_ground_truth(args.ground_truth)
    errors = pose_errors(T_camera_lidar_est, T_camera_lidar_true)
    print(json.dumps({**errors, "stage": stage}))
    return 0
