"""PointCloud2 decoding against a point-by-point reference: every datatype, count, padding and
byte order; packing round trips; bad messages."""

from __future__ import annotations

import struct
from types import SimpleNamespace

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.pointcloud2 import (
    POINTFIELD_DTYPES,
    PointFieldSpec,
    pack_pointcloud2,
    pointcloud2_to_fields,
    pointcloud2_to_pointcloud,
)

_STRUCT_CODES = {1: "b", 2: "B", 3: "h", 4: "H", 5: "i", 6: "I", 7: "f", 8: "d"}


def _unpack_point_by_point(msg) -> dict[str, list]:
    """Slow reference: struct.unpack every field of every point, honouring row_step."""
    order = ">" if msg.is_bigendian else "<"
    out = {f.name: [] for f in msg.fields}
    data = bytes(msg.data)
    for row in range(msg.height):
        for col in range(msg.width):
            base = row * msg.row_step + col * msg.point_step
            for f in msg.fields:
                code = order + _STRUCT_CODES[f.datatype] * f.count
                values = struct.unpack_from(code, data, base + f.offset)
                out[f.name].append(values if f.count > 1 else values[0])
    return out


def _message(fields, height, width, point_step, row_step, data, big=False):
    return SimpleNamespace(
        fields=[SimpleNamespace(name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
        height=height,
        width=width,
        point_step=point_step,
        row_step=row_step,
        is_bigendian=big,
        data=np.frombuffer(data, np.uint8),
    )


@pytest.mark.parametrize("big", [False, True])
def test_pointcloud2_every_datatype_count_and_padding(rng, big):
    # every datatype, a count-3 field, gaps between fields, point and row padding
    layout = [
        ("x", 0, 7, 1),
        ("y", 4, 7, 1),
        ("z", 8, 7, 1),
        ("i8", 12, 1, 1),
        ("u8", 13, 2, 1),
        ("i16", 14, 3, 1),
        ("u16", 16, 4, 1),
        ("i32", 20, 5, 1),
        ("u32", 24, 6, 1),
        ("f64", 32, 8, 1),
        ("normal", 40, 7, 3),
    ]
    height, width, point_step = 3, 7, 60
    row_step = width * point_step + 13
    data = rng.integers(0, 256, height * row_step).astype(np.uint8).tobytes()
    msg = _message(layout, height, width, point_step, row_step, data, big)
    fields = pointcloud2_to_fields(msg)
    expected = _unpack_point_by_point(msg)
    assert list(fields) == [name for name, *_ in layout]
    for name, _, datatype, count in layout:
        assert fields[name].dtype == POINTFIELD_DTYPES[datatype].newbyteorder("=")
        assert fields[name].shape == ((21, 3) if count == 3 else (21,))
        assert np.array_equal(fields[name], np.array(expected[name]), equal_nan=True), name


def test_pointcloud2_pack_round_trip_and_rules(rng):
    n = 500
    fields = {
        "x": rng.normal(size=n).astype(np.float32),
        "y": rng.normal(size=n).astype(np.float32),
        "z": rng.normal(size=n).astype(np.float32),
        "intensity": rng.random(n).astype(np.float32),
        "reflectivity": rng.integers(0, 65535, n).astype(np.uint16),
        "t": np.arange(n, dtype=np.uint32) * 200_000,  # ns (Ouster)
        "ring": rng.integers(0, 128, n).astype(np.uint8),
        "rgb": rng.integers(0, 255, (n, 3)).astype(np.uint8),
    }
    fields["x"][7] = np.nan
    specs, point_step, data = pack_pointcloud2(fields)
    assert point_step == 12 + 4 + 2 + 4 + 1 + 3
    assert specs[4] == PointFieldSpec("reflectivity", 16, 4, 1)
    msg = _message(
        [(s.name, s.offset, s.datatype, s.count) for s in specs],
        1,
        n,
        point_step,
        n * point_step,
        data.tobytes(),
    )
    decoded = pointcloud2_to_fields(msg)
    for name in fields:
        assert np.array_equal(decoded[name], fields[name], equal_nan=True), name
    cloud = pointcloud2_to_pointcloud(msg)
    assert len(cloud) == n - 1  # the NaN point is dropped
    assert np.array_equal(cloud.intensity, np.delete(fields["reflectivity"], 7).astype(float))
    assert np.allclose(cloud.times, np.delete(np.arange(n) * 2e-4, 7))
    with pytest.raises(ValueError, match="cannot store int64"):
        pack_pointcloud2({"x": np.zeros(3, np.int64)})


def test_pointcloud2_bad_messages_raise_input_error():
    msg = _message([("x", 0, 9, 1)], 1, 2, 4, 8, bytes(8))
    with pytest.raises(InputError, match="unknown datatype 9"):
        pointcloud2_to_fields(msg, source="a.bag /points")
    msg = _message([("x", 0, 7, 1), ("y", 4, 8, 1)], 1, 2, 8, 16, bytes(16))
    with pytest.raises(InputError, match="does not fit in point_step 8"):
        pointcloud2_to_fields(msg)
    msg = _message([("x", 0, 7, 1)], 2, 10, 4, 40, bytes(50))
    with pytest.raises(InputError, match="holds 50 bytes, expected 80") as info:
        pointcloud2_to_fields(msg, source="a.bag /points")
    assert str(info.value).startswith("a.bag /points: ")
    msg = _message([("x", 0, 7, 1), ("y", 4, 7, 1)], 1, 2, 8, 16, bytes(16))
    with pytest.raises(InputError, match="no z field"):
        pointcloud2_to_pointcloud(msg)
