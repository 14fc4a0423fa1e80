r"""Progress of the long steps: a bar on a terminal, step lines in a log, nothing when quiet.

One :class:`Progress` per loop that can take more than a few seconds (scans integrated, pairs
simulated, outer iterations, report figures, bytes hashed)::

    with Progress(len(scans), "integrate") as bar:
        for scan in scans:
            ...
            bar.update(what=scan.name)

Where it goes is decided once, when it is made:

* nothing when ``enabled`` is false or the ``nbcalib`` logger is not enabled for INFO: the
  command line's ``-q/--quiet`` sets it to WARNING, and a library user who configured no logging
  inherits the root logger's WARNING, so calling a function directly shows no progress unless
  logging at INFO is turned on (``logging.basicConfig(level=logging.INFO)``);
* a bar redrawn in place with ``\r`` on standard error when it is a terminal: count, label,
  elapsed time and the time left (or the rate when the total is unknown). A log record handled
  while the bar is drawn first erases it, so log lines do not run into the bar;
* the same bar as a text output updated in place in a Jupyter notebook (a display with an id:
  plain text, so a saved notebook keeps its last state, and never a stderr block);
* otherwise (a log file, a pipe, a notebook) plain step lines through the ``nbcalib.progress``
  logger, never ``\r``: at most one every ``interval`` seconds (:data:`LINE_INTERVAL`), and a
  last one when it closes (``integrate: 10/10 scans, in 6.2 s``).

Either way a display that ends within ``interval`` seconds leaves no line behind.

:func:`api_output` is what the Python API (:func:`nbcalib.calibrate`) wraps a call in: where
nothing about logging was configured, it shows the call's progress as the command line shows
it (stage lines and bars, in a notebook as text outputs), so a learner sees progress without
configuring logging; where logging was configured, the lines go to the configured log.

Functions with a ``progress=`` parameter keep its meaning: ``False`` or ``None`` for nothing,
``True`` for a display made here, a callable for a callback of the function's own signature.
Displays are not nested: one is drawn at a time.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import TextIO

__all__ = ["Progress", "api_output", "in_jupyter", "lines_only"]

log = logging.getLogger("nbcalib.progress")

#: Seconds between two redraws of a bar on a terminal.
BAR_REFRESH = 0.1
#: Seconds between two updates of a notebook's bar (each is a message to the browser).
NOTEBOOK_REFRESH = 0.5
#: Seconds between two step lines in a log, and the shortest display that writes any.
LINE_INTERVAL = 5.0
_BAR_WIDTH = 20

_local = threading.local()


@contextlib.contextmanager
def lines_only() -> Iterator[None]:
    """Displays made in this thread meanwhile write step lines, never a bar.

    For work that runs beside other work in threads (the cameras of a rig,
    :mod:`nbcalib.rig_pipeline`): two bars redrawn in one place would overwrite each other.
    """
    before = getattr(_local, "lines_only", False)
    _local.lines_only = True
    try:
        yield
    finally:
        _local.lines_only = before


class Progress:
    """A progress display: a bar on a terminal, throttled step lines in a log, or nothing.

    Parameters
    ----------
    total : int, optional
        Number of steps (or bytes with ``unit="B"``); ``None`` when unknown. May be set later
        through the attribute.
    label : str
        What progresses, first on the line (``"integrate"``).
    enabled : bool
        False: show nothing (the ``progress=False`` of the caller).
    unit : {"", "B"}
        ``"B"``: the counts are bytes, shown in MB.
    interval : float, optional
        Seconds between two step lines in a log (default :data:`LINE_INTERVAL`).
    stream : file-like, optional
        Where a bar is drawn (default: ``sys.stderr`` when it is made); a bar needs its
        ``isatty()`` to be true, otherwise step lines go to the log.

    Attributes
    ----------
    mode : {"bar", "notebook", "lines", "off"}
        What this display does.
    done : int
        Steps done so far.
    total : int or None
    """

    def __init__(
        self,
        total: int | None = None,
        label: str = "",
        *,
        enabled: bool = True,
        unit: str = "",
        interval: float | None = None,
        stream: TextIO | None = None,
    ):
        self.total = total
        self.label = label
        self.unit = unit
        self.interval = LINE_INTERVAL if interval is None else interval
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        self.what = ""
        if not enabled or not log.isEnabledFor(logging.INFO):
            self.mode = "off"
        elif getattr(_local, "lines_only", False):
            self.mode = "lines"
        elif _isatty(self.stream):
            self.mode = "bar"
        elif in_jupyter():
            self.mode = "notebook"
        else:
            self.mode = "lines"
        self._start = self._shown_at = time.monotonic()  # _shown_at: the last line or drawing
        self._drawn = 0  # characters of the bar on the terminal now (0: none)
        self._filter = _EraseBar(self)
        self._handle = None  # the notebook's display
        if self.mode == "bar":
            for handler in _handlers():
                handler.addFilter(self._filter)
            self._draw(self._start)  # the label at once: the first step may take a while
        elif self.mode == "notebook":
            self._show(self._start)

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(failed=exc_type is not None)

    def update(self, n: int = 1, what: str = "") -> None:
        """Count ``n`` more steps done; ``what`` says which (shown after the count).

        Parameters
        ----------
        n : int
            Steps (or bytes) just done.
        what : str
            Short text: the item just done or the current state.
        """
        self.done += n
        self.what = what
        if self.mode == "off":
            return
        now = time.monotonic()
        if self.mode == "bar" and now - self._shown_at >= BAR_REFRESH:
            self._draw(now)
        elif self.mode == "notebook" and now - self._shown_at >= NOTEBOOK_REFRESH:
            self._show(now)
        elif self.mode == "lines" and now - self._shown_at >= self.interval:
            if not (self.total and self.done >= self.total):  # the last step: close() says it
                self._line(now)

    def close(self, failed: bool = False) -> None:
        """The last line (a bar's final state and a line break); nothing more after it.

        Parameters
        ----------
        failed : bool
            The work stopped on an error: end a bar's line, write no last step line.
        """
        if self.mode == "bar":
            for handler in _handlers():
                handler.removeFilter(self._filter)
            now = time.monotonic()
            if failed:
                pass  # the bar stays as it stopped
            elif not self.done or now - self._start < self.interval:
                self._erase()  # as in a log, a quick display leaves no line
            else:
                self._draw(now, final=True)
            if self._drawn:
                self.stream.write("\n")
                self.stream.flush()
        elif self.mode == "notebook":
            now = time.monotonic()
            if failed:
                self._show(now)  # as it stopped
            elif not self.done or now - self._start < self.interval:
                self._show(now, text="")  # as on a terminal, a quick display leaves nothing
            else:
                self._show(now, final=True)
        elif self.mode == "lines" and self.done and not failed:
            now = time.monotonic()
            if now - self._start >= self.interval:  # a quicker display leaves no line
                self._line(now, final=True)
        self.mode = "off"

    # ------------------------------------------------------------------ text

    def _text(self, now: float, final: bool) -> str:
        count = self._count(self.done)
        if self.total:
            count += f"/{self._count(self.total)}"
        elapsed = now - self._start
        if final:
            timing = f"in {elapsed:.1f} s"
        elif self.total and 0 < self.done < self.total:
            timing = f"{elapsed:.1f} s, {elapsed * (self.total - self.done) / self.done:.0f} s left"
        elif self.done and elapsed > 0:
            rate = self.done / elapsed
            timing = f"{elapsed:.1f} s, " + (
                f"{rate / 1e6:.0f} MB/s" if self.unit == "B" else f"{rate:.1f}/s"
            )
        else:
            timing = ""
        return ", ".join(part for part in (f"{count} {self.what}".strip(), timing) if part)

    def _count(self, value: int) -> str:
        return f"{value / 1e6:.1f} MB" if self.unit == "B" else str(value)

    def _line(self, now: float, final: bool = False) -> None:
        log.info("%s: %s", self.label, self._text(now, final))
        self._shown_at = now

    def _bar_text(self, now: float, final: bool) -> str:
        bar = ""
        if self.total:
            filled = min(_BAR_WIDTH, int(_BAR_WIDTH * self.done / self.total))
            bar = f" [{'#' * filled}{'.' * (_BAR_WIDTH - filled)}]"
        return f"{self.label}{bar} {self._text(now, final)}"

    def _show(self, now: float, final: bool = False, text: str | None = None) -> None:
        """Draw the bar as a notebook's text output, in place after the first time."""
        from IPython.display import display

        bundle = {"text/plain": self._bar_text(now, final) if text is None else text}
        if self._handle is None:
            self._handle = display(bundle, raw=True, display_id=True)
        else:
            self._handle.update(bundle, raw=True)
        self._shown_at = now

    def _draw(self, now: float, final: bool = False) -> None:
        text = self._bar_text(now, final)
        text = text[: shutil.get_terminal_size().columns - 1]  # a wrapped line cannot be redrawn
        self.stream.write("\r" + text.ljust(self._drawn))
        self.stream.flush()
        self._drawn = len(text)
        self._shown_at = now

    def _erase(self) -> None:
        if self._drawn:
            self.stream.write("\r" + " " * self._drawn + "\r")
            self.stream.flush()
            self._drawn = 0
            self._shown_at = self._start  # redraw at the next update


def in_jupyter() -> bool:
    """Whether this code runs in a Jupyter kernel (JupyterLab, Notebook, VS Code notebooks)."""
    ipython = sys.modules.get("IPython")
    shell = ipython.get_ipython() if ipython is not None else None
    return type(shell).__name__ == "ZMQInteractiveShell"


def _configured(logger: logging.Logger) -> bool:
    """Whether the user configured logging for ``logger``: a level set, or a handler on its way."""
    return logger.level != logging.NOTSET or any(
        not isinstance(h, logging.NullHandler) for h in _handlers()
    )


@contextlib.contextmanager
def api_output(
    progress: bool | None = None, log: Callable[[str], None] | None = None
) -> Iterator[None]:
    """Show an API call's progress as the command line would, unless logging says otherwise.

    Parameters
    ----------
    progress : bool or None
        ``None`` (the default of the API): where nothing about logging was configured, stage
        lines and bars in a notebook (as text outputs) or on a terminal (standard error);
        nothing elsewhere (a script writing to a pipe or a file), as Python's logging does.
        ``True``: also elsewhere, as lines on standard error. ``False``: nothing, whatever
        was configured. Where logging was configured (a level for the ``nbcalib`` logger, or
        a handler such as ``logging.basicConfig``'s), ``None`` and ``True`` leave it alone:
        the lines go to that log.
    log : callable, optional
        Receives each line instead (``log=print``); the bars are shown as with ``None``.
    """
    logger = logging.getLogger("nbcalib")
    level, handler = logger.level, None
    if log is not None:
        handler = _Forward(log)
    elif progress is False:
        logger.setLevel(logging.WARNING)
    elif not _configured(logger):
        if in_jupyter():
            handler = logging.StreamHandler(sys.stdout)  # text, never a stderr block
        elif progress or _isatty(sys.stderr):
            handler = logging.StreamHandler(sys.stderr)  # as the command line
    if handler is not None:
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        if handler is not None:
            logger.removeHandler(handler)
        logger.setLevel(level)


class _Forward(logging.Handler):
    """Pass the log lines to a callable."""

    def __init__(self, log: Callable[[str], None]):
        super().__init__(logging.INFO)
        self.log = log

    def emit(self, record: logging.LogRecord) -> None:
        self.log(record.getMessage())


class _EraseBar(logging.Filter):
    """Erases a bar before a log record is written (a handler filter; lets every record pass)."""

    def __init__(self, progress: Progress):
        super().__init__()
        self.progress = progress

    def filter(self, record: logging.LogRecord) -> bool:
        self.progress._erase()
        return True


def _handlers() -> list[logging.Handler]:
    """The handlers a record of an ``nbcalib`` logger can reach (``nbcalib``, then ancestors)."""
    handlers = []
    logger: logging.Logger | None = logging.getLogger("nbcalib")
    while logger is not None:
        handlers += logger.handlers
        logger = logger.parent if logger.propagate else None
    return handlers


def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False
