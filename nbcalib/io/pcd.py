"""PCD point cloud files (PCL's format): ascii, binary and binary_compressed, v0.6 and v0.7.

:func:`read_pcd_fields` returns every field of the header with its TYPE/SIZE and COUNT (PCL's
padding fields ``_`` dropped, organised clouds flattened row-major); :func:`write_pcd` writes an
unorganised cloud (``HEIGHT 1``) in any of the three encodings, atomically.
``binary_compressed`` is PCL's: a uint32 compressed size, a uint32 uncompressed size, then the LZF
stream of the fields stored one after the other as column blocks; :func:`lzf_decompress` and
:func:`lzf_compress` wrap the kernels of :mod:`nbcalib.kernels.lzf`.
:func:`nbcalib.io.pointcloud.read_pointcloud` turns the fields into a
:class:`~nbcalib.io.pointcloud.PointCloud`.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._fields import (
    ascii_rows,
    buffer_array,
    field_arrays,
    fill_table,
    struct_to_fields,
)
from nbcalib.io._files import read_bytes, write_bytes_atomic

_PCD_TYPES = {
    ("F", 4): np.float32,
    ("F", 8): np.float64,
    ("I", 1): np.int8,
    ("I", 2): np.int16,
    ("I", 4): np.int32,
    ("I", 8): np.int64,
    ("U", 1): np.uint8,
    ("U", 2): np.uint16,
    ("U", 4): np.uint32,
    ("U", 8): np.uint64,
}
_PCD_ENCODINGS = ("ascii", "binary", "binary_compressed")
_PCD_MAX_HEADER = 1 << 16  # bytes searched for the DATA line
_LZF_MAX_EXPANSION = 88  # LZF's longest back reference: 264 bytes in 3


@dataclass
class _PcdHeader:
    names: list[str]
    dtypes: list[np.dtype]  # little-endian scalar dtype per field
    counts: list[int]
    width: int
    height: int
    points: int
    encoding: str
    data_offset: int  # byte offset of the data section


def _parse_pcd_header(data: bytes, path: Path) -> _PcdHeader:
    values: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = data.find(b"\n", pos)
        if end < 0:
            end = len(data)
        if pos >= len(data) or pos > _PCD_MAX_HEADER:
            raise InputError("no DATA line in the header (not a PCD file?)", path=path)
        try:
            line = data[pos:end].decode("ascii").strip()
        except UnicodeDecodeError:
            raise InputError(
                "header is not ASCII text before its DATA line (not a PCD file?)", path=path
            ) from None
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *rest = line.split()
        key = key.upper()
        values[key] = rest
        if key == "DATA":
            break

    def ints(key: str, default=None) -> list[int]:
        if key not in values:
            if default is None:
                raise InputError(f"header has no {key} line", path=path)
            return default
        try:
            return [int(v) for v in values[key]]
        except ValueError:
            raise InputError(f"bad {key} line: {' '.join(values[key])!r}", path=path) from None

    names = values.get("FIELDS", values.get("COLUMNS"))
    if not names:
        raise InputError("header has no FIELDS line", path=path)
    n_fields = len(names)
    sizes = ints("SIZE")
    types = [t.upper() for t in values.get("TYPE", [])]
    counts = ints("COUNT", [1] * n_fields)
    if not (len(sizes) == len(types) == len(counts) == n_fields):
        raise InputError(
            f"header lists {n_fields} FIELDS but {len(sizes)} SIZE, {len(types)} TYPE and "
            f"{len(counts)} COUNT entries",
            path=path,
        )
    dtypes = []
    for name, typ, size, count in zip(names, types, sizes, counts):
        if (typ, size) not in _PCD_TYPES:
            raise InputError(f"field '{name}' has unsupported TYPE {typ} SIZE {size}", path=path)
        if not 1 <= count <= len(data):  # more values than the file has bytes: corrupt
            raise InputError(f"field '{name}' has COUNT {count}", path=path)
        dtypes.append(np.dtype(_PCD_TYPES[(typ, size)]).newbyteorder("<"))

    def point_count(key: str) -> int | None:
        """The one number >= 0 of a WIDTH, HEIGHT or POINTS line; None without the line."""
        if key not in values:
            return None
        numbers = ints(key)
        if len(numbers) != 1 or numbers[0] < 0:
            raise InputError(f"bad {key} line: {' '.join(values[key])!r}", path=path)
        return numbers[0]

    width, height, points = (point_count(k) for k in ("WIDTH", "HEIGHT", "POINTS"))
    height = 1 if height is None else height
    if width is None and points is None:
        raise InputError("header has neither WIDTH nor POINTS", path=path)
    if points is None:
        points = width * height
    if width is None:
        width, height = points, 1
    if width * height != points:
        raise InputError(
            f"WIDTH {width} x HEIGHT {height} does not match POINTS {points}", path=path
        )
    encoding = (values["DATA"] or [""])[0].lower()
    if encoding not in _PCD_ENCODINGS:
        raise InputError(
            f"unknown DATA encoding '{encoding}'; expected one of {', '.join(_PCD_ENCODINGS)}",
            path=path,
        )
    real = [n for n in names if n != "_"]  # "_" is PCL's padding
    if len(set(real)) != len(real):
        raise InputError(f"duplicate field names in FIELDS: {' '.join(names)}", path=path)
    return _PcdHeader(names, dtypes, counts, width, height, points, encoding, pos)


def _pcd_struct_dtype(header: _PcdHeader) -> np.dtype:
    """Packed structured dtype of one point; padding fields "_" become "_pad<k>"."""
    return np.dtype(
        [
            (name if name != "_" else f"_pad{k}", dt, (count,) if count > 1 else ())
            for k, (name, dt, count) in enumerate(zip(header.names, header.dtypes, header.counts))
        ]
    )


def read_pcd_fields(path) -> dict[str, np.ndarray]:
    """Every field of a PCD file (ascii, binary or binary_compressed), in file order.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.pcd`` file.

    Returns
    -------
    dict of str to ndarray
        One array per field, shape (N,) or (N, COUNT), with the TYPE/SIZE of the header; PCL's
        padding fields ``_`` are dropped. N = POINTS (organised clouds are flattened row-major).

    Raises
    ------
    InputError
        Bad header, truncated or corrupt data; the message names the file.
    """
    path = Path(path)
    data = read_bytes(path)
    header = _parse_pcd_header(data, path)
    dtype = _pcd_struct_dtype(header)
    n = header.points
    body = memoryview(data)[header.data_offset :]
    if header.encoding == "binary":
        held = len(body) // dtype.itemsize
        if held < n:
            raise InputError(f"expected {n} points, file holds {held}", path=path)
        array = np.frombuffer(body, dtype=dtype, count=n)
    elif header.encoding == "binary_compressed":
        return _decode_pcd_compressed(body, dtype, n, path)
    else:
        array = _decode_pcd_ascii(body, dtype, n, path)
    return struct_to_fields(array)


def _decode_pcd_ascii(body: memoryview, dtype: np.dtype, n: int, path: Path) -> np.ndarray:
    if n == 0:
        return np.zeros(0, dtype=dtype)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data"
        try:
            array = np.loadtxt(io.BytesIO(body), dtype=dtype, ndmin=1, max_rows=n)
        except ValueError as exc:
            raise InputError(f"bad ascii data: {exc}", path=path) from None
    if array.shape[0] < n:
        raise InputError(f"expected {n} points, file holds {array.shape[0]}", path=path)
    return array


def _decode_pcd_compressed(
    body: memoryview, dtype: np.dtype, n: int, path: Path
) -> dict[str, np.ndarray]:
    """binary_compressed: uint32 compressed size, uint32 size, then LZF of the column blocks."""
    if n == 0:
        return struct_to_fields(np.zeros(0, dtype=dtype))
    if len(body) < 8:
        raise InputError("binary_compressed data ends before its size fields", path=path)
    compressed_size, size = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
    expected = n * dtype.itemsize
    if size != expected:
        raise InputError(
            f"binary_compressed data holds {size} bytes uncompressed, expected {expected} "
            f"for {n} points",
            path=path,
        )
    if size > _LZF_MAX_EXPANSION * compressed_size:  # refused before allocating ``size`` bytes
        raise InputError(
            f"binary_compressed data of {compressed_size} bytes cannot hold {size} bytes",
            path=path,
        )
    if len(body) - 8 < compressed_size:
        raise InputError(
            f"truncated: compressed data of {compressed_size} bytes, file holds {len(body) - 8}",
            path=path,
        )
    try:
        raw = lzf_decompress(body[8 : 8 + compressed_size], size)
    except ValueError as exc:
        raise InputError(f"corrupt binary_compressed data: {exc}", path=path) from None
    # column-major: each field is one contiguous block of n values (times COUNT)
    fields = {}
    offset = 0
    for name in dtype.names:
        field_dtype = dtype.fields[name][0]
        nbytes = n * field_dtype.itemsize
        if not name.startswith("_pad"):
            block = raw[offset : offset + nbytes].view(field_dtype.base)  # copy: aligned, native
            fields[name] = block.astype(field_dtype.base.newbyteorder("=")).reshape(
                (n, *field_dtype.shape)
            )
        offset += nbytes
    return fields


def _pcd_type_code(dtype: np.dtype) -> tuple[str, int]:
    for (code, size), np_type in _PCD_TYPES.items():
        if dtype == np.dtype(np_type):
            return code, size
    raise ValueError(f"PCD cannot store dtype {dtype}; use int8..uint64, float32 or float64")


def _as_field_table(fields: Mapping[str, np.ndarray]) -> tuple[np.ndarray, int]:
    """Pack named (N,) / (N, count) arrays into one little-endian structured array."""
    arrays, n = field_arrays(fields, action="write")
    layout = []
    for name, values in arrays.items():
        if values.ndim > 2 or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise ValueError(f"field {name!r} must be a valid name with shape (N,) or (N, count)")
        count = values.shape[1] if values.ndim == 2 else 1
        _pcd_type_code(values.dtype.newbyteorder("="))  # validates the type
        layout.append((name, values.dtype.newbyteorder("<"), (count,) if values.ndim == 2 else ()))
    return fill_table(arrays, layout, n), n


def write_pcd(path, fields: Mapping[str, np.ndarray], *, encoding: str = "binary") -> None:
    """Write a PCD v0.7 file (unorganised: ``HEIGHT 1``), atomically.

    Parameters
    ----------
    path : str or os.PathLike
        The ``.pcd`` file to write (replaced if it exists).
    fields : mapping of str to ndarray of shape (N,) or (N, count)
        The fields in file order, each with its own dtype (int8..uint64, float32, float64), e.g.
        ``x, y, z`` float32 (metres, sensor frame), ``intensity`` float32, ``t`` float32/float64
        (seconds) or uint32 (nanoseconds), ``ring`` uint16.
    encoding : {"ascii", "binary", "binary_compressed"}
        ``binary_compressed`` stores each field as one block and LZF-compresses the whole, as PCL.

    Raises
    ------
    ValueError
        Unequal lengths, an unsupported dtype or an unknown encoding (programming errors).
    """
    if encoding not in _PCD_ENCODINGS:
        raise ValueError(f"encoding must be one of {_PCD_ENCODINGS}, got {encoding!r}")
    table, n = _as_field_table(fields)
    names, sizes, types, counts = [], [], [], []
    for name in table.dtype.names:
        field_dtype = table.dtype.fields[name][0]
        code, size = _pcd_type_code(field_dtype.base.newbyteorder("="))
        names.append(name)
        sizes.append(str(size))
        types.append(code)
        counts.append(str(field_dtype.shape[0] if field_dtype.shape else 1))
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {' '.join(names)}\n"
        f"SIZE {' '.join(sizes)}\n"
        f"TYPE {' '.join(types)}\n"
        f"COUNT {' '.join(counts)}\n"
        f"WIDTH {n}\n"
        "HEIGHT 1\n"
        "VIEWPOINT 0 0 0 1 0 0 0\n"
        f"POINTS {n}\n"
        f"DATA {encoding}\n"
    ).encode("ascii")
    if encoding == "binary":
        body = [table.tobytes()]
    elif encoding == "binary_compressed":
        raw = b"".join(np.ascontiguousarray(table[name]).tobytes() for name in table.dtype.names)
        packed = lzf_compress(raw) if raw else b""
        body = [np.array([len(packed), len(raw)], dtype="<u4").tobytes(), packed]
    else:
        body = [ascii_rows(table)]
    write_bytes_atomic(path, [header, *body])


# ----------------------------------------------------------------------------------------------
# LZF wrappers (kernels in nbcalib.kernels.lzf)


def lzf_decompress(data, size: int) -> np.ndarray:
    """Decode an LZF stream that holds exactly ``size`` bytes; wraps ``_lzf_decompress``.

    Parameters
    ----------
    data : bytes-like or ndarray of uint8
        The compressed stream.
    size : int
        Number of bytes it decodes to.

    Returns
    -------
    ndarray of shape (size,), uint8

    Raises
    ------
    ValueError
        Truncated or corrupt stream, or one that does not decode to exactly ``size`` bytes.
    """
    from nbcalib.kernels.lzf import (
        ERR_BAD_REFERENCE,
        ERR_OUTPUT_FULL,
        ERR_TRUNCATED,
        _lzf_decompress,
    )

    src = np.ascontiguousarray(buffer_array(data), dtype=np.uint8)
    dst = np.empty(int(size), dtype=np.uint8)
    written = _lzf_decompress(src, dst)
    problems = {
        ERR_OUTPUT_FULL: f"LZF stream decodes to more than {size} bytes",
        ERR_BAD_REFERENCE: "LZF back reference points before the start of the output",
        ERR_TRUNCATED: "LZF stream ends inside a run",
    }
    if written in problems:
        raise ValueError(problems[written])
    if written != size:
        raise ValueError(f"LZF stream decodes to {written} bytes, expected {size}")
    return dst


def lzf_compress(data) -> bytes:
    """Encode bytes as an LZF stream (greedy hash matching, like liblzf); wraps ``_lzf_compress``.

    Parameters
    ----------
    data : bytes-like or ndarray of uint8

    Returns
    -------
    bytes
        The stream; :func:`lzf_decompress` restores ``data`` from it.
    """
    from nbcalib.kernels.lzf import _lzf_compress

    src = np.ascontiguousarray(buffer_array(data).reshape(-1).view(np.uint8))
    dst = np.empty(src.shape[0] + src.shape[0] // 32 + 2, dtype=np.uint8)
    written = _lzf_compress(src, dst)
    return dst[:written].tobytes()
