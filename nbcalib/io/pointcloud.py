"""Point cloud files: PCD (ascii, binary, binary_compressed), PLY, KITTI ``.bin``, NumPy.

Every reader returns a :class:`PointCloud`: the finite points in the LiDAR frame (metres), the
intensity channel and the per-point times picked by the reference toolbox's rules, and every field
of the file as read. The same rules serve ``sensor_msgs/PointCloud2`` messages
(:mod:`nbcalib.io.pointcloud2`) through :func:`pointcloud_from_fields`:

- **intensity** (``intensity_channel="auto"``): ``reflectivity`` wins over ``intensity``; any
  other name is used as given. Values are kept as stored (no scaling), as float64.
- **times** (``time_field="auto"``): the first of ``t``, ``time``, ``time_stamp``, ``timestamp``.
  Integer fields hold nanoseconds (the reference reads ``uint32`` so; nbcalib extends it to every
  integer type), float fields hold seconds. Then the reference's ``TimeKeeper`` normalisation:
  negative times are shifted so that the minimum is 0; if the first time is still >= 1 s the
  times are absolute and are made relative to the first point; float values above 1e16 are taken
  as nanoseconds (Livox). The result is seconds relative to the scan, float64.
- **finite points only**: rows whose x, y or z is not finite are dropped from every field.

Writers (:func:`write_pcd`, :func:`write_ply`, :func:`write_kitti_bin`) write to a temporary file
beside the target and rename it into place, so a crash never leaves a file that looks complete.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._files import write_bytes_atomic

#: Suffixes that :func:`read_pointcloud` understands.
POINTCLOUD_SUFFIXES = (".pcd", ".ply", ".bin", ".npy", ".npz")

#: Intensity channels in the order ``intensity_channel="auto"`` prefers them (reference rule).
INTENSITY_PRIORITY = ("reflectivity", "intensity")

#: Per-point time fields in the order ``time_field="auto"`` looks for them (reference rule).
TIME_FIELDS = ("t", "time", "time_stamp", "timestamp")

_FIRST_TIME_ABSOLUTE_S = 1.0  # a first time >= 1 s means absolute times (reference TimeKeeper)
_NANOSECONDS_ABOVE = 1e16  # float "seconds" above this are nanoseconds (Livox)


@dataclass
class PointCloud:
    """One point cloud with its intensity and per-point times.

    Attributes
    ----------
    points : ndarray of shape (N, 3), float64
        Finite points in the sensor (LiDAR) frame, metres. Rows with a non-finite x, y or z in the
        file are dropped.
    intensity : ndarray of shape (N,), float64, or None
        The chosen intensity channel, raw values as stored (no scaling); None when there is none.
    times : ndarray of shape (N,), float64, or None
        Per-point time in seconds relative to the scan (module docstring); None when the source
        has no time field.
    fields : dict of str to ndarray
        Every field as read, with its own dtype, shape (N,) or (N, count), same rows as ``points``.
    """

    points: np.ndarray
    intensity: np.ndarray | None = None
    times: np.ndarray | None = None
    fields: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.points.shape[0])


# ----------------------------------------------------------------------------------------------
# Fields -> PointCloud (shared with PointCloud2 messages)


def select_intensity_field(
    names: Iterable[str], intensity_channel: str | None = "auto", *, source=None
) -> str | None:
    """Name of the intensity field to use, by the reference's rule.

    Parameters
    ----------
    names : iterable of str
        The available field names.
    intensity_channel : str or None
        ``"auto"`` picks ``reflectivity`` over ``intensity`` (None if neither exists); None or
        ``"none"`` means no intensity; any other name must exist.
    source : str or os.PathLike, optional
        File (or bag and topic) named in the error message.

    Raises
    ------
    InputError
        A named channel that does not exist; the message lists the available fields.
    """
    names = list(names)
    if intensity_channel is None or intensity_channel == "none":
        return None
    if intensity_channel == "auto":
        return next((n for n in INTENSITY_PRIORITY if n in names), None)
    if intensity_channel not in names:
        raise InputError(
            f"intensity channel '{intensity_channel}' not found; available fields: "
            f"{', '.join(names) or '(none)'}",
            path=source,
        )
    return intensity_channel


def select_time_field(
    names: Iterable[str], time_field: str | None = "auto", *, source=None
) -> str | None:
    """Name of the per-point time field: ``"auto"`` takes the first of :data:`TIME_FIELDS`.

    None or ``"none"`` means no times; any other name must exist (else :class:`InputError`).
    """
    names = list(names)
    if time_field is None or time_field == "none":
        return None
    if time_field == "auto":
        return next((n for n in TIME_FIELDS if n in names), None)
    if time_field not in names:
        raise InputError(
            f"time field '{time_field}' not found; available fields: "
            f"{', '.join(names) or '(none)'}",
            path=source,
        )
    return time_field


def normalize_point_times(raw: np.ndarray) -> np.ndarray:
    """Per-point times in seconds relative to the scan, by the reference's ``TimeKeeper`` rules.

    Parameters
    ----------
    raw : ndarray of shape (N,)
        The time field as stored: integer types are nanoseconds, float types seconds.

    Returns
    -------
    ndarray of shape (N,), float64
        Seconds. Negative times are shifted so the minimum is 0; then, if the first time is >= 1 s,
        all times are made relative to the first point (they were absolute); float values above
        1e16 are treated as nanoseconds. Integer inputs are shifted in integer arithmetic, so
        absolute nanosecond stamps keep full precision.
    """
    raw = np.asarray(raw)
    if raw.ndim != 1:
        raise ValueError(f"point times must be 1-D, got shape {raw.shape}")
    if raw.size == 0:
        return np.zeros(0)
    if np.issubdtype(raw.dtype, np.integer):
        ns = raw.astype(np.int64)  # absolute ns stamps fit in int64 until the year 2262
        if ns.min() < 0:
            ns = ns - ns.min()
        if ns[0] >= _FIRST_TIME_ABSOLUTE_S * 1e9:
            ns = ns - ns[0]
        return ns.astype(np.float64) * 1e-9
    if not np.issubdtype(raw.dtype, np.floating):
        raise ValueError(f"point times must be integer or float, got {raw.dtype}")
    t = raw.astype(np.float64)
    finite = np.isfinite(t)
    if finite.any() and t[finite].min() < 0.0:
        t = t - t[finite].min()
    if t[0] >= _FIRST_TIME_ABSOLUTE_S:
        if t[0] > _NANOSECONDS_ABOVE:
            return (t - t[0]) * 1e-9
        t = t - t[0]
    return t


def pointcloud_from_fields(
    fields: Mapping[str, np.ndarray],
    *,
    intensity_channel: str | None = "auto",
    time_field: str | None = "auto",
    source=None,
) -> PointCloud:
    """Build a :class:`PointCloud` from named per-point arrays (one file or message).

    Parameters
    ----------
    fields : mapping of str to ndarray of shape (N,) or (N, count)
        Every field, same length; must contain ``x``, ``y``, ``z``.
    intensity_channel : str or None
        See :func:`select_intensity_field`.
    time_field : str or None
        See :func:`select_time_field`.
    source : str or os.PathLike, optional
        File (or bag and topic) named in error messages.

    Returns
    -------
    PointCloud
        Non-finite xyz rows dropped from every field.
    """
    names = list(fields)
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise InputError(
            f"no {', '.join(missing)} field; fields present: {', '.join(names) or '(none)'}",
            path=source,
        )
    for c in "xyz":
        if fields[c].ndim != 1:
            raise InputError(f"field '{c}' has count {fields[c].shape[1:]}, expected 1", source)
    xyz = np.stack([fields[c].astype(np.float64, copy=False) for c in "xyz"], axis=1)
    finite = np.isfinite(xyz).all(axis=1)
    if finite.all():
        kept = dict(fields)
    else:
        xyz = xyz[finite]
        kept = {name: values[finite] for name, values in fields.items()}
    points = np.ascontiguousarray(xyz, dtype=np.float64)

    intensity = None
    name = select_intensity_field(names, intensity_channel, source=source)
    if name is not None:
        values = kept[name]
        if values.ndim != 1 or not (
            np.issubdtype(values.dtype, np.integer) or np.issubdtype(values.dtype, np.floating)
        ):
            raise InputError(
                f"intensity field '{name}' must be one number per point, got {values.dtype} "
                f"with shape {values.shape}",
                path=source,
            )
        intensity = values.astype(np.float64)

    times = None
    name = select_time_field(names, time_field, source=source)
    if name is not None:
        values = kept[name]
        if values.ndim != 1 or values.dtype.kind not in "iuf":
            raise InputError(
                f"time field '{name}' must be one number per point, got {values.dtype} "
                f"with shape {values.shape}",
                path=source,
            )
        times = normalize_point_times(values)
    return PointCloud(points=points, intensity=intensity, times=times, fields=kept)


# ----------------------------------------------------------------------------------------------
# Dispatch


def read_pointcloud(
    path, *, intensity_channel: str | None = "auto", time_field: str | None = "auto"
) -> PointCloud:
    """Read a point cloud file, by suffix: ``.pcd``, ``.ply``, ``.bin`` (KITTI), ``.npy``, ``.npz``.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    intensity_channel : str or None
        ``"auto"`` (``reflectivity`` over ``intensity``), a field name, or None (no intensity).
    time_field : str or None
        ``"auto"`` (first of ``t``, ``time``, ``time_stamp``, ``timestamp``), a name, or None.

    Returns
    -------
    PointCloud
        Points in the sensor frame (metres), intensity as stored, times in seconds relative to
        the scan (module docstring).

    Raises
    ------
    InputError
        Missing, empty, truncated or corrupt file, or an unknown suffix; the message names the file.

    Notes
    -----
    ``.npy`` holds either a structured array (one field per column name) or a float array of shape
    (N, 3) ``x, y, z`` or (N, 4) ``x, y, z, intensity``. ``.npz`` holds one array per field
    (``x``, ``y``, ``z``, ...) or ``points`` (N, 3) with optional ``intensity`` and ``t``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    readers = {
        ".pcd": read_pcd_fields,
        ".ply": read_ply_fields,
        ".bin": read_kitti_bin_fields,
        ".npy": _read_npy_fields,
        ".npz": _read_npz_fields,
    }
    if suffix not in readers:
        raise InputError(
            f"unknown point cloud suffix '{path.suffix}'; expected one of "
            f"{', '.join(POINTCLOUD_SUFFIXES)}",
            path=path,
        )
    fields = readers[suffix](path)
    return pointcloud_from_fields(
        fields, intensity_channel=intensity_channel, time_field=time_field, source=path
    )


