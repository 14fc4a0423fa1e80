"""Point clouds in NumPy files (``.npy``, ``.npz``), read into named fields.

``.npy`` holds either a structured array (one field per column name) or a numeric array of shape
(N, 3) ``x, y, z`` or (N, 4) ``x, y, z, intensity``. ``.npz`` holds one array per field (``x``,
``y``, ``z``, ...) or ``points`` (N, 3) / (N, 4) with further per-point arrays (``intensity``,
``t``, ...). Pickled objects are refused.
"""

from __future__ import annotations

import io
import lzma
import math
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._fields import struct_to_fields
from nbcalib.io._files import read_bytes

_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = b"PK"
#: header readers of the .npy versions (3.0 is 2.0 with UTF-8 field names)
_NPY_HEADER_READERS = {
    (1, 0): np.lib.format.read_array_header_1_0,
    (2, 0): np.lib.format.read_array_header_2_0,
    (3, 0): np.lib.format.read_array_header_2_0,
}
#: what NumPy's parser of the header (a Python literal) raises for a corrupt one
_NPY_HEADER_ERRORS = (ValueError, TypeError, IndexError, SyntaxError, tokenize.TokenError)
#: what zipfile raises for a corrupt archive (zlib, bz2 and lzma streams, encryption flags)
_ZIP_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    lzma.LZMAError,
    EOFError,
    OSError,
    RuntimeError,
    ValueError,
)


def _fields_from_matrix(array: np.ndarray, path: Path) -> dict[str, np.ndarray]:
    if array.ndim != 2 or array.shape[1] not in (3, 4) or array.dtype.kind not in "iuf":
        raise InputError(
            f"expected a structured array or a numeric (N, 3) / (N, 4) array, got {array.dtype} "
            f"with shape {array.shape}",
            path=path,
        )
    names = ("x", "y", "z", "intensity")[: array.shape[1]]
    return {name: np.ascontiguousarray(array[:, k]) for k, name in enumerate(names)}


def read_npy_fields(path) -> dict[str, np.ndarray]:
    """The fields of a ``.npy`` file: a structured array's columns, or ``x, y, z[, intensity]``.

    Returns
    -------
    dict of str to ndarray of shape (N,) or (N, count)
        Native byte order.

    Raises
    ------
    InputError
        Missing, empty or unreadable file, not a ``.npy`` file, pickled objects, data shorter than
        the header declares, or an array that is neither structured nor (N, 3) / (N, 4) numeric.
    """
    path = Path(path)
    array = _npy_array(read_bytes(path), path)
    if array.dtype.names:
        return struct_to_fields(array.reshape(-1))
    return _fields_from_matrix(array, path)


def read_npz_fields(path) -> dict[str, np.ndarray]:
    """The fields of a ``.npz`` file: one array per field, ``points`` split into ``x, y, z``.

    Returns
    -------
    dict of str to ndarray
        The archive's arrays as stored, ``points`` (N, 3) / (N, 4) replaced by ``x``, ``y``,
        ``z`` (and ``intensity``), every array of the same length N.

    Raises
    ------
    InputError
        Missing, empty or unreadable file, not a zip archive of ``.npy`` files, or arrays of
        different lengths.
    """
    path = Path(path)
    data = read_bytes(path)
    if not data.startswith(_ZIP_MAGIC):
        raise InputError("not a readable .npz file: it is not a zip archive", path=path)
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            members = {name: archive.read(name) for name in archive.namelist()}
    except _ZIP_ERRORS as exc:
        raise InputError(f"not a readable .npz file: {exc}", path=path) from None
    arrays = {
        name.removesuffix(".npy"): _npy_array(member, path, name)
        for name, member in members.items()
    }
    if "points" in arrays:
        fields = _fields_from_matrix(arrays.pop("points"), path)
        fields.update(arrays)
    else:
        fields = arrays
    lengths = {np.shape(v)[0] if np.ndim(v) else -1 for v in fields.values()}
    if len(lengths) != 1 or -1 in lengths:
        shapes = {name: np.shape(v) for name, v in fields.items()}
        raise InputError(f"arrays of different lengths: {shapes}", path=path)
    return fields


def _npy_array(data: bytes, path: Path, member: str | None = None) -> np.ndarray:
    """The array of the bytes of an ``.npy`` file, its header checked before any data is read.

    ``member``: the name of the bytes in an ``.npz`` archive, for messages. Refused: no ``.npy``
    magic, a corrupt header, pickled objects, and data shorter than the header's shape and dtype.
    """
    where = f"member '{member}': " if member else ""
    if not data.startswith(_NPY_MAGIC):
        raise InputError(f"{where}not a readable .npy file: it is not a NumPy file", path=path)
    stream = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(stream)
        if version not in _NPY_HEADER_READERS:
            raise ValueError(f"unknown .npy version {version}")
        shape, _, dtype = _NPY_HEADER_READERS[version](stream)
    except _NPY_HEADER_ERRORS as exc:
        raise InputError(f"{where}corrupt .npy header ({exc})", path=path) from None
    if any(size < 0 for size in shape):
        raise InputError(f"{where}corrupt .npy header (shape {shape})", path=path)
    if dtype.hasobject:
        raise InputError(f"{where}holds Python objects (pickled data), not numbers", path=path)
    needed, held = math.prod(shape) * dtype.itemsize, len(data) - stream.tell()
    if needed > held:
        raise InputError(
            f"{where}truncated: a {dtype} array of shape {shape} needs {needed} bytes, the file "
            f"holds {held}",
            path=path,
        )
    return np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
