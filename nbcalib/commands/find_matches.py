"""``nbcalib find-matches WORKDIR``: match each camera image with its LiDAR intensity image.

For every data name of the work directory, matches the camera image ``<name>.png`` with the
LiDAR data and writes ``<name>_matches.json`` (the reference toolbox's format) and
``<name>_matches.png`` (the matches drawn side by side).

Default (``--views 12``): the dense cloud is rendered through the real camera's model at the
LiDAR's angular resolution, looking along 12 headings around the LiDAR (or around a prior:
``--prior``, else ``init_T_lidar_camera`` of ``calib.json``), each view is matched and the view
with the best rotation-only RANSAC support kept (:func:`nbcalib.initial_guess.match_views`).
The LiDAR keypoints are written as pixels of ``<name>_lidar_intensities.png`` (their 3-D points
projected), plus the cloud row of each under ``nbcalib.kpts1_point_index``.
``--views 0``: the reference's way, :func:`nbcalib.matching.match_images` on
``<name>_lidar_intensities.png`` itself.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
Find keypoint matches between the camera image and the LiDAR intensity image of each data name
in WORKDIR (after 'nbcalib preprocess'); writes <name>_matches.json (the reference toolbox's
format, read by 'nbcalib initial-guess') and <name>_matches.png (the matches drawn).

Matchers: learned ones run through onnxruntime once exported with 'nbcalib models export'
(xfeat-lighterglue, aliked-lightglue, disk-lightglue); 'sift' (OpenCV SIFT + ratio test) always
runs. 'auto' takes the first exported one in that order, else SIFT, and says which it used.

By default the camera image is matched against camera-shaped LiDAR views (the dense cloud
rendered through the camera's own model at the LiDAR's resolution) at --views headings around
the LiDAR, or around a prior (--prior, else init_T_lidar_camera of calib.json), and the view
with the most rotation-only RANSAC inliers is kept; --views 0 matches the stored LiDAR image
as the reference toolbox does."""

EPILOG = """\
examples:
  nbcalib find-matches work
  nbcalib find-matches work --matcher xfeat-lighterglue --match-threshold 0.05
  nbcalib find-matches work --rotate-camera 180          # camera mounted upside down
  nbcalib find-matches work --prior 0,0,0,-0.5,0.5,-0.5,0.5   # camera roughly along LiDAR +x
  nbcalib find-matches work --views 0                    # the reference's single LiDAR image
  nbcalib models export                                  # once, to get the learned matchers
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``find-matches`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.matching.normalize import NORMALIZATIONS

    matchers = ("auto", "xfeat-lighterglue", "aliked-lightglue", "disk-lightglue", "sift")
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
    parser.add_argument(
        "--views",
        metavar="N",
        type=int,
        default=12,
        help="camera-shaped LiDAR views at N headings around the LiDAR (0: match the stored "
        "LiDAR image instead, as the reference)",
    )
    parser.add_argument(
        "--prior",
        metavar="X,Y,Z,QX,QY,QZ,QW",
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="rough T_lidar_camera (calib.json layout): views around it instead of the heading "
        "sweep (default: init_T_lidar_camera of calib.json when present); write --prior=-0.1,... "
        "when the first value is negative",
    )
    parser.add_argument(
        "--no-prior", action="store_true", help="ignore init_T_lidar_camera of calib.json"
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
    from nbcalib.workdir import WorkDir

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
    if args.views < 0:
        raise InputError(f"--views must be >= 0, got {args.views}", workdir.path)
    if args.views > 0 and _run_views(args, workdir, names, matcher, options, log):
        return 0
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


def _prior(args, calib, log):
    """``T_camera_lidar`` of --prior, else of init_T_lidar_camera in calib.json, else None."""
    from nbcalib.io.calib_json import MANUAL_STAGE, T_camera_lidar_from_values

    text = getattr(args, "prior", None)
    if text is not None:
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            from nbcalib.errors import InputError

            raise InputError(f"--prior must be 7 numbers x,y,z,qx,qy,qz,qw, got {text!r}") from None
        return T_camera_lidar_from_values(values, what="--prior")
    if not args.no_prior and calib.has_result(MANUAL_STAGE):
        log.info("views around %s of calib.json (--no-prior ignores it)", MANUAL_STAGE)
        return calib.get_T_camera_lidar(MANUAL_STAGE)
    return None


def _run_views(args, workdir, names, matcher, options, log) -> bool:
    """Match every pair against camera-shaped LiDAR views; write the kept matches.

    Returns False (nothing done) when calib.json records no virtual camera (a work directory of
    the reference toolbox): the caller then matches the stored LiDAR images.
    """
    from nbcalib.initial_guess.multiview import match_views
    from nbcalib.io.image import write_png
    from nbcalib.matching.draw import draw_matches
    from nbcalib.matching.matches import write_matches_json
    from nbcalib.workdir import get_virtual_camera

    calib = workdir.read_calib()
    virtual = get_virtual_camera(calib)
    if virtual is None:
        log.info(
            "no virtual camera in calib.json (made by the reference toolbox?): matching the "
            "stored LiDAR images (as --views 0)"
        )
        return False
    prior = _prior(args, calib, log)
    view_options = {k: v for k, v in options.items() if k not in ("camera_scale", "matcher")}
    for name in names:
        pair = workdir.load_pair(name)
        camera = calib.camera_model(pair.image.shape[1], pair.image.shape[0])
        mv = match_views(
            camera,
            pair.image,
            pair.points_lidar,
            pair.intensities,
            matcher=matcher,
            n_headings=args.views,
            T_camera_lidar_prior=prior,
            name=name,
            **view_options,
        )
        log.debug("%s views:\n%s", name, mv.summary())
        matches = mv.to_matches(virtual[0], virtual[1], matcher=matcher)
        write_matches_json(workdir.matches_path(name), matches)
        if not args.no_picture:
            picture = draw_matches(pair.image, pair.lidar_intensity, matches)
            write_png(workdir.path / f"{name}_matches.png", picture)
        best = mv.views[mv.best] if mv.best >= 0 else None
        log.info(
            "%s: %d views, best heading %s (RANSAC inliers %d), %d matches kept (%s, %.1f s)",
            name,
            len(mv.views),
            "n/a" if best is None else f"{best.view.heading_deg:.0f} deg",
            0 if best is None else best.ransac_inliers,
            matches.num_matches,
            matcher,
            mv.seconds,
        )
    return True


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
    from nbcalib.workdir import get_virtual_camera

    calib = workdir.read_calib()
    virtual = get_virtual_camera(calib)
    if virtual is None:
        log.info("no virtual camera in calib.json (made by the reference toolbox?): camera scale 1")
        return None
    width, height = read_image_size(workdir.image_path(name))
    scale = camera_scale_for(calib.camera_model(width, height), virtual[0])
    log.debug("camera scale %.3f (LiDAR image / camera pixels per degree)", scale)
    return scale