def _read_bytes(path: Path) -> bytes:
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path=path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=path) from None
    if not data:
        raise InputError("empty file", path=path)
    return data


# ----------------------------------------------------------------------------------------------
# PCD

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
        if count < 1:
            raise InputError(f"field '{name}' has COUNT {count}", path=path)
        dtypes.append(np.dtype(_PCD_TYPES[(typ, size)]).newbyteorder("<"))

    width = ints("WIDTH", [-1])[0]
    height = ints("HEIGHT", [1])[0]
    points = ints("POINTS", [-1])[0]
    if width < 0 and points < 0:
        raise InputError("header has neither WIDTH nor POINTS", path=path)
    if points < 0:
        points = width * height
    if width < 0:
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


def _struct_to_fields(array: np.ndarray) -> dict[str, np.ndarray]:
    """Named columns of a structured array, native byte order, padding dropped."""
    fields = {}
    for name in array.dtype.names:
        if name.startswith("_pad"):
            continue
        column = array[name]
        fields[name] = np.ascontiguousarray(column, dtype=column.dtype.newbyteorder("="))
    return fields


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
    data = _read_bytes(path)
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
    return _struct_to_fields(array)


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
        return _struct_to_fields(np.zeros(0, dtype=dtype))
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
    if not fields:
        raise ValueError("no fields to write")
    arrays = {name: np.asarray(values) for name, values in fields.items()}
    lengths = {values.shape[0] if values.ndim else -1 for values in arrays.values()}
    if len(lengths) != 1 or -1 in lengths:
        shapes = {name: values.shape for name, values in arrays.items()}
        raise ValueError(f"fields must be (N,) or (N, count) arrays of one length N, got {shapes}")
    n = lengths.pop()
    layout = []
    for name, values in arrays.items():
        if values.ndim > 2 or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name):
            raise ValueError(f"field {name!r} must be a valid name with shape (N,) or (N, count)")
        count = values.shape[1] if values.ndim == 2 else 1
        _pcd_type_code(values.dtype.newbyteorder("="))  # validates the type
        layout.append((name, values.dtype.newbyteorder("<"), (count,) if values.ndim == 2 else ()))
    table = np.empty(n, dtype=np.dtype(layout))
    for name, values in arrays.items():
        table[name] = values
    return table, n


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
        body = [_ascii_rows(table)]
    write_bytes_atomic(path, [header, *body])


