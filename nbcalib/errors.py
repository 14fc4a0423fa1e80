"""Exceptions that separate a user's mistake from a bug.

:class:`InputError` is raised for anything the user can fix (a missing or corrupt file, a wrong
parameter count, an unknown topic). Its message is one line that names the file or option and the
problem; the CLI prints it and exits with status 2, without a traceback.
:class:`RegistrationFailed` is a run that finished without a result it can stand by (exit status
3). Any other exception is an internal failure (exit status 1).
"""

from __future__ import annotations

import os

from nbcalib.wording import say


class InputError(ValueError):
    """Bad user input: one line naming the file or option and the problem.

    Parameters
    ----------
    message : str
        What is wrong, in one line.
    path : str or os.PathLike, optional
        The file concerned; prefixed to the message as ``"<path>: "``.
    """

    def __init__(self, message: str, path: str | os.PathLike | None = None):
        self.path = None if path is None else os.fspath(path)
        # one line, whatever the caller passed; settings named as the front end spells them
        text = say(" ".join(str(message).split()))
        super().__init__(f"{self.path}: {text}" if self.path else text)


class RegistrationFailed(RuntimeError):
    """Fine registration ran but has no result to give: it ended on its trust region's edge.

    Neither a user's mistake nor a bug: the start was too far off, or the cost has no minimum
    near it. The CLI prints the one-line message and exits with :data:`FAILED_STATUS`; no
    result is written (the attempt is recorded under ``nbcalib.calibration`` in calib.json).

    Parameters
    ----------
    message : str
        What happened and what to try, in one line.
    result : RefineResult, optional
        The run that failed (its pose, history and trust region), for callers that want it.
    """

    def __init__(self, message: str, result=None):
        self.result = result
        super().__init__(say(" ".join(str(message).split())))


#: Exit status of a command whose run finished without a trustworthy result (a fine
#: registration on its trust region's edge; ``nbcalib report --strict`` on a suspect verdict).
FAILED_STATUS = 3


class MissingExtraError(InputError):
    """An optional dependency is not installed; the message names the extra that provides it."""

    def __init__(self, module: str, extra: str):
        super().__init__(
            f"this needs the optional package '{module}'; install it with "
            f'pip install "nbcalib[{extra}]"'
        )


def require(module: str, extra: str):
    """Import an optional dependency or raise :class:`MissingExtraError` naming its extra."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise MissingExtraError(module, extra) from exc
