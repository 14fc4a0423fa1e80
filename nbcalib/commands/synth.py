"""``nbcalib synth``: a synthetic LiDAR-camera data set with a known answer."""

from __future__ import annotations

import argparse
import time

from nbcalib.commands._args import add_verbosity_arguments
from nbcalib.synthetic.effects import DESCRIPTIONS

LIDARS = ("spinning16", "spinning32", "spinning64", "spinning128", "livox")
CAMERAS = (
    "pinhole",
    "plumb_bob",
    "rational_polynomial",
    "fisheye",
    "atan",
    "omnidir",
    "equirectangular",
)
SCENES = ("room", "street")
FORMATS = ("files", "bag1", "bag2", "mcap")

DESCRIPTION = """\
Simulate a LiDAR-camera rig with a known extrinsic calibration in a procedurally generated room
or street: per pair, a few seconds of LiDAR scans (spinning LiDARs nod up and down as the
method's collection procedure asks, a rosette LiDAR holds still; scans are motion-distorted and
carry per-point times and rings) and the camera image taken at the start of the first scan, with
the rig at rest. Pairs share the rig, not the scene.

Writes OUT/ground_truth.json ({"T_lidar_camera": [x,y,z,qx,qy,qz,qw], "T_camera_lidar": 4x4},
plus the data's description), written last, so a crashed run has none; OUT/camera.yaml; and per
pair either pair_NNN.png + pair_NNN.pcd (all scans, t = seconds since the image; a moving rig
also gets pair_NNN_scans/scan_MMMM.pcd, one per scan) or one bag (ROS 1 .bag, ROS 2 sqlite3 or
mcap folder) with /points (PointCloud2: x, y, z, intensity, t, ring), /image, /camera_info and
/tf_static (lidar -> camera).

--cameras MODEL[:WxH],... simulates a camera ring around the LiDAR instead of one camera:
cam0 (the first, the rig's reference: the extrinsic and --image-size of one camera), cam1...
turned about the LiDAR by a share of a full turn (spinning LiDARs) or spread over +-20 degrees
(livox), each with its own small offset, lens and image size (1024x768 unless given). Files go
to OUT/<camera>/pair_NNN.png and OUT/<camera>/camera.yaml beside the shared pair_NNN.pcd; bags
get /<camera>/image and /<camera>/camera_info per camera; ground_truth.json keeps cam0 at the
top and lists every camera under "cameras" (with T_cam0_camera, the rig).

--given-focal-scale S, --given-center-shift DX,DY and --given-distortion-scale S hand the
calibrator intrinsics that differ from the camera that rendered the images (one camera, any
model but equirectangular, whose intrinsics are its image size): OUT/camera.yaml and the bags'
camera_info hold fx, fy times S, cx, cy plus DX, DY pixels and the distortion times S;
ground_truth.json keeps both cameras and the offset under "intrinsics".

--without EFFECTS turns single camera/LiDAR differences off, each on its own, to measure what
each one costs a calibration (none by default: the rig above, bit for bit); ground_truth.json
records them as "without". lidar-texture, materials and elements act on the LiDAR's designed
reflectivity, so in proportion to --modality-gap (at 0 the LiDAR already sees the camera's
albedo, camera texture included); camera-texture acts on the camera, and through the albedo on
the LiDAR. With all of them the two sensors are as alike as this rig can make them:
""" + "".join(f"  {name:<15} {text}\n" for name, text in DESCRIPTIONS.items())

EPILOG = """\
examples:
  nbcalib synth out --lidar livox --camera omnidir --pairs 3 --seed 1
  nbcalib synth out --lidar spinning64 --camera fisheye --scene street --format bag2
  nbcalib synth out --lidar spinning16 --format bag1 --duration 4 --image-size 640x480
  nbcalib synth out --lidar spinning128 --scene street --motion drive --format mcap
  nbcalib synth out --T-lidar-camera 0.05,-0.1,0.02,0.5,-0.5,0.5,-0.5
  nbcalib synth out --camera fisheye --pairs 10 --given-focal-scale 1.015 --given-center-shift 5,-5
  nbcalib synth out --lidar spinning64 --without motion,lidar-noise,optics
  nbcalib synth out --cameras pinhole,fisheye,fisheye --format bag2
  nbcalib synth out --cameras pinhole:1280x960,fisheye:800x800 --lidar livox
  nbcalib evaluate work --ground-truth out/ground_truth.json
"""


