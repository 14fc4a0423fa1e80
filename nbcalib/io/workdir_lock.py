"""One job at a time in a work directory: the lock a job holds while it writes there (issue 48).

Two jobs writing one work directory at once would interleave their products; the last writer
wins with a record that looks coherent, and neither is told. So every job that writes (the
stages of :class:`nbcalib.pipeline.Calibrator`: ``preprocess`` ... ``report``, and ``run``)
holds ``WORKDIR/.nbcalib.lock`` while it runs:

- the lock is an ``flock`` on that file, which the kernel releases when the process ends, however
  it ends (a ``kill -9`` included), so a crashed job never blocks the next;
- the file says who holds it (process id, host, command, since when): a second job exits at
  once with a one-line error naming them (:class:`~nbcalib.errors.InputError`, exit 2);
- a job that finds the file still naming another process, but the lock free, took it over from
  a job that was killed: it says so in one line and goes on;
- read-only commands (``evaluate``, ``export``, ``topics``) never take it, so they run beside a
  job; one process may take it again while it holds it (nested stages).

Where ``fcntl`` does not exist (Windows) there is no lock, and the job runs as before.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from nbcalib.errors import InputError

try:  # POSIX only
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = ["LOCK_FILE", "holder", "workdir_lock"]

log = logging.getLogger(__name__)

#: The lock file's name in a work directory.
LOCK_FILE = ".nbcalib.lock"

#: Locks this process holds: resolved work directory -> [file descriptor, depth].
_HELD: dict[str, list[int]] = {}


def _command() -> str:
    """What this process is, for the other job's message (``nbcalib calibrate``, ``python``)."""
    first = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path("python")
    if first.name == "nbcalib" or (first.name == "__main__.py" and first.parent.name == "nbcalib"):
        words = [w for w in sys.argv[1:2] if not w.startswith("-")]
        return " ".join(["nbcalib", *words])
    return first.name or "python"


def holder(path) -> dict | None:
    """What the lock file of the work directory ``path`` says (None: empty, absent, unreadable)."""
    try:
        text = (Path(path) / LOCK_FILE).read_text()
    except OSError:
        return None
    try:
        data = json.loads(text) if text.strip() else None
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


def _describe(info: dict | None) -> str:
    if not info:
        return "another process"
    who = f"process {info.get('pid', '?')} on {info.get('host', '?')}"
    return f"{info.get('command', 'a job')} ({who}, since {info.get('since', '?')})"


@contextmanager
def workdir_lock(path):
    """Hold the lock of the work directory ``path`` (created if missing) while the block runs.

    Raises
    ------
    InputError
        Another process holds it: naming that process, its command and since when.
    """
    work = Path(path)
    if fcntl is None:  # pragma: no cover - Windows
        yield
        return
    created = not work.exists()
    work.mkdir(parents=True, exist_ok=True)
    key = str(work.resolve())
    if key in _HELD:  # this process holds it already (a stage inside a job)
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    lock_path = work / LOCK_FILE
    fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise InputError(
            f"in use by {_describe(holder(work))}: wait for it to end, or use another work "
            "directory",
            work,
        ) from None
    previous = holder(work)
    if previous:  # it names a job that no longer holds the lock: one that was killed
        log.warning(
            "%s: took over the lock of %s, which ended without releasing it",
            work,
            _describe(previous),
        )
    info = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "command": _command(),
        "since": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime()),
    }
    os.ftruncate(fd, 0)
    os.pwrite(fd, json.dumps(info).encode(), 0)
    _HELD[key] = [fd, 1]
    try:
        yield
    finally:
        del _HELD[key]
        os.ftruncate(fd, 0)  # released cleanly: an empty file
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        if created and [p.name for p in work.iterdir()] == [LOCK_FILE]:
            # the job made the folder and wrote nothing into it: leave nothing behind
            lock_path.unlink(missing_ok=True)
            try:
                work.rmdir()
            except OSError:
                pass
