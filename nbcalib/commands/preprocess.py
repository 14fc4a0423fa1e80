"""``nbcalib preprocess``: bags or plain files -> a work directory (dense clouds, LiDAR images)."""

from __future__ import annotations

import argparse

from nbcalib.commands._args import (
    add_force_argument,
    add_input_arguments,
    input_spec,
    split_workdir,
)
from nbcalib.errors import InputError

DESCRIPTION = """\
Turn LiDAR-camera recordings into a work directory: each bag (or the set of plain point-cloud
files) becomes one pair: a dense cloud (static accumulation for a LiDAR at rest, motion-
compensated continuous-time ICP for a moving spinning LiDAR), the first camera image, and a
LiDAR intensity image with its point-index map rendered by a virtual camera. No ROS needed.

INPUT: ROS 1 .bag files, ROS 2 bag folders (sqlite3 or mcap), or plain files: point clouds
(.pcd, .ply, KITTI .bin = float32 x,y,z,intensity, .npy/.npz) in time order and one image
(.png/.jpg). The last positional argument is WORKDIR.

Several pairs from one recording, one per image: --frames DIR (a folder of frames), --images
FILE... (several images for the point clouds), or a bag with --every N, --pair-count N or
--image-times. Each pair accumulates the --neighbors K scans around its image (default 1: its
own scan) and its cloud is expressed in the LiDAR frame at the image's time (from the stamps, or
--image-scan-fraction of the image's own sweep when there are none: 0.5 fits KITTI).
"""

EPILOG = """\
examples:
  nbcalib preprocess rosbag2_2023_03_09-13_42_46 work/     # ROS 2 bag, camera from CameraInfo
  nbcalib preprocess run1.bag run2.bag work/ --dynamic      # two pairs, moving spinning LiDAR
  nbcalib preprocess scans/*.bin image.png work/ --camera camera.yaml     # KITTI plain files
  nbcalib preprocess --points lidar.pcd --image image.png work/ \\
      --camera-model plumb_bob --intrinsics 1450,1450,960,600 --distortion=-0.04,0.08,0,0,0
  nbcalib preprocess out.bag work/ --points-topic /livox/lidar --image-topic /image
  nbcalib preprocess --frames kitti_raw/ work/ --camera calib.json --neighbors 10  # pair per frame
  nbcalib preprocess scans/*.bin --images cam/*.png work/ --camera camera.yaml --every 5
  nbcalib preprocess drive.bag work/ --pair-count 5 --neighbors 10 --dynamic  # 5 pairs of one bag

--camera FILE accepts a ROS camera_info YAML, an nbcalib/OpenCV camera YAML/JSON, or a calib.json.
"""


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``preprocess``."""
    from nbcalib.commands._options import PREPROCESS, add_options

    p = subparsers.add_parser(
        "preprocess",
        help="bags or plain files -> work directory (dense clouds, LiDAR images)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    add_input_arguments(p)
    add_options(p.add_argument_group("preprocessing"), PREPROCESS)
    add_force_argument(p)
    return p


def run(args) -> int:
    """Gather the inputs, preprocess them into WORKDIR, print a summary."""
    from nbcalib.commands._options import build_config
    from nbcalib.pipeline import Calibrator

    inputs, points, images, workdir = split_workdir(args.inputs, args.points, args.images or [])
    spec = input_spec(args, inputs, points, images=images)
    if spec.empty:
        raise InputError(
            "nothing to preprocess: give INPUT... WORKDIR (or --points FILE --image FILE, or "
            "--frames DIR)"
        )
    calibrator = Calibrator(build_config(args), workdir=workdir)
    calibrator.run(spec, only="preprocess", overwrite=args.force)
    total = sum(len(p) for p in calibrator.pairs)
    print(
        f"wrote {workdir}: {len(calibrator.pairs)} pair(s), {total} points, "
        f"LiDAR FoV {calibrator.virtual.fov_deg:.1f} deg, {calibrator.seconds['preprocess']:.1f} s"
    )
    return 0