def _image_size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got {text!r}") from None
    if width < 16 or height < 16:
        raise argparse.ArgumentTypeError(f"image size must be at least 16x16, got {text!r}")
    return width, height


def _without(text: str) -> tuple[str, ...]:
    """The effects of ``--without`` (comma-separated), checked; a one-line InputError if not."""
    from nbcalib.errors import InputError
    from nbcalib.synthetic.effects import check_effects

    try:
        return check_effects(text)
    except ValueError as exc:
        raise InputError(f"--without: {exc}") from None


def _cameras(text: str) -> tuple[str, ...]:
    """The ring of ``--cameras`` (``model[:WxH]``, comma-separated), checked; InputError if not."""
    from nbcalib.errors import InputError
    from nbcalib.synthetic.rig import _ring_spec

    entries = tuple(t.strip() for t in text.split(",") if t.strip())
    if not entries:
        raise InputError("--cameras: give at least one camera model")
    for entry in entries:
        try:
            model, _ = _ring_spec(entry)
        except ValueError as exc:
            raise InputError(f"--cameras: {exc}") from None
        if model not in CAMERAS:
            raise InputError(f"--cameras: unknown camera {model!r}; expected one of {CAMERAS}")
    return entries


def _given(args):
    """The ``--given-*`` options as a GivenIntrinsics (None: the true intrinsics)."""
    from nbcalib.errors import InputError
    from nbcalib.synthetic.intrinsics import GivenIntrinsics

    try:
        shift = [float(v) for v in str(args.given_center_shift).split(",")]
        if len(shift) != 2:
            raise ValueError(f"--given-center-shift takes DX,DY, got {args.given_center_shift!r}")
        given = GivenIntrinsics(args.given_focal_scale, tuple(shift), args.given_distortion_scale)
        if given.exact:
            return None
        if args.cameras is not None:
            raise ValueError("--given-* take one camera, not --cameras")
        given.check(args.camera)
    except ValueError as exc:
        raise InputError(f"--given-*: {exc}") from None
    return given


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``synth``."""
    p = subparsers.add_parser(
        "synth",
        help="synthetic LiDAR-camera data with ground truth",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("out", metavar="OUT", help="output folder (created)")
    p.add_argument("--lidar", choices=LIDARS, default="spinning64", help="LiDAR model")
    p.add_argument("--camera", choices=CAMERAS, default="pinhole", help="camera model")
    p.add_argument(
        "--cameras",
        default=None,
        metavar="MODEL[:WxH],...",
        help="a camera ring instead of one camera: a model per camera, the first the reference "
        f"(models: {', '.join(CAMERAS)})",
    )
    p.add_argument("--scene", choices=SCENES, default="room", help="kind of scene")
    p.add_argument("--pairs", type=int, default=1, metavar="N", help="number of LiDAR-image pairs")
    p.add_argument("--seed", type=int, default=0, metavar="S", help="seed of everything")
    p.add_argument(
        "--format", choices=FORMATS, default="files", dest="fmt", help="PNG + PCD files or bags"
    )
    p.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="SECONDS",
        help="LiDAR data per pair (default: 3 s for spinning16, 2 s for spinning32/64, 1.5 s for "
        "spinning128, 10 s for livox)",
    )
    p.add_argument(
        "--motion",
        choices=("nod", "drive", "static"),
        default=None,
        help="rig motion (default: nod for spinning LiDARs, static for livox)",
    )
    p.add_argument(
        "--image-size",
        type=_image_size,
        default=None,
        metavar="WxH",
        help="camera image size (default 1280x960; equirectangular 1280x640)",
    )
    colour = p.add_mutually_exclusive_group()
    colour.add_argument(
        "--color", dest="color", action="store_true", default=None, help="RGB images (default)"
    )
    colour.add_argument(
        "--gray", dest="color", action="store_false", default=None, help="grey images"
    )
    p.add_argument(
        "--modality-gap",
        type=float,
        default=1.0,
        metavar="G",
        help="camera/LiDAR texture gap in [0, 1] (0: LiDAR reflectivity = camera albedo)",
    )
    p.add_argument(
        "--without",
        default=None,
        metavar="EFFECTS",
        help="comma-separated camera/LiDAR differences to switch off (listed above; default: none)",
    )
    p.add_argument(
        "--T-lidar-camera",
        dest="T_lidar_camera",
        default=None,
        metavar="x,y,z,qx,qy,qz,qw",
        help="ground-truth extrinsics as in calib.json (p_lidar = T_lidar_camera p_camera; "
        "default: drawn from the seed like a real rig, 5-30 cm, any direction)",
    )
    given = p.add_argument_group("intrinsics given to the calibrator (default: the true ones)")
    given.add_argument("--given-focal-scale", type=float, default=1.0, metavar="S",
                       help="fx, fy given = true times S")  # fmt: skip
    given.add_argument("--given-center-shift", default="0,0", metavar="DX,DY",
                       help="cx, cy given = true plus DX, DY pixels")  # fmt: skip
    given.add_argument("--given-distortion-scale", type=float, default=1.0, metavar="S",
                       help="distortion coefficients given = true times S")  # fmt: skip
    p.add_argument(
        "--parallel",
        action="store_true",
        help="use the parallel kernels (same output; no gain measured yet, docs/BENCHMARKS.md)",
    )
    add_verbosity_arguments(p)
    return p


def run(args) -> int:
    """Simulate and write the data set; returns 0."""
    from pathlib import Path

    from nbcalib.errors import InputError
    from nbcalib.synthetic import RigConfig
    from nbcalib.synthetic.writer import export_dataset
    from nbcalib.workdir import check_writable

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", path=out)
    check_writable(out)  # before the simulation, not after it
    if args.pairs < 1:
        raise InputError(f"--pairs must be at least 1, got {args.pairs}")
    if args.duration is not None and not args.duration > 0:
        raise InputError(f"--duration must be > 0 seconds, got {args.duration}")
    if not 0.0 <= args.modality_gap <= 1.0:
        raise InputError(f"--modality-gap must be in [0, 1], got {args.modality_gap}")
    without = _without(args.without or "")
    cameras = _cameras(args.cameras) if args.cameras is not None else ()
    T_camera_lidar = None
    if args.T_lidar_camera is not None:
        from nbcalib.transforms import invert_T, pose_from_xyz_quat

        try:
            values = [float(v) for v in args.T_lidar_camera.split(",")]
            if len(values) != 7:
                raise ValueError(f"expected 7 numbers, got {len(values)}")
            T_camera_lidar = invert_T(pose_from_xyz_quat(values))
        except ValueError as exc:
            raise InputError(f"--T-lidar-camera: {exc}") from None
    config = RigConfig(
        T_camera_lidar=T_camera_lidar,
        lidar=args.lidar,
        camera=args.camera,
        scene=args.scene,
        seed=args.seed,
        duration=args.duration,
        motion=args.motion,
        image_size=args.image_size,
        color=args.color is not False,
        modality_gap=args.modality_gap,
        without=without,
        parallel=args.parallel,
        cameras=cameras,
    )
    given = _given(args)
    start = time.perf_counter()
    truth = export_dataset(config, out, pairs=args.pairs, fmt=args.fmt, progress=True, given=given)
    points = sum(p["num_points"] for p in truth["pairs"])
    sensors = args.camera if not cameras else f"{len(cameras)} cameras ({','.join(cameras)})"
    print(
        f"nbcalib synth: {args.pairs} pair(s), {points} LiDAR points, {args.lidar} + "
        f"{sensors} in a {args.scene}, {args.fmt}, in {time.perf_counter() - start:.1f} s; "
        f"ground truth: {out / 'ground_truth.json'}"
    )
    return 0
