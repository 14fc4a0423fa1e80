"""``nbcalib find-matches WORKDIR``: match each camera image with its LiDAR intensity image.

For every data name of the work directory, reads ``<name>.png`` and
``<name>_lidar_intensities.png``, runs :func:`nbcalib.matching.match_images` and writes
``<name>_matches.json`` (the reference toolbox's format) and ``<name>_matches.png`` (the matches
drawn side by side).
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
Find keypoint matches between the camera image and the LiDAR intensity image of each data name
in WORKDIR (after 'nbcalib preprocess'); writes <name>_matches.json (the reference toolbox's
format, read by 'nbcalib initial-guess') and <name>_matches.png (the matches drawn).

Matchers: learned ones run through onnxruntime once exported with 'nbcalib models export'
(aliked-lightglue, disk-lightglue, xfeat-lighterglue); 'sift' (OpenCV SIFT + ratio test) always
runs. 'auto' takes the best exported one, else SIFT, and says which it used."""

EPILOG = """\
examples:
  nbcalib find-matches work
  nbcalib find-matches work --matcher xfeat-lighterglue --match-threshold 0.05
  nbcalib find-matches work --rotate-camera 180          # camera mounted upside down
  nbcalib models export                                  # once, to get the learned matchers
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``find-matches`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.matching.preprocess import NORMALIZATIONS

    matchers = ("auto", "aliked-lightglue", "disk-lightglue", "xfeat-lighterglue", "sift")
    parser = subparsers.add_parser(
        "find-matches",
        help="keypoint matches between camera and LiDAR images (learned, or SIFT)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument("workdir", metavar="WORKDIR", type=Path, help="work directory")
    parser.add_argument("--matcher", choices=matchers, default="auto", help="matcher to use")
    parser.add_argument(
        "--match-threshold",
        metavar="P",
        type=float,
        default=0.01,
        help="minimum match probability of a learned matcher (reference 0.01, paper 0.05)",
    )
    for side in ("camera", "lidar"):
        parser.add_argument(
            f"--rotate-{side}",
            metavar="DEG",
            type=int,
            choices=(0, 90, 180, 270),
            default=0,
            help=f"rotate the {side} image clockwise by 0, 90, 180 or 270 degrees before matching",
        )
    parser.add_argument(
        "--camera-normalization",
        choices=NORMALIZATIONS,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="image normalisation of the camera image (default: the measured best, gradient)",
    )
    parser.add_argument(
        "--lidar-normalization",
        choices=NORMALIZATIONS,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="image normalisation of the LiDAR image (default: the measured best, gradient)",
    )
    parser.add_argument(
        "--camera-scale",
        metavar="S",
        type=float,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="resample the camera image by S before matching (default: the ratio of the LiDAR "
        "image's to the camera's pixels per degree, from calib.json; 1 without a recorded "
        "virtual camera)",
    )
    parser.add_argument(
        "--model-dir",
        metavar="DIR",
        type=Path,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="exported models (default: $NBCALIB_MODEL_DIR or the user cache)",
    )
    parser.add_argument("--no-picture", action="store_true", help="do not write <name>_matches.png")
    return parser


def run(args: argparse.Namespace) -> int:
    """Match every data name of the work directory; returns 0."""
    import logging

    from nbcalib.errors import InputError
    from nbcalib.io.image import read_image, write_png
    from nbcalib.matching import match as m
    from nbcalib.matching.draw import draw_matches
    from nbcalib.matching.matches import write_matches_json
    from nbcalib.preprocess.workdir import WorkDir

    log = logging.getLogger("nbcalib.find_matches")
    workdir = WorkDir(args.workdir)
    if not workdir.path.is_dir():
        raise InputError("work directory not found", workdir.path)
    if not workdir.calib_path.is_file():
        raise InputError("no calib.json: run 'nbcalib preprocess' first", workdir.calib_path)
    names = workdir.names()
    if not names:
        raise InputError("no data names in calib.json meta.bag_names", workdir.calib_path)
    matcher = m.resolve_matcher(args.matcher, getattr(args, "model_dir", None))
    camera_scale = getattr(args, "camera_scale", None)
    if camera_scale is None:
        camera_scale = _camera_scale(workdir, names[0], log)
    options = {
        "matcher": matcher,
        "camera_scale": camera_scale,
        "match_threshold": args.match_threshold,
        "rotate_camera": args.rotate_camera,
        "rotate_lidar": args.rotate_lidar,
        "model_dir": getattr(args, "model_dir", None),
    }
    for key in ("camera_normalization", "lidar_normalization"):
        if getattr(args, key, None) is not None:
            options[key] = getattr(args, key)
    for name in names:
        camera = _read_grey(workdir.image_path(name), read_image)
        lidar = _read_grey(workdir.lidar_intensity_path(name), read_image)
        matches = m.match_images(camera, lidar, **options)
        write_matches_json(workdir.matches_path(name), matches)
        if not args.no_picture:
            picture = draw_matches(camera, lidar, matches)
            write_png(workdir.path / f"{name}_matches.png", picture)
        log.info(
            "%s: %d matches of %d camera and %d LiDAR keypoints (%s, %.1f s)",
            name,
            matches.num_matches,
            len(matches.kpts_camera),
            len(matches.kpts_lidar),
            matches.matcher,
            matches.info["seconds"],
        )
    return 0


def _read_grey(path: Path, read_image):
    import numpy as np

    from nbcalib.errors import InputError

    image = read_image(path, grey=True)
    if image.dtype != np.uint8:
        raise InputError(f"expected an 8-bit image, got {image.dtype}", path)
    return image


def _camera_scale(workdir, name: str, log) -> float | None:
    """Pixels per degree of the LiDAR image over the camera image's, from ``calib.json``."""
    from nbcalib.io.calib_json import read_image_size
    from nbcalib.matching.match import camera_scale_for
    from nbcalib.preprocess.workdir import get_virtual_camera

    calib = workdir.read_calib()
    virtual = get_virtual_camera(calib)
    if virtual is None:
        log.info("no virtual camera in calib.json (made by the reference toolbox?): camera scale 1")
        return None
    width, height = read_image_size(workdir.image_path(name))
    scale = camera_scale_for(calib.camera_model(width, height), virtual[0])
    log.debug("camera scale %.3f (LiDAR image / camera pixels per degree)", scale)
    return scale
