"""Arguments shared by several commands: inputs, poses, verbosity, work directories.

Settings options (``--voxel-size``, ``--bins``...) live in :mod:`nbcalib.commands._options`,
mapped onto the config tree; this module holds what is not a setting.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nbcalib.errors import InputError

__all__ = [
    "add_force_argument",
    "add_input_arguments",
    "add_verbosity_arguments",
    "check_model_dir",
    "input_spec",
    "parse_pose",
    "parse_start",
    "split_workdir",
    "stage_calibrator",
    "stage_parser",
]


def add_input_arguments(parser: argparse.ArgumentParser) -> None:
    """Positional ``INPUT... WORKDIR``, ``--points FILE... --image FILE`` and the camera."""
    from nbcalib.commands._options import INPUT_OPTIONS, RECORDING_OPTIONS, add_options

    parser.add_argument(
        "inputs",
        nargs="*",
        metavar="INPUT",
        help="bags, or point cloud files and one image; the last argument is WORKDIR",
    )
    parser.add_argument(
        "--points", nargs="+", metavar="FILE", help="point cloud files, in time order"
    )
    parser.add_argument("--image", metavar="FILE", help="camera image for --points")
    add_options(parser.add_argument_group("camera (default: the bag's CameraInfo)"), INPUT_OPTIONS)
    group = parser.add_argument_group("several pairs from one recording (one pair per image)")
    for option in RECORDING_OPTIONS:
        kwargs = {"metavar": option.metavar, "help": option.help}
        if option.flag == "--images":
            kwargs["nargs"] = "+"
        elif option.flag in ("--every", "--pair-count"):
            kwargs["type"] = _whole
        group.add_argument(option.flag, **kwargs)


#: Help of a stage command's ``--force``.
FORCE_HELP = (
    "run even when WORKDIR holds a finished result (T_lidar_camera): it goes, with the report "
    "and exports made from it"
)


def add_force_argument(parser, help: str = FORCE_HELP) -> None:
    """``--force``: a stage command may replace a finished result (as ``nbcalib run --force``)."""
    parser.add_argument("--force", action="store_true", help=help)


def _whole(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


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


def stage_parser(module, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """The parser of one command module (``add_parser(subparsers, formatter_class)``)."""
    scratch = argparse.ArgumentParser(add_help=False)
    return module.add_parser(scratch.add_subparsers(), formatter_class=formatter_class)


def split_workdir(inputs, points, images=None):
    """``INPUT... WORKDIR`` -> (inputs, points, workdir); with ``images``, images before WORKDIR.

    ``--points a.pcd b.pcd WORKDIR`` (or ``scans/*.bin --images a.png b.png WORKDIR``): a last
    list entry that is not a file of its list's kind is WORKDIR (argparse cannot tell); then
    every positional argument is an input. ``--points`` does so only with no positional left, as
    before.

    Raises
    ------
    InputError
        No WORKDIR, or a WORKDIR that names a data file.
    """
    from nbcalib.preprocess.sources import CLOUD_SUFFIXES, IMAGE_SUFFIXES

    inputs, points = [str(p) for p in inputs or []], [str(p) for p in points or []]
    image_list = [str(p) for p in images or []]
    workdir = None
    if len(image_list) > 1 and Path(image_list[-1]).suffix.lower() not in IMAGE_SUFFIXES:
        workdir = image_list.pop()
    elif not inputs and len(points) > 1 and Path(points[-1]).suffix.lower() not in CLOUD_SUFFIXES:
        workdir = points.pop()
    if workdir is None:
        if not inputs:
            raise InputError("WORKDIR missing: give the work directory as the last argument")
        workdir = inputs.pop()
    if Path(workdir).suffix.lower() in (*CLOUD_SUFFIXES, *IMAGE_SUFFIXES, ".bag"):
        raise InputError(f"the last argument must be WORKDIR, a folder, not the file {workdir}")
    if images is None:
        return inputs, points, workdir
    return inputs, points, image_list, workdir


#: Options of the input spec that are not lists of inputs (laid over a recorded spec)
_SPEC_OPTIONS = (
    "image",
    "camera",
    "camera_model",
    "intrinsics",
    "distortion",
    "image_times",
    "scan_times",
    "every",
    "pair_count",
)


def input_spec(
    args: argparse.Namespace, inputs, points, *, images=None, recorded: dict | None = None
):
    """The :class:`~nbcalib.preprocess.inputs.InputSpec` of a command line.

    With no input given (no ``INPUT``, ``--points``, ``--images`` or ``--frames``), the inputs a
    work directory recorded (``recorded``) are used, with the options given now (camera, image
    selection) laid over them.
    """
    from nbcalib.preprocess.inputs import InputSpec

    images = list(getattr(args, "images", None) or []) if images is None else list(images)
    frames = getattr(args, "frames", None)
    given = {
        key: getattr(args, key) for key in _SPEC_OPTIONS if getattr(args, key, None) is not None
    }
    if not inputs and not points and not images and frames is None and recorded:
        base = InputSpec.from_dict(recorded).to_dict()
        return InputSpec.from_dict({**base, **given})
    return InputSpec(
        inputs=tuple(inputs), points=tuple(points), images=tuple(images), frames=frames, **given
    )


def parse_pose(text: str, option: str):
    """``x,y,z,qx,qy,qz,qw`` (``T_lidar_camera``, the calib.json layout) as a pipeline Start."""
    from nbcalib.products import Start

    try:
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise InputError(f"{option} must be 7 numbers x,y,z,qx,qy,qz,qw, got {text!r}") from None
    if len(values) != 7:
        raise InputError(f"{option} must be 7 numbers x,y,z,qx,qy,qz,qw, got {len(values)}")
    return Start.from_values(values, option)


def parse_start(text, uncertainty=None, option: str = "--init"):
    """``--init`` (``parse_pose``) with its ``--init-uncertainty METRES DEGREES``, or None.

    Raises
    ------
    InputError
        A malformed pose or uncertainty, or an uncertainty without a pose.
    """
    from dataclasses import replace

    from nbcalib.products import check_uncertainty

    if not text:
        if uncertainty is not None:
            raise InputError(f"{option}-uncertainty needs {option} POSE (the start it describes)")
        return None
    start = parse_pose(text, option)
    if uncertainty is None:
        return start
    try:
        return replace(start, uncertainty=check_uncertainty(uncertainty, option))
    except ValueError as exc:
        raise InputError(f"{option}-uncertainty: {exc}") from None


def check_model_dir(path) -> None:
    """A ``--model-dir`` the user gave must be a folder (None: not given)."""
    if path is not None and not Path(path).is_dir():
        raise InputError("--model-dir: no such folder", path)


def stage_calibrator(args: argparse.Namespace, own: tuple[str, ...]):
    """The :class:`~nbcalib.pipeline.Calibrator` of a stage command on a preprocessed WORKDIR.

    The stage's own settings (config sections ``own``, and ``seed`` when named) start from
    their defaults, with the options given now over them, as when the stage is run by hand;
    the other sections are the ones the work directory recorded, so that what earlier stages
    made is described by the settings that made it.
    """
    from dataclasses import replace

    from nbcalib.commands._options import build_config
    from nbcalib.config import CalibrationConfig, config_from_record
    from nbcalib.pipeline import Calibrator
    from nbcalib.workdir import WorkDir

    work = WorkDir(args.workdir)
    calib = work.require_preprocessed()
    defaults = CalibrationConfig()
    base = replace(
        config_from_record(calib.record.config),
        **{name: getattr(defaults, name) for name in own},
    )
    model_dir = getattr(args, "model_dir", None)
    check_model_dir(model_dir)
    model_dir = model_dir or (calib.record.run.model_dir if calib.record.run else None)
    return Calibrator(build_config(args, base=base), workdir=work, model_dir=model_dir)
