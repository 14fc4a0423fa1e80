"""Whole-file reads that fail with an InputError, and atomic writes.

Atomic writes: readers see the old file or the new one, whole, never a half-written one.

Every writer in nbcalib that replaces a file goes through :func:`write_bytes_atomic`: the data goes
to a uniquely named temporary file in the same folder (opened exclusively, so it gets the umask's
permissions, unlike ``mkstemp``), is flushed to disk, takes over an existing file's permissions,
and is renamed over the target with :func:`os.replace`.
"""

from __future__ import annotations

import os
import stat
import uuid
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError


def write_bytes_atomic(path, parts: Iterable[bytes | memoryview | np.ndarray]) -> None:
    """Replace ``path`` with the concatenation of ``parts``, atomically."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:12]}.tmp")
    try:
        with open(tmp, "xb") as f:
            for part in parts:
                f.write(part)
            f.flush()
            os.fsync(f.fileno())
        if path.exists():
            os.chmod(tmp, stat.S_IMODE(path.stat().st_mode))
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        unnamed = exc.filename is None or str(exc.filename) == str(tmp)
        if exc.errno is not None and unnamed:  # name the file meant, not the temporary one
            raise type(exc)(exc.errno, exc.strerror, str(path)) from exc
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path, text: str) -> None:
    """Replace ``path`` with ``text`` (UTF-8, newlines as given), atomically."""
    write_bytes_atomic(path, [text.encode("utf-8")])


def read_bytes(path: Path, limit: int | None = None) -> bytes:
    """The whole file (its first ``limit`` bytes); missing, unreadable or empty: an InputError."""
    try:
        with open(path, "rb") as stream:
            data = stream.read(-1 if limit is None else limit)
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    if not data:
        raise InputError("empty file", path=path)
    return data