def _ascii_rows(table: np.ndarray) -> bytes:
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

    src = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    src = np.ascontiguousarray(src, dtype=np.uint8)
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

    src = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    src = np.ascontiguousarray(src.reshape(-1).view(np.uint8))
    dst = np.empty(src.shape[0] + src.shape[0] // 32 + 2, dtype=np.uint8)
    written = _lzf_compress(src, dst)
    return dst[:written].tobytes()


# ----------------------------------------------------------------------------------------------
# PLY

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
    data = _read_bytes(path)
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
    if element.has_list:
        raise InputError("vertex element with list properties is not supported", path=path)
    names = [name for name, _ in element.properties]
    if len(set(names)) != len(names):
        raise InputError(f"duplicate vertex properties: {' '.join(names)}", path=path)
    n = element.count
    dtype = np.dtype([(name, byte_order + code) for name, code in element.properties])
    if binary:
        held = max(len(data) - offset, 0) // dtype.itemsize
        if held < n:
            raise InputError(f"expected {n} vertices, file holds {held}", path=path)
        array = np.frombuffer(data, dtype=dtype, count=n, offset=offset)
    elif n == 0:
        array = np.zeros(0, dtype=dtype)
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
    return _struct_to_fields(array)


def read_ply(
    path, *, intensity_channel: str | None = "auto", time_field: str | None = "auto"
) -> PointCloud:
    """Read the vertices of a PLY file (binary little/big endian or ascii) as a :class:`PointCloud`.

    Intensity and time fields follow :func:`read_pointcloud`'s rules.
    """
    return pointcloud_from_fields(
        read_ply_fields(path),
        intensity_channel=intensity_channel,
        time_field=time_field,
        source=Path(path),
    )


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
    table = np.empty(n, dtype=[(name, "<f4") for name in columns])
    for name, values in columns.items():
        table[name] = values
    header = "".join(
        [
            "ply\n",
            "format binary_little_endian 1.0\n" if encoding == "binary" else "format ascii 1.0\n",
            f"element vertex {n}\n",
            *[f"property float {name}\n" for name in columns],
            "end_header\n",
        ]
    ).encode("ascii")
    body = table.tobytes() if encoding == "binary" else _ascii_rows(table)
    write_bytes_atomic(path, [header, body])


# ----------------------------------------------------------------------------------------------
# KITTI .bin and NumPy files


def read_kitti_bin_fields(path) -> dict[str, np.ndarray]:
    """Read a KITTI Velodyne scan: float32 records ``x, y, z, reflectance``.

    Returns
    -------
    dict
        ``x``, ``y``, ``z`` (metres), ``intensity`` (the reflectance, 0..1), float32 (N,).
    """
    path = Path(path)
    data = _read_bytes(path)
    if len(data) % 16:
        raise InputError(
            f"size {len(data)} bytes is not a multiple of 16 (float32 x, y, z, reflectance)",
            path=path,
        )
    records = np.frombuffer(data, dtype="<f4").reshape(-1, 4)
    return {
        name: records[:, k].astype(np.float32)
        for k, name in enumerate(("x", "y", "z", "intensity"))
    }


def write_kitti_bin(path, points: np.ndarray, intensity: np.ndarray) -> None:
    """Write a KITTI Velodyne ``.bin`` (float32 ``x, y, z, reflectance`` records), atomically.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Metres, LiDAR frame.
    intensity : ndarray of shape (N,)
        Reflectance (KITTI's is in 0..1).
    """
    points = np.asarray(points)
    intensity = np.asarray(intensity)
    if points.ndim != 2 or points.shape[1] != 3 or intensity.shape != (points.shape[0],):
        raise ValueError(
            f"expected points (N, 3) and intensity (N,), got {points.shape}, {intensity.shape}"
        )
    records = np.empty((points.shape[0], 4), dtype="<f4")
    records[:, :3] = points
    records[:, 3] = intensity
    write_bytes_atomic(path, [records.tobytes()])


def _fields_from_matrix(array: np.ndarray, path: Path) -> dict[str, np.ndarray]:
    if array.ndim != 2 or array.shape[1] not in (3, 4) or array.dtype.kind not in "iuf":
        raise InputError(
            f"expected a structured array or a numeric (N, 3) / (N, 4) array, got {array.dtype} "
            f"with shape {array.shape}",
            path=path,
        )
    names = ("x", "y", "z", "intensity")[: array.shape[1]]
    return {name: np.ascontiguousarray(array[:, k]) for k, name in enumerate(names)}


def _read_npy_fields(path: Path) -> dict[str, np.ndarray]:
    _read_bytes(path)  # missing / empty checks
    try:
        array = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise InputError(f"not a readable .npy file: {exc}", path=path) from None
    if array.dtype.names:
        return _struct_to_fields(array.reshape(-1))
    return _fields_from_matrix(array, path)


def _read_npz_fields(path: Path) -> dict[str, np.ndarray]:
    _read_bytes(path)
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
