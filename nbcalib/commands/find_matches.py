"""``nbcalib find-matches WORKDIR``: 2D-3D correspondences between each image and its cloud.

The matching stage of :class:`nbcalib.pipeline.Calibrator` over a preprocessed work directory
(:func:`nbcalib.matching.find.find_correspondences` per pair). For every data name it writes
``<name>_correspondences.json`` (every correspondence found), ``<name>_matches.json`` (the
reference toolbox's format, LiDAR keypoints at the stored LiDAR image's pixels) and
``<name>_matches.png`` (the matches drawn).
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

log = logging.getLogger("nbcalib.find_matches")

DESCRIPTION = """\
Find 2D-3D correspondences between the camera image and the dense cloud of each data name in
WORKDIR (after 'nbcalib preprocess'); writes <name>_correspondences.json (read by 'nbcalib
initial-guess'), <name>_matches.json (the reference toolbox's format) and <name>_matches.png
(the matches drawn).

Matchers: learned ones run through onnxruntime: xfeat-lighterglue ships with nbcalib,
aliked-lightglue and disk-lightglue once exported with 'nbcalib models export'; 'sift' (OpenCV
SIFT + ratio test) always runs. 'auto' takes the first available in the order xfeat-lighterglue,
aliked-lightglue, disk-lightglue, else SIFT, and says which it used.

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
  nbcalib models export --models aliked-lightglue        # once, for ALIKED + LightGlue
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``find-matches`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.commands._args import add_force_argument
    from nbcalib.commands._options import MATCHING, add_options

    parser = subparsers.add_parser(
        "find-matches",
        help="keypoint matches between camera and LiDAR images (learned, or SIFT)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument("workdir", metavar="WORKDIR", type=Path, help="work directory")
    add_options(parser.add_argument_group("matching"), MATCHING)
    parser.add_argument(
        "--model-dir",
        metavar="DIR",
        type=Path,
        default=argparse.SUPPRESS,
        help="exported models (default: $NBCALIB_MODEL_DIR or the user cache)",
    )
    parser.add_argument(
        "--prior",
        metavar="X,Y,Z,QX,QY,QZ,QW",
        default=argparse.SUPPRESS,
        help="rough T_lidar_camera (calib.json layout): views around it instead of the heading "
        "sweep (default: init_T_lidar_camera of calib.json when present)",
    )
    parser.add_argument(
        "--no-prior", action="store_true", help="ignore init_T_lidar_camera of calib.json"
    )
    add_force_argument(parser)
    return parser


def run(args: argparse.Namespace) -> int:
    """Match every data name of the work directory; returns 0."""
    from nbcalib.commands._args import parse_pose, stage_calibrator
    from nbcalib.io.calib_json import MANUAL_STAGE
    from nbcalib.products import Start

    calibrator = stage_calibrator(args, ("matching",))
    calib = calibrator.work.read_calib()
    prior = None
    if getattr(args, "prior", None) is not None:
        prior = parse_pose(args.prior, "--prior")
    elif not args.no_prior and calib.has_result(MANUAL_STAGE):
        log.info("views around %s of calib.json (--no-prior ignores it)", MANUAL_STAGE)
        prior = Start.from_matrix(calib.get_T_camera_lidar(MANUAL_STAGE), MANUAL_STAGE)
    calibrator.run(prior=prior, only="find-matches", overwrite=args.force)
    for found in calibrator.matches.values():
        print(found.summary())
    return 0
