"""``nbcalib evaluate WORKDIR --ground-truth FILE``: compare a work directory's result to the truth.

Prints exactly one JSON line on stdout::

    {"translation_error_m": 0.0123, "rotation_error_deg": 0.0456, "stage": "T_lidar_camera"}

``stage`` is the ``calib.json`` result judged: the final ``T_lidar_camera`` if present, else the
most recent initial guess (:meth:`nbcalib.io.calib_json.CalibFile.latest_stage`), or the one
named by ``--stage``. Errors are defined in :mod:`nbcalib.metrics`.

A several-camera work directory (``WORKDIR/rig.json``, :mod:`nbcalib.rig_pipeline`) against the
ground truth of a camera ring (``nbcalib synth --cameras``) prints the rig's line first, then one
line per camera with a ``camera`` key::

    {"rig": "cam0", "cameras": 3, "translation_error_m": ..., "rotation_error_deg": ...,
     "worst_translation_error_m": ..., "worst_rotation_error_deg": ..., "stage": ...}
    {"camera": "cam0", "translation_error_m": ..., "rotation_error_deg": ..., "stage": ...}

The rig's error is its pose's: the reference camera's (the first); ``worst_*`` the largest of
the cameras'.
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
(the final T_lidar_camera if present, else the most recent initial guess). Against the ground
truth of 'nbcalib synth --given-*' (intrinsics other than the true ones) the line adds
"focal_error_percent" and "center_error_px": the work directory's camera against the true one.

For a several-camera job (WORKDIR/rig.json) and a camera ring's ground truth ('nbcalib synth
--cameras'): the rig's line (the reference camera's errors, and the worst camera's), then one
line per camera with a "camera" key."""

EPILOG = """\
examples:
  nbcalib evaluate work --ground-truth synth/ground_truth.json
  nbcalib evaluate work --ground-truth other_work/calib.json     # compare with another result
  nbcalib evaluate work --ground-truth gt.json --stage init_T_lidar_camera_auto
  nbcalib evaluate ring_work --ground-truth ring/ground_truth.json   # a line per camera
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
    from nbcalib.io.ground_truth import read_ground_truth
    from nbcalib.rig_pipeline import read_rig_job

    workdir = Path(args.workdir)
    if not workdir.is_dir():
        raise InputError("work directory not found", workdir)
    job = read_rig_job(workdir) if not (workdir / "calib.json").is_file() else None
    if job is not None:
        return _evaluate_rig(args, workdir, job)
    if not (workdir / "calib.json").is_file():  # before the ground truth: the first thing missing
        raise InputError("no calib.json: run 'nbcalib preprocess' first", workdir / "calib.json")
    stage, errors = _evaluate(workdir, read_ground_truth(args.ground_truth), args)
    intrinsics = _intrinsics_errors(workdir, args.ground_truth, stage)
    print(json.dumps({**errors, "stage": stage, **intrinsics}))
    return 0


def _intrinsics_errors(workdir: Path, ground_truth, stage: str) -> dict:
    """The camera of ``stage``'s result against the lab's rendering camera (``synth --given-*``).

    The refined camera when fine registration refined the intrinsics, else the one given
    (:meth:`~nbcalib.io.calib_json.CalibFile.result_camera`).
    ``focal_error_percent`` (the mean of ``fx, fy`` against the truth's) and
    ``center_error_px`` (the principal point's distance); nothing for other ground truths.
    """
    import numpy as np

    from nbcalib.io.calib_json import read_calib_json
    from nbcalib.io.ground_truth import read_ground_truth_camera

    true = read_ground_truth_camera(ground_truth)
    if true is None:
        return {}
    camera = read_calib_json(workdir / "calib.json").result_camera(stage)
    if "equirectangular" in (camera.model, true.model):  # intrinsics = image size: no focal
        raise InputError(
            f"the camera is {camera.model}, the ground truth's {true.model}: no focal length "
            "to compare",
            ground_truth,
        )
    focal = float(np.mean(camera.intrinsics[:2]) / np.mean(true.intrinsics[:2]) - 1.0)
    center = float(np.hypot(*(np.asarray(camera.intrinsics[2:4]) - true.intrinsics[2:4])))
    return {"focal_error_percent": 100.0 * focal, "center_error_px": center}


def _evaluate(workdir: Path, T_camera_lidar_true, args) -> tuple[str, dict]:
    """(the stage judged, its errors) of one camera's work directory."""
    from nbcalib.io.calib_json import read_calib_json
    from nbcalib.metrics import pose_errors

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
    return stage, pose_errors(calib.get_T_camera_lidar(stage), T_camera_lidar_true)


def _evaluate_rig(args, workdir: Path, job: dict) -> int:
    """The rig's line, then a line per camera (module docstring)."""
    from nbcalib.io.ground_truth import read_ground_truth_cameras

    truth = read_ground_truth_cameras(args.ground_truth)
    names = [c["name"] for c in job["cameras"]]
    missing = [n for n in names if n not in truth]
    if missing:
        raise InputError(
            f"no ground truth for camera {', '.join(missing)} (it has: "
            f"{', '.join(truth) or 'no camera list'})",
            args.ground_truth,
        )
    lines = []
    for name in names:
        stage, errors = _evaluate(workdir / name, truth[name], args)
        lines.append({"camera": name, **errors, "stage": stage})
    ref = lines[0]
    rig = {
        "rig": ref["camera"],
        "cameras": len(lines),
        "translation_error_m": ref["translation_error_m"],
        "rotation_error_deg": ref["rotation_error_deg"],
        "worst_translation_error_m": max(x["translation_error_m"] for x in lines),
        "worst_rotation_error_deg": max(x["rotation_error_deg"] for x in lines),
        "stage": ref["stage"],
    }
    for line in (rig, *lines):
        print(json.dumps(line))
    return 0
