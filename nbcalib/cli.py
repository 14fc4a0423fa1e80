"""The ``nbcalib`` command line: one subcommand per stage of the method, over one work directory.

Each subcommand lives in its own module under :mod:`nbcalib.commands` with two functions,
``add_parser(subparsers)`` and ``run(args) -> int``. Command modules import the heavy parts of
nbcalib (numba kernels, rosbags, onnxruntime) inside ``run``, so ``nbcalib --help`` stays fast.

Exit status (../shared/spec/cli.md): 0 success, 2 user error (one line naming the file and the
problem, no traceback), 1 internal failure.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
import traceback

from nbcalib import __version__
from nbcalib.errors import InputError

#: Command modules in the order ``--help`` lists them (the order of the method's stages).
COMMAND_MODULES = (
    "selfcheck",
    "synth",
    "preprocess",
    "find_matches",
    "initial_guess",
    "calibrate",
    "report",
    "evaluate",
    "run",
    "demo",
    "export",
    "data",
    "models",
)

EPILOG = """\
examples:
  nbcalib selfcheck                     # check every camera model on this machine
  nbcalib <command> --help              # options and examples of one command

Conventions (frames, T_a_b, calib.json, pixels): docs/conventions.md
"""


class _Formatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Keep the examples' line breaks and show defaults."""


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line, exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """Assemble the top-level parser from the command modules."""
    parser = _Parser(
        prog="nbcalib",
        description="Target-less, single-shot, automatic LiDAR-camera extrinsic calibration.",
        epilog=EPILOG,
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"nbcalib {__version__}")
    verbosity = parser.add_mutually_exclusive_group()
    verbosity.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    verbosity.add_argument("-q", "--quiet", action="store_true", help="warnings and errors only")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        module = importlib.import_module(f"nbcalib.commands.{name}")
        sub_parser = module.add_parser(sub, formatter_class=_Formatter)
        sub_parser.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    logging.basicConfig(level=level, format="%(message)s")
    try:
        status = args.run(args)
    except InputError as exc:
        print(f"nbcalib {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"nbcalib {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `nbcalib ... | head`: the reader left; not an error of ours
        sys.stderr.close()
        return 0
    except Exception:
        traceback.print_exc()
        print(f"nbcalib {args.command}: internal error (a bug: please report it)", file=sys.stderr)
        return 1
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
