"""The ``nbcalib`` command line: one subcommand per stage of the method, over one work directory.

Each subcommand lives in its own module under :mod:`nbcalib.commands` with two functions,
``add_parser(subparsers)`` and ``run(args) -> int``. Command modules import the heavy parts of
nbcalib (numba kernels, rosbags, onnxruntime) inside ``run``, so ``nbcalib --help`` stays fast.

Exit status (../shared/spec/cli.md): 0 success, 2 user error (one line naming the file and the
problem, no traceback), 1 internal failure.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import logging
import re
import signal
import sys
import threading
import traceback

from nbcalib import __version__
from nbcalib.commands._args import add_verbosity_arguments
from nbcalib.commands._options import flag_spelling
from nbcalib.errors import FAILED_STATUS, InputError, RegistrationFailed
from nbcalib.wording import say, spelling

#: Command modules in the order ``--help`` lists them (the order of the method's stages).
COMMAND_MODULES = (
    "selfcheck",
    "synth",
    "topics",
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
    """Keep the examples' line breaks and show defaults (not the empty ones: None, False)."""

    def _get_help_string(self, action):
        if action.default is None or action.default is False:
            return action.help
        return super()._get_help_string(action)


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
        if "--quiet" not in sub_parser._option_string_actions:  # -v / -q after the command too
            add_verbosity_arguments(sub_parser)
        sub_parser.set_defaults(run=module.run)
    return parser


_NEGATIVE = re.compile(r"^-(\d|\.\d)")


def join_negative_values(argv: list[str]) -> list[str]:
    """``--init -0.1,0.2,...`` -> ``--init=-0.1,0.2,...``.

    argparse takes a value that starts with ``-`` and is not a plain number for an option, so a
    pasted pose or distortion vector starting with a minus would fail with "expected one
    argument". No option of nbcalib takes a negative number as a positional argument.
    """
    out: list[str] = []
    i = 0
    while i < len(argv):
        token = argv[i]
        if (
            token.startswith("--")
            and "=" not in token
            and i + 1 < len(argv)
            and _NEGATIVE.match(argv[i + 1])
        ):
            out.append(f"{token}={argv[i + 1]}")
            i += 2
            continue
        out.append(token)
        i += 1
    return out


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    """Parse, taking positional arguments after options as inputs too.

    argparse stops filling a ``nargs="*"`` positional at the first option, so
    ``preprocess a.pcd --image b.png work/`` would leave ``work/`` unrecognised. For commands
    with ``INPUT... WORKDIR``, such trailing words join the inputs (WORKDIR is the last one).
    """
    args, extras = parser.parse_known_args(argv)
    words = [w for w in extras if not w.startswith("-")]
    if words and isinstance(getattr(args, "inputs", None), list):
        args.inputs += words
        extras = [w for w in extras if w.startswith("-")]
    if extras:
        parser.error(f"unrecognized arguments: {' '.join(extras)}")
    return args


class _SpellingFormatter(logging.Formatter):
    """Log lines with settings named by their flags (:mod:`nbcalib.wording`)."""

    def format(self, record: logging.LogRecord) -> str:
        return say(super().format(record))


def _log_to_stderr(level: int) -> None:
    """Stage progress (the ``nbcalib`` loggers) to this command's stderr, one line each."""
    logger = logging.getLogger("nbcalib")
    for handler in list(logger.handlers):
        if getattr(handler, "nbcalib_cli", False):
            logger.removeHandler(handler)
    handler = logging.StreamHandler(sys.stderr)
    handler.nbcalib_cli = True
    handler.setFormatter(_SpellingFormatter("%(message)s"))
    logger.addHandler(handler)
    logger.setLevel(level)


#: Errors of a full file system: a user's to fix, not a bug.
_DISK_FULL = (errno.ENOSPC, errno.EDQUOT)


def _written(filename) -> str:
    """The file being written, as the user knows it.

    A temporary file or folder of an atomic write (``.NAME.PID.HEX.tmp``) is named NAME.
    """
    return re.sub(r"(^|/)\.([^/]+)\.\d+\.[0-9a-f]+\.tmp(?=/|$)", r"\1\2", str(filename))


def _internal_error(args) -> int:
    traceback.print_exc()
    print(f"nbcalib {args.command}: internal error (a bug: please report it)", file=sys.stderr)
    return 1


class Terminated(BaseException):
    """SIGTERM, raised in the main thread: the job unwinds as for Ctrl-C (issue 48).

    Its files are written atomically (a temporary file renamed into place, removed on any
    exception) and its work-directory lock released, so what a stage finished stays and what it
    had begun leaves nothing; ``nbcalib run WORKDIR`` goes on from the last finished stage.
    """


def _terminate(signum, frame):
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    in_main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main else None
    try:
        return _main(argv)
    finally:
        if in_main:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    args = _parse(parser, join_negative_values(sys.argv[1:] if argv is None else list(argv)))
    if args.command is None:
        parser.print_help()
        return 2
    level = logging.DEBUG if args.verbose else logging.WARNING if args.quiet else logging.INFO
    _log_to_stderr(level)
    try:
        with spelling(flag_spelling()):  # messages name settings by their flags
            status = args.run(args)
    except InputError as exc:
        print(f"nbcalib {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except RegistrationFailed as exc:
        print(f"nbcalib {args.command}: failed: {exc}", file=sys.stderr)
        return FAILED_STATUS
    except KeyboardInterrupt:
        print(f"nbcalib {args.command}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"nbcalib {args.command}: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    except BrokenPipeError:  # `nbcalib ... | head`: the reader left; not an error of ours
        sys.stderr.close()
        return 0
    except (PermissionError, NotADirectoryError, IsADirectoryError, FileExistsError) as exc:
        # the file system refused (a read-only folder, a file where a folder should be): the
        # user's to fix, so one line naming the path, not a traceback
        where = f"{exc.filename}: " if exc.filename else ""
        reason = (exc.strerror or type(exc).__name__).lower()
        print(f"nbcalib {args.command}: error: {where}{reason}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.errno not in _DISK_FULL:
            return _internal_error(args)
        # a full disk (or quota): every file is written atomically, so the one being written
        # was not, and what was there before is as it was
        where = f"{_written(exc.filename)}: " if exc.filename else ""
        print(
            f"nbcalib {args.command}: error: {where}{(exc.strerror or 'disk full').lower()}: "
            "not written (what was there before is kept); free some space and run again",
            file=sys.stderr,
        )
        return 2
    except Exception:
        return _internal_error(args)
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
