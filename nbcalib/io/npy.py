"""Point clouds in NumPy files (``.npy``, ``.npz``), read into named fields.

``.npy`` holds either a structured array (one field per column name) or a numeric array of shape
(N, 3) ``x, y, z`` or (N, 4) ``x, y, z, intensity``. ``.npz`` holds one array per field (``x``,
``y``, ``z``, ...) or ``points`` (N, 3) / (N, 4) with further per-point arrays (``intensity``,
``t``, ...). Pickled objects are refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._fields import struct_to_fields
from nbcalib.io._files import read_bytes


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
        Missing, empty or unreadable file, or an array that is neither structured nor (N, 3) /
        (N, 4) numeric.
    """
    path = Path(path)
    read_bytes(path)  # missing / empty checks
    try:
        array = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise InputError(f"not a readable .npy file: {exc}", path=path) from None
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
        Missing, empty or unreadable file, or arrays of different lengths.
    """
    path = Path(path)
    read_bytes(path)
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (ValueError, OSError) as exc:
        raise InputError(f"not a readable .npz file: {exc}", path=path) from None
    if "points" in arrays:
        fields = _fields_from_matrix(np.asarray(arrays.pop("points")), path)
        fields.update(arrays)
    else:
        fields = arrays
    lengths = {np.shape(v)[0] if np.ndim(v) else -1 for v in fields.values()}
    if len(lengths) != 1 or -1 in lengths:
        shapes = {name: np.shape(v) for name, v in fields.items()}
        raise InputError(f"arrays of different lengths: {shapes}", path=path)
    return fields
