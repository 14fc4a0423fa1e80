"""PLY point cloud files: the ``vertex`` element, ascii or binary (little or big endian).

:func:`read_ply_fields` returns every vertex property (faces and later elements are ignored);
:func:`~nbcalib.io.pointcloud.read_pointcloud` makes a
:class:`~nbcalib.io.pointcloud.PointCloud` of them (this module knows the format only);
:func:`write_ply` writes float32 ``x, y, z`` (and ``intensity``) vertices with the reference's
header, atomically.
"""

from __future__ import annotations

import io
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._fields import ascii_rows, fill_table, struct_to_fields
from nbcalib.io._files import read_bytes, write_bytes_atomic

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


@dataclass
class _PlyElement:
    name: str
    count: int
    properties: list[tuple[str, str]] = field(default_factory=list)  # (name, numpy code)
    has_list: bool = False


def _parse_ply_header(data: bytes, path: Path) -> tuple[str, list[_PlyElement], int]:
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise InputError("not a PLY file (no 'ply' ... 'end_header' header)", path=path)
    newline = data.find(b"\n", end)
    offset = newline + 1 if newline >= 0 else len(data)
    fmt = None
    elements: list[_PlyElement] = []
    for raw_line in data[:end].decode("ascii", errors="replace").splitlines()[1:]:
        words = raw_line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                elements.append(_PlyElement(words[1], int(words[2])))
                if elements[-1].count < 0:
                    raise ValueError("negative count")
            elif words[0] == "property" and words[1] == "list":
                elements[-1].has_list = True
                elements[-1].properties.append((words[4], "list"))
            elif words[0] == "property":
                if words[1] not in _PLY_TYPES:
                    raise InputError(f"unknown PLY property type '{words[1]}'", path=path)
                elements[-1].properties.append((words[2], _PLY_TYPES[words[1]]))
            else:
                raise InputError(f"bad header line {raw_line.strip()!r}", path=path)
        except (IndexError, ValueError):
            raise InputError(f"bad header line {raw_line.strip()!r}", path=path) from None
    if fmt not in _PLY_FORMATS:
        raise InputError(f"unknown PLY format '{fmt}'", path=path)
    return fmt, elements, offset


def _vertex_dtype(vertex: _PlyElement, byte_order: str, path: Path) -> np.dtype:
    """The vertex element's row dtype; its list properties, none or duplicates refused."""
    if vertex.has_list:
        raise InputError("vertex element with list properties is not supported", path=path)
    names = [name for name, _ in vertex.properties]
    if not names:
        raise InputError("vertex element without properties", path=path)
    if len(set(names)) != len(names):
        raise InputError(f"duplicate vertex properties: {' '.join(names)}", path=path)
    return np.dtype([(name, byte_order + code) for name, code in vertex.properties])


def _vertex_layout(path: Path):
    """``(dtype, count, offset)`` of a binary PLY whose first element is the vertices; else None.

    Checks what :func:`read_ply_fields` checks of such a file, and that the file holds its
    vertices.
    """
    head = read_bytes(path, 1 << 16)  # a PLY header fits
    if b"end_header" not in head:
        return None  # a header past 64 KB: the whole file is parsed
    fmt, elements, offset = _parse_ply_header(head, path)
    if fmt == "ascii" or not elements or elements[0].name != "vertex":
        return None
    vertex = elements[0]
    dtype = _vertex_dtype(vertex, _PLY_FORMATS[fmt], path)
    held = max(path.stat().st_size - offset, 0) // dtype.itemsize
    if held < vertex.count:
        raise InputError(f"expected {vertex.count} vertices, file holds {held}", path=path)
    return dtype, vertex.count, offset


def read_ply_vertex_header(path) -> tuple[int, list[str]]:
    """The vertex count and property names of a PLY file, from its header alone.

    For a binary file, the file must be long enough for its vertices (a truncated file is an
    :class:`~nbcalib.errors.InputError` naming it, as :func:`read_ply_fields` would raise). An
    ascii file is read whole (its rows cannot be counted from the header).
    """
    path = Path(path)
    layout = _vertex_layout(path)
    if layout is None:
        fields = read_ply_fields(path)
        return len(next(iter(fields.values()))), list(fields)
    dtype, count, _ = layout
    return count, list(dtype.names)


