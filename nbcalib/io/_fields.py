"""Named per-point fields <-> NumPy structured arrays, shared by the point cloud file modules."""

from __future__ import annotations

import numpy as np


def struct_to_fields(array: np.ndarray) -> dict[str, np.ndarray]:
    """Named columns of a structured array, native byte order, padding dropped."""
    fields = {}
    for name in array.dtype.names:
        if name.startswith("_pad"):
            continue
        column = array[name]
        fields[name] = np.ascontiguousarray(column, dtype=column.dtype.newbyteorder("="))
    return fields


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
