"""``nbcalib export WORKDIR --format tf2|urdf|opencv|all``: the result for ROS and OpenCV.

Writes the chosen ``calib.json`` result as tf2 ``static_transform_publisher`` arguments (ROS 1
and ROS 2) with a ROS 2 launch file, a URDF fixed joint, and an OpenCV FileStorage YAML with
the camera and the extrinsic (:mod:`nbcalib.io.extrinsic_formats`). Each file states its frame
convention.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
Export the LiDAR-camera extrinsic of WORKDIR/calib.json for other tools. The ROS outputs
(tf2 static_transform_publisher arguments and a ROS 2 launch file, a URDF fixed joint) publish
the camera OPTICAL frame (x right, y down, z forward) as the child of the LiDAR frame, i.e.
T_lidar_camera (p_lidar = T_lidar_camera p_camera) exactly as calib.json stores it. The OpenCV
YAML holds K, D, the image size and the other direction, T_camera_lidar with R, t and rvec, as
cv2.projectPoints wants it.

A several-camera work directory (WORKDIR/rig.json) exports every camera in one tree: one tf2
script and launch file with a publisher per camera (each child frame named after its camera),
one URDF with a joint per camera, and WORKDIR/export/<camera>/camera_lidar_opencv.yaml."""

EPILOG = """\
examples:
  nbcalib export work --format all                       # every format into work/export/
  nbcalib export work --format tf2 --parent-frame velodyne --child-frame camera_optical
  nbcalib export work --format opencv --out calib_out --stage auto
  nbcalib export ring_work                               # several cameras: one tree
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``export`` on the ``nbcalib`` subcommand parser."""
    parser = subparsers.add_parser(
        "export",
        help="write the result as tf2 / URDF / OpenCV YAML",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument("workdir", metavar="WORKDIR", type=Path, help="work directory")
    parser.add_argument(
        "--format",
        dest="fmt",
        choices=("tf2", "urdf", "opencv", "all"),
        default="all",
        help="what to write: tf2 (tf2_static_transform.sh, static_transform.launch.py), urdf "
        "(lidar_camera.urdf), opencv (camera_lidar_opencv.yaml) or all",
    )
    parser.add_argument(
        "--out", metavar="DIR", type=Path, default=None, help="output folder (WORKDIR/export)"
    )
    parser.add_argument(
        "--stage",
        choices=("latest", "final", "init", "auto"),
        default="latest",
        help="result: final (T_lidar_camera), init (manual guess), auto (automatic guess), or "
        "latest (final if present, else the most recent guess)",
    )
    parser.add_argument(
        "--parent-frame", default="lidar", help="ROS name of the LiDAR frame (the parent)"
    )
    parser.add_argument(
        "--child-frame",
        default="camera",
        help="ROS name of the camera optical frame (the child; often *_optical_frame)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Write the export files and list them; returns 0."""
    from nbcalib.io.extrinsic_formats import FORMATS, export_result, load_result, tf2_arguments
    from nbcalib.rig_pipeline import read_rig_job
    from nbcalib.transforms import pose_from_xyz_quat

    formats = FORMATS if args.fmt == "all" else (args.fmt,)
    job = None if (Path(args.workdir) / "calib.json").is_file() else read_rig_job(args.workdir)
    if job is not None:
        return _export_rig(args, job, formats)
    written = export_result(
        args.workdir,
        formats,
        args.out,
        stage=args.stage,
        parent_frame=args.parent_frame,
        child_frame=args.child_frame,
    )
    calib, key = load_result(args.workdir, stage=args.stage)
    print(f"exported {key} of {calib.path}:")
    for path in written:
        print(f"  {path}")
    if "tf2" in formats:
        T_lidar_camera = pose_from_xyz_quat(calib.results[key])
        ros2 = tf2_arguments(
            T_lidar_camera, parent_frame=args.parent_frame, child_frame=args.child_frame
        )
        print("\nROS 2: ros2 run tf2_ros static_transform_publisher " + " ".join(ros2))
    return 0


def _export_rig(args, job: dict, formats) -> int:
    """Every camera of a several-camera work directory in one tree."""
    from nbcalib.errors import InputError
    from nbcalib.io.extrinsic_formats import export_rig

    if args.child_frame != "camera":
        raise InputError(
            "--child-frame names one camera; a several-camera job names each camera's frame "
            "after the camera"
        )
    names = [c["name"] for c in job["cameras"]]
    written = export_rig(
        args.workdir, names, formats, args.out, stage=args.stage, parent_frame=args.parent_frame
    )
    print(f"exported {len(names)} cameras ({', '.join(names)}) of {args.workdir}:")
    for path in written:
        print(f"  {path}")
    return 0
