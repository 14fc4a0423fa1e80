"""``nbcalib preprocess``: bags or plain files -> a work directory (dense clouds, LiDAR images)."""

from __future__ import annotations

import argparse

from nbcalib.commands._args import add_input_arguments, add_preprocess_arguments

DESCRIPTION = """\
Turn LiDAR-camera recordings into a work directory: each bag (or the set of plain point-cloud
files) becomes one pair: a dense cloud (static accumulation for a LiDAR at rest, motion-
compensated continuous-time ICP for a moving spinning LiDAR), the first camera image, and a
LiDAR intensity image with its point-index map rendered by a virtual camera. No ROS needed.

INPUT: ROS 1 .bag files, ROS 2 bag folders (sqlite3 or mcap), or plain files: point clouds
(.pcd, .ply, KITTI .bin = float32 x,y,z,intensity, .npy/.npz) in time order and one image
(.png/.jpg). The last positional argument is WORKDIR.
"""

EPILOG = """\
examples:
  nbcalib preprocess rosbag2_2023_03_09-13_42_46 work/     # ROS 2 bag, camera from CameraInfo
  nbcalib preprocess run1.bag run2.bag work/ --dynamic      # two pairs, moving spinning LiDAR
  nbcalib preprocess scans/*.bin image.png work/ --camera camera.yaml     # KITTI plain files
  nbcalib preprocess --points lidar.pcd --image image.png work/ \\
      --camera-model plumb_bob --intrinsics 1450,1450,960,600 --distortion=-0.04,0.08,0,0,0
  nbcalib preprocess out.bag work/ --points-topic /livox/lidar --image-topic /image

--camera FILE accepts a ROS camera_info YAML, an nbcalib/OpenCV camera YAML/JSON, or a calib.json.
"""


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``preprocess``."""
    p = subparsers.add_parser(
        "preprocess",
        help="bags or plain files -> work directory (dense clouds, LiDAR images)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    add_input_arguments(p)
    add_preprocess_arguments(p)
    return p


def _numbers(text: str | None, option: str) -> list[float]:
    from nbcalib.errors import InputError

    if text is None or text.strip() == "":
        return []
    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{option} must be comma-separated numbers, got {text!r}") from None


def _camera_from_args(args, image_shape):
    from nbcalib.camera import canonical_model_name, create_camera
    from nbcalib.errors import InputError
    from nbcalib.io.camera_file import load_camera

    height, width = image_shape[:2] if image_shape is not None else (None, None)
    if args.camera:
        return load_camera(args.camera, width=width, height=height)
    if not args.camera_model:
        if args.intrinsics or args.distortion:
            raise InputError("--intrinsics/--distortion need --camera-model")
        return None
    if width is None:
        raise InputError("--camera-model needs an image to take the size from")
    try:
        model = canonical_model_name(args.camera_model)
        intrinsics = _numbers(args.intrinsics, "--intrinsics")
        if model == "equirectangular" and not intrinsics:
            intrinsics = [width, height]  # as the reference: the image size
        return create_camera(
            model, intrinsics, _numbers(args.distortion, "--distortion"), width, height
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None


def run(args) -> int:
    """Gather inputs, preprocess, print a summary."""
    from pathlib import Path

    from nbcalib.errors import InputError
    from nbcalib.preprocess.pipeline import (
        CLOUD_SUFFIXES,
        PreprocessConfig,
        classify_inputs,
        gather_bag,
        gather_files,
        preprocess,
    )

    inputs = list(args.inputs)
    points = list(args.points or [])
    # `--points a.pcd b.pcd WORKDIR` with no positional left: the last --points entry is WORKDIR
    if not inputs and points and Path(points[-1]).suffix.lower() not in CLOUD_SUFFIXES:
        inputs = [points.pop()]
    if not inputs:
        raise InputError("WORKDIR missing: give the output folder as the last argument")
    workdir = inputs.pop()
    if Path(workdir).suffix.lower() in (*CLOUD_SUFFIXES, ".png", ".jpg", ".bag"):
        raise InputError(f"the last argument must be WORKDIR, a folder, not the file {workdir}")
    bags, clouds, images = classify_inputs(inputs)
    clouds += [Path(p) for p in points]
    if args.image:
        images.append(Path(args.image))
    config = PreprocessConfig(
        mode="dynamic" if args.dynamic else "static" if args.static else "auto",
        voxel_size=args.voxel_size,
        min_distance=args.min_distance,
        frame_rate=args.frame_rate,
        equalize_intensities=not args.no_equalize,
        equalize_image=not args.no_equalize,
        intensity_channel=args.intensity_channel,
        points_topic=args.points_topic,
        image_topic=args.image_topic,
        camera_info_topic=args.camera_info_topic,
        max_scans=args.max_scans,
    )
    if bags and (clouds or images):
        raise InputError("give either bags or plain files (point clouds + image), not both")
    if bags:
        pairs = [gather_bag(b, config) for b in sorted(bags, key=lambda p: p.name)]
        data_path = str(Path(bags[0]).resolve().parent)
    else:
        if len(images) != 1:
            raise InputError(
                f"plain files need exactly one image (.png/.jpg), got {len(images)}"
                + ("" if images else "; add --image FILE")
            )
        pairs = [gather_files(clouds, images[0], config)]
        data_path = str(Path(clouds[0]).resolve().parent) if clouds else ""
    camera = _camera_from_args(args, pairs[0].image.shape)
    summary = preprocess(pairs, workdir, camera=camera, config=config, data_path=data_path)
    total = sum(p["points"] for p in summary["pairs"].values())
    print(
        f"wrote {workdir}: {len(summary['pairs'])} pair(s), {total} points, "
        f"LiDAR FoV {summary['lidar_fov_deg']:.1f} deg, {summary['seconds']:.1f} s"
    )
    return 0
