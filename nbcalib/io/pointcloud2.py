"""``sensor_msgs/PointCloud2`` <-> named NumPy arrays, without ROS.

A PointCloud2 message is ``height x width`` points of ``point_step`` bytes each, rows ``row_step``
bytes apart, in the byte order ``is_bigendian``; every ``PointField`` (name, offset, datatype,
count) says where one field sits inside a point. Reading builds one NumPy structured dtype from
the fields (with the offsets and ``point_step`` as item size), so any datatype, ``count`` and
padding is decoded by NumPy in one pass, never point by point.

The functions take any object with the message's attributes (a rosbags message or a stand-in), so
they work for ROS 1 and ROS 2 alike. Building a message is left to :mod:`nbcalib.io.bag_writer`,
which holds the type store: :func:`pack_pointcloud2` returns the parts.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._fields import buffer_array, field_arrays, fill_table, native_columns
from nbcalib.io.pointcloud import PointCloud, pointcloud_from_fields

#: PointField datatype constants (sensor_msgs/PointField) and their NumPy types.
POINTFIELD_DTYPES = {
    1: np.dtype(np.int8),  # INT8
    2: np.dtype(np.uint8),  # UINT8
    3: np.dtype(np.int16),  # INT16
    4: np.dtype(np.uint16),  # UINT16
    5: np.dtype(np.int32),  # INT32
    6: np.dtype(np.uint32),  # UINT32
    7: np.dtype(np.float32),  # FLOAT32
    8: np.dtype(np.float64),  # FLOAT64
}
_DATATYPE_OF = {dtype: code for code, dtype in POINTFIELD_DTYPES.items()}


@dataclass(frozen=True)
class PointFieldSpec:
    """One ``sensor_msgs/PointField``: name, byte offset in a point, datatype code, count."""

    name: str
    offset: int
    datatype: int
    count: int = 1


def pointcloud2_dtype(fields, point_step: int, *, is_bigendian: bool = False, source=None):
    """Structured dtype of one point, from the message's ``PointField`` list.

    Parameters
    ----------
    fields : sequence of objects with ``name``, ``offset``, ``datatype``, ``count``
        The message's ``fields``.
    point_step : int
        Bytes per point (the dtype's item size, so padding is skipped).
    is_bigendian : bool
        Byte order of the data.
    source : str, optional
        Named in error messages (bag and topic).

    Returns
    -------
    numpy.dtype
        Fields with empty names and repeated names (after the first) are left out.

    Raises
    ------
    InputError
        An unknown datatype, a field that does not fit in ``point_step``, or a ``point_step``
        out of range.
    """
    if not 0 <= point_step < 2**31:  # NumPy's limit for an item size
        raise InputError(f"PointCloud2 point_step {point_step} is out of range", path=source)
    order = ">" if is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in fields:
        name = str(f.name)
        if not name or name in names:
            continue
        if int(f.datatype) not in POINTFIELD_DTYPES:
            raise InputError(
                f"PointCloud2 field '{name}' has unknown datatype {int(f.datatype)}", path=source
            )
        base = POINTFIELD_DTYPES[int(f.datatype)].newbyteorder(order)
        count = max(int(f.count), 1)  # count 0 occurs in the wild and means 1
        if int(f.offset) + base.itemsize * count > point_step:
            raise InputError(
                f"PointCloud2 field '{name}' (offset {int(f.offset)}, {count} x {base}) does not "
                f"fit in point_step {point_step}",
                path=source,
            )
        names.append(name)
        formats.append((base, (count,)) if count > 1 else base)
        offsets.append(int(f.offset))
    return np.dtype(
        {"names": names, "formats": formats, "offsets": offsets, "itemsize": int(point_step)}
    )


def pointcloud2_to_fields(msg, *, source=None) -> dict[str, np.ndarray]:
    """Decode a PointCloud2 message into one array per field.

    Parameters
    ----------
    msg : sensor_msgs/PointCloud2 (any object with its attributes)
        ``height``, ``width``, ``fields``, ``is_bigendian``, ``point_step``, ``row_step``, ``data``.
    source : str, optional
        Named in error messages.

    Returns
    -------
    dict of str to ndarray
        Arrays of shape (height * width,) or (height * width, count), native byte order, in the
        message's field order; rows of an organised cloud are concatenated.

    Raises
    ------
    InputError
        Data shorter than the header promises, or a bad field.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    dtype = pointcloud2_dtype(
        msg.fields, point_step, is_bigendian=bool(msg.is_bigendian), source=source
    )
    data = buffer_array(msg.data).reshape(-1).view(np.uint8)
    n = height * width
    if n == 0:
        points = np.zeros(0, dtype=dtype)
    elif point_step == 0:
        raise InputError(f"PointCloud2 of {height} x {width} points has point_step 0", path=source)
    else:
        row_bytes = width * point_step
        row_step = max(row_step, row_bytes) if height == 1 else row_step
        if row_step < row_bytes:
            raise InputError(
                f"PointCloud2 row_step {row_step} is smaller than width {width} x point_step "
                f"{point_step}",
                path=source,
            )
        needed = (height - 1) * row_step + row_bytes
        if data.size < needed:
            raise InputError(
                f"PointCloud2 data holds {data.size} bytes, expected {needed} for {height} x "
                f"{width} points",
                path=source,
            )
        if row_step == row_bytes or height == 1:
            points = np.frombuffer(data[:needed], dtype=dtype, count=n)
        else:  # rows padded to row_step: drop the padding, then view as points
            rows = np.lib.stride_tricks.as_strided(
                data, shape=(height, row_bytes), strides=(row_step, 1), writeable=False
            )
            points = np.ascontiguousarray(rows).reshape(-1).view(dtype)
    return native_columns(points, dtype.names)


def pointcloud2_to_pointcloud(
    msg,
    *,
    intensity_channel: str | None = "auto",
    time_field: str | None = "auto",
    source=None,
) -> PointCloud:
    """Decode a PointCloud2 message into a :class:`~nbcalib.io.pointcloud.PointCloud`.

    Intensity channel, time field and finite-point rules are those of
    :func:`nbcalib.io.pointcloud.pointcloud_from_fields` (the reference's): ``reflectivity`` over
    ``intensity``; time fields ``t``, ``time``, ``time_stamp``, ``timestamp`` with integer =
    nanoseconds, float = seconds, then the ``TimeKeeper`` normalisation; rows with non-finite
    x, y, z dropped.
    """
    return pointcloud_from_fields(
        pointcloud2_to_fields(msg, source=source),
        intensity_channel=intensity_channel,
        time_field=time_field,
        source=source,
    )


def pack_pointcloud2(
    fields: Mapping[str, np.ndarray],
) -> tuple[list[PointFieldSpec], int, np.ndarray]:
    """Pack named arrays into PointCloud2 parts (little endian, no padding, ``height`` 1).

    Parameters
    ----------
    fields : mapping of str to ndarray of shape (N,) or (N, count)
        Fields in message order, each with its own dtype (int8..uint32 and int8..float64 as
        PointField allows; e.g. x, y, z float32, intensity float32, t float32 or uint32 ns).

    Returns
    -------
    specs : list of PointFieldSpec
        The message's ``fields``.
    point_step : int
        Bytes per point; ``row_step = N * point_step``.
    data : ndarray of shape (N * point_step,), uint8
        The message's ``data``.

    Raises
    ------
    ValueError
        A dtype PointField cannot express (int64, uint64, bool, ...), or unequal lengths.
    """
    arrays, n = field_arrays(fields, action="pack", max_ndim=2)
    specs, layout, offset = [], [], 0
    for name, values in arrays.items():
        native = values.dtype.newbyteorder("=")
        if native not in _DATATYPE_OF:
            raise ValueError(
                f"field {name!r}: PointCloud2 cannot store {values.dtype}; use int8..uint32, "
                "float32 or float64"
            )
        count = values.shape[1] if values.ndim == 2 else 1
        specs.append(PointFieldSpec(name, offset, _DATATYPE_OF[native], count))
        layout.append((name, native.newbyteorder("<"), (count,) if values.ndim == 2 else ()))
        offset += native.itemsize * count
    table = fill_table(arrays, layout, n)
    return specs, table.dtype.itemsize, table.view(np.uint8).reshape(-1)
