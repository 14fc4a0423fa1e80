"""Argument definitions shared by several commands (``preprocess`` and ``run``).

``preprocess`` and ``run`` take the same inputs and preprocessing options; they are defined here
once, so both commands accept exactly the same spellings, and :func:`copy_stage_options` lets
``run`` offer every option of the later stages (``find-matches``, ``initial-guess``,
``calibrate``) without repeating their definitions.
"""

from __future__ import annotations

import argparse
import copy

__all__ = [
    "add_input_arguments",
    "add_preprocess_arguments",
    "add_verbosity_arguments",
    "copy_stage_options",
    "stage_parser",
    "suppress_defaults",
]


def add_input_arguments(parser: argparse.ArgumentParser) -> None:
    """Positional ``INPUT... WORKDIR`` and ``--points FILE... --image FILE``."""
    parser.add_argument(
        "inputs", nargs="*", metavar="INPUT... WORKDIR", help="inputs, then WORKDIR"
    )
    parser.add_argument(
        "--points", nargs="+", metavar="FILE", help="point cloud files, in time order"
    )
    parser.add_argument("--image", metavar="FILE", help="camera image for --points")


def add_preprocess_arguments(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options of ``preprocess`` (integration mode, camera, topics, dense cloud).

    Returns
    -------
    list of argparse.Action
        The actions added, so that a caller can change their defaults
        (:func:`suppress_defaults`).
    """
    before = len(parser._actions)
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--dynamic", action="store_true", help="moving spinning LiDAR (CT-ICP)")
    mode.add_argument("--static", action="store_true", help="LiDAR at rest (accumulate)")
    cam = parser.add_argument_group("camera (default: the bag's CameraInfo)")
    cam.add_argument("--camera", metavar="FILE", help="camera file")
    cam.add_argument("--camera-model", metavar="M", help="pinhole, plumb_bob, fisheye, ...")
    cam.add_argument("--intrinsics", metavar="A,B,...", help="fx,fy,cx,cy[,xi]")
    cam.add_argument("--distortion", metavar="A,B,...", help="distortion coefficients")
    topics = parser.add_argument_group("bag topics (default: the only one of each kind)")
    topics.add_argument("--points-topic", metavar="T")
    topics.add_argument("--image-topic", metavar="T")
    topics.add_argument("--camera-info-topic", metavar="T")
    parser.add_argument(
        "--intensity-channel", default="auto", help="'auto': reflectivity > intensity"
    )
    parser.add_argument("--voxel-size", type=float, default=0.002, help="dense cloud voxel, metres")
    parser.add_argument(
        "--min-distance", type=float, default=1.0, help="drop nearer points, metres"
    )
    parser.add_argument(
        "--frame-rate", type=float, default=10.0, help="for files without times, Hz"
    )
    parser.add_argument("--max-scans", type=int, default=None, help="use at most N scans per pair")
    parser.add_argument("--no-equalize", action="store_true", help="keep raw intensities and image")
    return parser._actions[before:]


def add_verbosity_arguments(group) -> None:
    """``-v`` / ``-q`` after the command name as well (the global ones come before it).

    Their defaults are ``argparse.SUPPRESS``, so the global ``nbcalib -v`` is not overwritten;
    given after the command, they set the same ``verbose`` / ``quiet`` that ``cli.main`` reads.
    """
    verbosity = group.add_mutually_exclusive_group()
    verbosity.add_argument(
        "-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="debug logging"
    )
    verbosity.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        default=argparse.SUPPRESS,
        help="warnings and errors only",
    )


def suppress_defaults(actions) -> None:
    """Leave options out of the namespace unless given; name the default in their help instead.

    ``run`` merges three sources (command line over config file over each stage's defaults) and
    has to know which options the user gave; an option with ``argparse.SUPPRESS`` as default is
    absent from the namespace unless given.
    """
    for action in actions:
        if action.default is argparse.SUPPRESS:
            continue
        if action.default not in (None, False) and action.help:
            action.help = f"{action.help} (default: {action.default})"
        action.default = argparse.SUPPRESS


def stage_parser(module, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """The parser of one command module (``add_parser(subparsers, formatter_class)``)."""
    scratch = argparse.ArgumentParser(add_help=False)
    return module.add_parser(scratch.add_subparsers(), formatter_class=formatter_class)


def copy_stage_options(
    parser: argparse.ArgumentParser, module, title: str, *, skip=()
) -> list[argparse.Action]:
    """Add the optional arguments of a command module's parser to ``parser``, as a group.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        Receives copies of the options.
    module : module
        A command module (``add_parser``).
    title : str
        Title of the argument group in ``--help``.
    skip : iterable of str
        Option strings not to copy (e.g. ``--force``, which means something else in ``run``);
        options whose strings ``parser`` already has are skipped as well.

    Returns
    -------
    list of argparse.Action
        The copies, defaults untouched.
    """
    taken = set(parser._option_string_actions) | set(skip)
    group = parser.add_argument_group(title)
    copies = []
    for action in stage_parser(module)._actions:
        if not action.option_strings or isinstance(action, argparse._HelpAction):
            continue
        if taken & set(action.option_strings):
            continue
        clone = copy.copy(action)
        group._add_action(clone)
        copies.append(clone)
    return copies
