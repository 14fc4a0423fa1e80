"""NumPy helpers shared by the point cloud, PointCloud2 and bag modules of :mod:`nbcalib.io`.

Raw buffers as arrays, named per-point fields <-> structured arrays, and text rows.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np


def buffer_array(data) -> np.ndarray:
    """A bytes-like object as a uint8 array (a view, no copy); an ndarray as it is."""
    return np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data


def native_columns(array: np.ndarray, names: Iterable[str]) -> dict[str, np.ndarray]:
    """The named columns of a structured array, each contiguous and in native byte order."""
    fields = {}
    for name in names:
        column = array[name]
        fields[name] = np.ascontiguousarray(column, dtype=column.dtype.newbyteorder("="))
    return fields


def struct_to_fields(array: np.ndarray) -> dict[str, np.ndarray]:
    """Named columns of a structured array, native byte order, padding dropped."""
    return native_columns(array, [n for n in array.dtype.names if not n.startswith("_pad")])


def field_arrays(
    fields: Mapping[str, np.ndarray], *, action: str, max_ndim: int | None = None
) -> tuple[dict[str, np.ndarray], int]:
    """Named arrays to write, checked to share their first dimension N.

    Parameters
    ----------
    fields : mapping of str to array_like of shape (N,) or (N, count)
        The fields, in order.
    action : str
        Named in the error for no fields (``"no fields to <action>"``).
    max_ndim : int, optional
        Arrays with more dimensions fail the length check too; None lets them through (for the
        caller's own check).

    Returns
    -------
    arrays : dict of str to ndarray
        ``np.asarray`` of each field, same order.
    n : int
        N.

    Raises
    ------
    ValueError
        No fields, a 0-d array, or lengths that differ (programming errors).
    """
    if not fields:
        raise ValueError(f"no fields to {action}")
    arrays = {name: np.asarray(values) for name, values in fields.items()}
    lengths = {
        values.shape[0] if values.ndim and (max_ndim is None or values.ndim <= max_ndim) else -1
        for values in arrays.values()
    }
    if len(lengths) != 1 or -1 in lengths:
        shapes = {name: values.shape for name, values in arrays.items()}
        raise ValueError(f"fields must be (N,) or (N, count) arrays of one length N, got {shapes}")
    return arrays, lengths.pop()


def fill_table(arrays: Mapping[str, np.ndarray], layout, n: int) -> np.ndarray:
    """A structured array of ``n`` rows of dtype ``layout``, each column set from ``arrays``."""
    table = np.empty(n, dtype=np.dtype(layout))
    for name, values in arrays.items():
        table[name] = values
    return table


def ascii_rows(table: np.ndarray) -> bytes:
    """One text line per row; floats with enough digits to read back bit-exactly."""
    columns, formats = [], []
    for name in table.dtype.names:
        values = table[name]
        values = values[:, None] if values.ndim == 1 else values
        kind = values.dtype.kind
        fmt = {"f": "%.9g" if values.dtype.itemsize == 4 else "%.17g"}.get(kind, "%d")
        for k in range(values.shape[1]):
            columns.append(values[:, k].tolist())
            formats.append(fmt)
    row = " ".join(formats)
    return "".join(row % r + "\n" for r in zip(*columns)).encode("ascii")