def read_ply_xyzi(path) -> np.ndarray | None:
    """The vertices as one (N, 4) float32 block, if that is how the file stores them.

    For a binary PLY whose vertices come first as exactly ``x, y, z, intensity``, float32 in
    native byte order (how a work directory stores a dense cloud): read straight from the file,
    no column copied; columns 0-2 are the points and 3 the intensities. None for any other
    layout (:func:`read_ply_fields` reads every layout).
    """
    path = Path(path)
    layout = _vertex_layout(path)
    if layout is None:
        return None
    dtype, count, offset = layout
    f32 = np.dtype(np.float32)
    if (
        dtype.names != ("x", "y", "z", "intensity")
        or dtype.itemsize != 16
        or [dtype.fields[n] for n in dtype.names] != [(f32, k) for k in (0, 4, 8, 12)]
    ):
        return None  # another layout, or not native float32
    block = np.fromfile(path, dtype=np.float32, count=4 * count, offset=offset)
    return block.reshape(count, 4)


def read_ply_fields(path) -> dict[str, np.ndarray]:
    """Every property of the ``vertex`` element of a PLY file (ascii, binary LE or BE).

    Faces and other elements after the vertices are ignored. Elements before the vertices are
    skipped if they have no list properties.

    Returns
    -------
    dict of str to ndarray of shape (N,)
        One array per vertex property, native byte order.
    """
    path = Path(path)
    layout = _vertex_layout(path)
    if layout is not None:  # binary, vertices first: straight from the file, no copy of it
        dtype, count, offset = layout
        if count == 0:
            return struct_to_fields(np.zeros(0, dtype=dtype))
        return struct_to_fields(np.fromfile(path, dtype=dtype, count=count, offset=offset))
    data = read_bytes(path)
    fmt, elements, offset = _parse_ply_header(data, path)
    byte_order = _PLY_FORMATS[fmt]
    binary = fmt != "ascii"
    skip_rows = 0
    for element in elements:
        if element.name == "vertex":
            break
        if element.has_list:
            raise InputError(
                f"element '{element.name}' with list properties before the vertices",
                path=path,
            )
        if binary:
            offset += element.count * sum(np.dtype(code).itemsize for _, code in element.properties)
        else:
            skip_rows += element.count
    else:
        raise InputError("no 'vertex' element", path=path)
    n = element.count
    dtype = _vertex_dtype(element, byte_order, path)
    if n == 0:
        array = np.zeros(0, dtype=dtype)
    elif binary:
        held = max(len(data) - offset, 0) // dtype.itemsize
        if held < n:
            raise InputError(f"expected {n} vertices, file holds {held}", path=path)
        array = np.frombuffer(data, dtype=dtype, count=n, offset=offset)
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            try:
                array = np.loadtxt(
                    io.BytesIO(data[offset:]), dtype=dtype, ndmin=1, skiprows=skip_rows, max_rows=n
                )
            except ValueError as exc:
                raise InputError(f"bad ascii vertex data: {exc}", path=path) from None
        if array.shape[0] < n:
            raise InputError(f"expected {n} vertices, file holds {array.shape[0]}", path=path)
    return struct_to_fields(array)


def write_ply(
    path,
    points: np.ndarray,
    intensity: np.ndarray | None = None,
    *,
    encoding: str = "binary",
) -> None:
    """Write vertices as PLY, atomically, like the reference's ``<bag>.ply``.

    The binary header is exactly the reference's (``glk::save_ply_binary``)::

        ply
        format binary_little_endian 1.0
        element vertex N
        property float x
        property float y
        property float z
        property float intensity
        end_header

    Parameters
    ----------
    path : str or os.PathLike
        The ``.ply`` file (replaced if it exists).
    points : ndarray of shape (N, 3)
        Points, stored as float32 (metres, in the frame of the cloud).
    intensity : ndarray of shape (N,), optional
        Stored as float32; omitted from the file when None.
    encoding : {"binary", "ascii"}
        Binary little endian (the reference's) or ascii.
    """
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {points.shape}")
    if encoding not in ("binary", "ascii"):
        raise ValueError(f"encoding must be 'binary' or 'ascii', got {encoding!r}")
    columns = {"x": points[:, 0], "y": points[:, 1], "z": points[:, 2]}
    if intensity is not None:
        intensity = np.asarray(intensity)
        if intensity.shape != (points.shape[0],):
            raise ValueError(
                f"intensity must have shape ({points.shape[0]},), got {intensity.shape}"
            )
        columns["intensity"] = intensity
    n = points.shape[0]
    table = fill_table(columns, [(name, "<f4") for name in columns], n)
    header = "".join(
        [
            "ply\n",
            "format binary_little_endian 1.0\n" if encoding == "binary" else "format ascii 1.0\n",
            f"element vertex {n}\n",
            *[f"property float {name}\n" for name in columns],
            "end_header\n",
        ]
    ).encode("ascii")
    body = table.tobytes() if encoding == "binary" else ascii_rows(table)
    write_bytes_atomic(path, [header, body])
