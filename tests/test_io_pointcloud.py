"""Point cloud files: LZF kernels vs reference, PCD / PLY / KITTI / NumPy round trips, time and
intensity rules, corrupt inputs, and the real KITTI and PJLab clouds."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.pointcloud import (
    lzf_compress,
    lzf_decompress,
    normalize_point_times,
    pointcloud_from_fields,
    read_pcd_fields,
    read_ply,
    read_pointcloud,
    write_kitti_bin,
    write_pcd,
    write_ply,
)
from nbcalib.kernels.lzf import _lzf_compress, _lzf_decompress
from nbcalib.reference import lzf as lzf_ref

JIT_OFF = os.environ.get("NUMBA_DISABLE_JIT") == "1"  # coverage runs execute kernels in Python

# ------------------------------------------------------------------------------------------ LZF


def _lzf_inputs(rng):
    """Small, nasty inputs: empty, tiny, incompressible, low entropy, long runs, far matches."""
    block = rng.integers(0, 256, 9000).astype(np.uint8)
    yield np.zeros(0, np.uint8)
    yield np.array([7], np.uint8)
    yield np.array([1, 2], np.uint8)
    yield np.array([5, 5, 5], np.uint8)
    yield np.full(1000, 42, np.uint8)  # runs longer than the longest back reference (264)
    yield rng.integers(0, 256, 5000).astype(np.uint8)  # incompressible
    yield rng.integers(0, 3, 5000).astype(np.uint8)
    yield np.repeat(rng.integers(0, 256, 700).astype(np.uint8), 5)
    for period in (8191, 8192, 8193):  # matches exactly at and beyond the farthest offset
        yield np.concatenate([block[:period], block[:period]])
    yield np.arange(4000, dtype="<f4").view(np.uint8)  # float columns, like a PCD field block


def test_lzf_kernels_equal_reference(rng):
    for data in _lzf_inputs(rng):
        stream = lzf_ref.lzf_compress(data.tobytes())
        dst = np.empty(data.size + data.size // 32 + 2, np.uint8)
        n = _lzf_compress(data, dst)
        assert dst[:n].tobytes() == stream  # the kernel makes the reference's exact stream
        out = np.empty(data.size, np.uint8)
        assert _lzf_decompress(np.frombuffer(stream, np.uint8), out) == data.size
        assert np.array_equal(out, data)
        assert lzf_ref.lzf_decompress(stream, data.size) == data.tobytes()


def test_lzf_compresses_redundant_data(rng):
    data = np.tile(rng.integers(0, 256, 100).astype(np.uint8), 80)  # 8000 bytes, period 100
    assert len(lzf_compress(data)) < 200  # 101 literal bytes, then 264-byte back references
    noise = rng.integers(0, 256, 3200).astype(np.uint8)
    assert len(lzf_compress(noise)) <= noise.size + noise.size // 32 + 1


def test_lzf_decoder_matches_reference_on_a_foreign_stream():
    # hand-written stream: literal "abc", then back reference of 5 bytes at offset 3 (overlapping)
    stream = bytes([2, ord("a"), ord("b"), ord("c"), (3 << 5) | 0, 2])
    assert lzf_ref.lzf_decompress(stream, 8) == b"abcabcab"
    assert lzf_decompress(stream, 8).tobytes() == b"abcabcab"
    # long back reference: length code 7 + extra byte 10 -> 19 bytes of a run of one byte
    stream = bytes([0, ord("z"), 7 << 5, 10, 0])
    assert lzf_decompress(stream, 20).tobytes() == b"z" * 20 == lzf_ref.lzf_decompress(stream, 20)


@pytest.mark.parametrize(
    ("stream", "size", "problem"),
    [
        (bytes([5, 1, 2]), 6, "ends inside"),  # literal run cut short
        (bytes([0, 1, 1 << 5]), 4, "ends inside"),  # back reference without its offset byte
        (bytes([0, 1, 1 << 5, 5]), 4, "before the start"),  # offset beyond the output
        (bytes([3, 1, 2, 3, 4]), 2, "more than"),  # decodes to more than expected
        (bytes([1, 1, 2]), 5, "expected 5"),  # decodes to less than expected
    ],
)
def test_lzf_corrupt_streams_raise(stream, size, problem):
    with pytest.raises(ValueError, match=problem):
        lzf_decompress(stream, size)
    with pytest.raises(ValueError):
        lzf_ref.lzf_decompress(stream, size)


# ------------------------------------------------------------------------------------------ PCD


def _mixed_fields(rng, n=257):
    return {
        "x": rng.normal(size=n).astype(np.float32),
        "y": rng.normal(size=n).astype(np.float32),
        "z": rng.normal(size=n).astype(np.float32),
        "intensity": rng.uniform(0, 255, n).astype(np.float32),
        "ring": rng.integers(0, 128, n).astype(np.uint16),
        "t": np.sort(rng.uniform(0, 0.1, n)),  # float64 seconds
        "label": rng.integers(-128, 128, n).astype(np.int8),
        "normal": rng.normal(size=(n, 3)).astype(np.float32),  # COUNT 3
        "id": rng.integers(0, 2**63, n, dtype=np.int64).astype(np.uint64),
    }


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip_keeps_every_field_exactly(tmp_path, rng, encoding):
    fields = _mixed_fields(rng)
    path = tmp_path / "cloud.pcd"
    write_pcd(path, fields, encoding=encoding)
    read = read_pcd_fields(path)
    assert list(read) == list(fields)
    for name, values in fields.items():
        assert read[name].dtype == values.dtype, name
        assert np.array_equal(read[name], values), name
    cloud = read_pointcloud(path)
    assert cloud.points.dtype == np.float64 and cloud.points.shape == (257, 3)
    assert np.array_equal(cloud.intensity, fields["intensity"].astype(np.float64))
    assert np.array_equal(cloud.times, fields["t"] - fields["t"][0] * (fields["t"][0] >= 1))
    assert list(path.parent.iterdir()) == [path]  # no temporary file left behind


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_pcd_non_finite_rows_are_dropped_from_every_field(tmp_path, rng, encoding):
    fields = _mixed_fields(rng, n=50)
    fields["x"][[3, 10]] = np.nan
    fields["z"][20] = np.inf
    write_pcd(tmp_path / "c.pcd", fields, encoding=encoding)
    cloud = read_pointcloud(tmp_path / "c.pcd")
    keep = np.ones(50, bool)
    keep[[3, 10, 20]] = False
    assert len(cloud) == 47
    assert np.array_equal(cloud.fields["ring"], fields["ring"][keep])
    assert np.array_equal(cloud.points[:, 1], fields["y"][keep].astype(np.float64))


def test_pcd_empty_cloud_round_trip(tmp_path):
    for encoding in ("ascii", "binary", "binary_compressed"):
        fields = {c: np.zeros(0, np.float32) for c in "xyz"}
        write_pcd(tmp_path / "e.pcd", fields, encoding=encoding)
        cloud = read_pointcloud(tmp_path / "e.pcd")
        assert cloud.points.shape == (0, 3)


def _compressed_pcd_by_hand(fields: dict) -> bytes:
    """A binary_compressed PCD assembled from the format description, with the pure-Python LZF."""
    n = len(fields["x"])
    blocks = b"".join(
        np.ascontiguousarray(v).astype(v.dtype.newbyteorder("<")).tobytes() for v in fields.values()
    )
    packed = lzf_ref.lzf_compress(blocks)
    sizes = " ".join(str(v.dtype.itemsize) for v in fields.values())
    types = " ".join({"f": "F", "u": "U", "i": "I"}[v.dtype.kind] for v in fields.values())
    header = (
        f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {' '.join(fields)}\n"
        f"SIZE {sizes}\nTYPE {types}\nCOUNT {' '.join('1' for _ in fields)}\nWIDTH {n}\n"
        f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary_compressed\n"
    )
    return header.encode() + struct.pack("<II", len(packed), len(blocks)) + packed


def test_pcd_binary_compressed_layout_is_column_blocks(tmp_path, rng):
    fields = {
        "x": rng.normal(size=100).astype(np.float32),
        "y": rng.normal(size=100).astype(np.float32),
        "z": rng.normal(size=100).astype(np.float32),
        "ring": rng.integers(0, 64, 100).astype(np.uint16),
        "timestamp": 1.6e9 + np.linspace(0, 0.1, 100),
    }
    (tmp_path / "hand.pcd").write_bytes(_compressed_pcd_by_hand(fields))
    read = read_pcd_fields(tmp_path / "hand.pcd")
    for name in fields:
        assert np.array_equal(read[name], fields[name]), name
    # and our writer produces the same bytes, since both compressors make the same stream
    write_pcd(tmp_path / "ours.pcd", fields, encoding="binary_compressed")
    assert (tmp_path / "ours.pcd").read_bytes() == (tmp_path / "hand.pcd").read_bytes()


def test_pcd_ascii_as_pcl_writes_it(tmp_path):
    text = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
        "WIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\nDATA ascii\n"
        "1 2 3 4278190080\nnan nan nan 0\n0.5 -1.25 1e-3 16711935\n7 8 9 1\n"
    )
    (tmp_path / "org.pcd").write_text(text)
    cloud = read_pointcloud(tmp_path / "org.pcd")
    assert len(cloud) == 3  # the nan row of the organised cloud is dropped
    assert np.array_equal(cloud.fields["rgb"], np.array([4278190080, 16711935, 1], np.uint32))
    assert np.allclose(cloud.points[1], [0.5, -1.25, 1e-3])
    assert cloud.intensity is None and cloud.times is None


def test_pcd_pcl_padding_fields_and_old_header(tmp_path, rng):
    # PCD v0.6-style header without VIEWPOINT, with PCL's "_" padding field (COUNT 4)
    n = 10
    table = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("pad", "u1", (4,))])
    table["x"] = rng.normal(size=n)
    header = (
        "VERSION .6\nFIELDS x y z _\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 4\n"
        f"WIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA binary\n"
    )
    (tmp_path / "p.pcd").write_bytes(header.encode() + table.tobytes())
    fields = read_pcd_fields(tmp_path / "p.pcd")
    assert list(fields) == ["x", "y", "z"]
    assert np.array_equal(fields["x"], table["x"])


def _broken_pcd(tmp_path, rng, how: str):
    fields = _mixed_fields(rng, n=100)
    encoding = "binary_compressed" if how.startswith("compressed") else "binary"
    write_pcd(tmp_path / "ok.pcd", fields, encoding=encoding)
    data = (tmp_path / "ok.pcd").read_bytes()
    body = data.index(b"DATA") + data[data.index(b"DATA") :].index(b"\n") + 1
    broken = {
        "truncated": data[: body + 1234],
        "compressed_truncated": data[:-50],
        "compressed_corrupt": data[: body + 8] + bytes([255, 255, 255]) + data[body + 11 :],
        "no_data_line": data[: data.index(b"DATA")],
        "bad_size_line": data.replace(b"SIZE 4 4 4 4 2 8 1 4 8", b"SIZE 4 4 4"),
        "bad_type": data.replace(b"TYPE F F F F U F I F U", b"TYPE F F F F U F I F Q"),
        "bad_points": data.replace(b"POINTS 100", b"POINTS 99"),
        "not_text": b"\x00\xff\xfe" * 100,
    }[how]
    path = tmp_path / f"{how}.pcd"
    path.write_bytes(broken)
    return path


@pytest.mark.parametrize(
    ("how", "problem"),
    [
        ("truncated", "expected 100 points, file holds 26"),
        ("compressed_truncated", "truncated"),
        ("compressed_corrupt", "corrupt binary_compressed"),
        ("no_data_line", "no DATA line"),
        ("bad_size_line", "9 FIELDS but 3 SIZE"),
        ("bad_type", "unsupported TYPE Q"),
        ("bad_points", "does not match POINTS 99"),
        ("not_text", "not ASCII"),
    ],
)
def test_corrupt_pcd_raises_input_error_naming_the_file(tmp_path, rng, how, problem):
    path = _broken_pcd(tmp_path, rng, how)
    with pytest.raises(InputError, match=problem) as info:
        read_pointcloud(path)
    assert str(path) in str(info.value)


def test_truncated_ascii_pcd(tmp_path, rng):
    write_pcd(tmp_path / "a.pcd", _mixed_fields(rng, n=30), encoding="ascii")
    lines = (tmp_path / "a.pcd").read_text().splitlines(keepends=True)
    (tmp_path / "cut.pcd").write_text("".join(lines[:-5]))
    with pytest.raises(InputError, match="expected 30 points, file holds 25"):
        read_pointcloud(tmp_path / "cut.pcd")
    (tmp_path / "short.pcd").write_text("".join(lines[:-1]) + "1 2 3\n")
    with pytest.raises(InputError, match="bad ascii data"):
        read_pointcloud(tmp_path / "short.pcd")


@pytest.mark.parametrize("name", ["empty.pcd", "empty.ply", "empty.bin", "empty.npy"])
def test_empty_file(tmp_path, name):
    (tmp_path / name).write_bytes(b"")
    with pytest.raises(InputError, match="empty file") as info:
        read_pointcloud(tmp_path / name)
    assert name in str(info.value)


def test_missing_file_and_unknown_suffix(tmp_path):
    with pytest.raises(InputError, match="file not found") as info:
        read_pointcloud(tmp_path / "nope.pcd")
    assert "nope.pcd" in str(info.value)
    (tmp_path / "cloud.xyz").write_text("1 2 3\n")
    with pytest.raises(InputError, match=r"unknown point cloud suffix '\.xyz'") as info:
        read_pointcloud(tmp_path / "cloud.xyz")
    assert "cloud.xyz" in str(info.value)


def test_write_is_atomic_when_interrupted(tmp_path, rng, monkeypatch):
    import nbcalib.io.pointcloud as pc

    path = tmp_path / "keep.pcd"
    write_pcd(path, _mixed_fields(rng, n=10))
    before = path.read_bytes()

    def failing_compress(data):
        raise KeyboardInterrupt  # a crash between header and data

    monkeypatch.setattr(pc, "lzf_compress", failing_compress)
    with pytest.raises(KeyboardInterrupt):
        write_pcd(path, _mixed_fields(rng, n=20), encoding="binary_compressed")
    assert path.read_bytes() == before
    assert list(tmp_path.iterdir()) == [path]


def test_write_pcd_rejects_programming_errors(tmp_path):
    with pytest.raises(ValueError, match="one length"):
        write_pcd(tmp_path / "a.pcd", {"x": np.zeros(3), "y": np.zeros(4)})
    with pytest.raises(ValueError, match="cannot store"):
        write_pcd(tmp_path / "a.pcd", {"x": np.zeros(3, bool)})
    with pytest.raises(ValueError, match="encoding"):
        write_pcd(tmp_path / "a.pcd", {"x": np.zeros(3)}, encoding="zip")
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------- intensity channel and times


def _xyz(n=5):
    return {c: np.arange(n, dtype=np.float32) for c in "xyz"}


def test_intensity_channel_auto_prefers_reflectivity():
    fields = {
        **_xyz(),
        "intensity": np.full(5, 1.0, np.float32),
        "reflectivity": np.full(5, 9, np.uint8),
    }
    assert np.array_equal(pointcloud_from_fields(fields).intensity, np.full(5, 9.0))
    named = pointcloud_from_fields(fields, intensity_channel="intensity")
    assert np.array_equal(named.intensity, np.ones(5))
    assert pointcloud_from_fields(fields, intensity_channel=None).intensity is None
    assert pointcloud_from_fields(_xyz()).intensity is None


def test_missing_intensity_channel_lists_the_fields():
    fields = {**_xyz(), "intensity": np.ones(5, np.float32)}
    with pytest.raises(
        InputError, match="'signal' not found; available fields: x, y, z, intensity"
    ) as info:
        pointcloud_from_fields(fields, intensity_channel="signal", source="scan.pcd")
    assert str(info.value).startswith("scan.pcd: ")


def test_time_units_and_timekeeper_rules():
    # uint32 nanoseconds (Ouster "t")
    assert np.allclose(normalize_point_times(np.array([0, 50_000_000], np.uint32)), [0.0, 0.05])
    # float seconds, already relative: unchanged
    assert np.array_equal(
        normalize_point_times(np.array([0.0, 0.02], np.float32)), np.array([0.0, np.float32(0.02)])
    )
    # negative: shifted so the minimum is 0
    assert np.allclose(normalize_point_times(np.array([-0.05, 0.0, 0.05])), [0.0, 0.05, 0.1])
    # absolute seconds (Hesai "timestamp"): relative to the first point
    t = 1605333546.7827358 + np.array([0.0, 0.05, 0.1])
    assert np.allclose(normalize_point_times(t), [0.0, 0.05, 0.1], atol=1e-7)
    # float nanoseconds above 1e16 (Livox absolute stamps as double)
    t = 1.6e18 + np.array([0.0, 5e7, 1e8])
    assert np.allclose(normalize_point_times(t), [0.0, 0.05, 0.1], atol=1e-6)
    # integer absolute nanoseconds keep full precision
    t = np.array([1_600_000_000_123_456_789, 1_600_000_000_123_456_790], np.uint64)
    assert np.array_equal(normalize_point_times(t), [0.0, 1e-9])
    # relative to the first point, as the reference (not to the minimum)
    assert np.allclose(normalize_point_times(np.array([10.0, 9.5, 10.5])), [0.0, -0.5, 0.5])


def test_time_field_selection():
    fields = {
        **_xyz(3),
        "timestamp": np.array([5.0, 5.1, 5.2]),
        "t": np.array([0, 1000, 2000], np.uint32),
    }
    assert np.allclose(pointcloud_from_fields(fields).times, [0, 1e-6, 2e-6])  # "t" comes first
    assert np.allclose(pointcloud_from_fields(fields, time_field="timestamp").times, [0, 0.1, 0.2])
    assert pointcloud_from_fields(fields, time_field=None).times is None
    with pytest.raises(InputError, match="time field 'stamp' not found"):
        pointcloud_from_fields(fields, time_field="stamp")


def test_missing_xyz_is_an_input_error():
    with pytest.raises(InputError, match="no z field; fields present: x, y"):
        pointcloud_from_fields({"x": np.zeros(2), "y": np.zeros(2)}, source="a.npz")


# ------------------------------------------------------------------------------------------ PLY


def test_ply_binary_header_is_the_references(tmp_path, rng):
    points = rng.normal(size=(20, 3))
    intensity = rng.random(20)
    write_ply(tmp_path / "a.ply", points, intensity)
    data = (tmp_path / "a.ply").read_bytes()
    header = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 20\nproperty float x\n"
        b"property float y\nproperty float z\nproperty float intensity\nend_header\n"
    )
    assert data.startswith(header) and len(data) == len(header) + 20 * 16
    body = np.frombuffer(data[len(header) :], "<f4").reshape(20, 4)
    assert np.array_equal(body[:, :3], points.astype(np.float32))


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_ply_round_trip(tmp_path, rng, encoding):
    points = rng.normal(size=(300, 3)) * 20
    intensity = rng.random(300)
    write_ply(tmp_path / "a.ply", points, intensity, encoding=encoding)
    cloud = read_ply(tmp_path / "a.ply")
    assert np.array_equal(cloud.points, points.astype(np.float32).astype(np.float64))
    assert np.array_equal(cloud.intensity, intensity.astype(np.float32).astype(np.float64))
    no_intensity = tmp_path / "b.ply"
    write_ply(no_intensity, points, encoding=encoding)
    assert read_pointcloud(no_intensity).intensity is None


def test_ply_big_endian_with_faces(tmp_path, rng):
    vertices = np.zeros(4, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("reflectivity", "u1")])
    vertices["x"] = rng.normal(size=4)
    vertices["reflectivity"] = [1, 2, 3, 4]
    header = (
        b"ply\nformat binary_big_endian 1.0\ncomment made by hand\nelement vertex 4\n"
        b"property double x\nproperty double y\nproperty double z\nproperty uchar reflectivity\n"
        b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face = struct.pack(">Biii", 3, 0, 1, 2)
    (tmp_path / "be.ply").write_bytes(header + vertices.tobytes() + face)
    cloud = read_pointcloud(tmp_path / "be.ply")
    assert np.array_equal(cloud.points[:, 0], vertices["x"])
    assert np.array_equal(cloud.intensity, [1.0, 2.0, 3.0, 4.0])


def test_ply_ascii_with_faces(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    )
    (tmp_path / "t.ply").write_text(text)
    assert np.array_equal(read_ply(tmp_path / "t.ply").points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (
            b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
            b"property float y\nproperty float z\nend_header\n" + bytes(12 * 4),
            "expected 10 vertices, file holds 4",
        ),
        (b"solid cube\nfacet normal 0 0 1\n", "not a PLY file"),
        (
            b"ply\nformat binary_little_endian 1.0\nelement face 1\nproperty int v\nend_header\n",
            "no 'vertex' element",
        ),
        (
            b"ply\nformat binary_middle_endian 1.0\nelement vertex 0\nend_header\n",
            "unknown PLY format",
        ),
    ],
)
def test_corrupt_ply(tmp_path, content, problem):
    (tmp_path / "bad.ply").write_bytes(content)
    with pytest.raises(InputError, match=problem) as info:
        read_pointcloud(tmp_path / "bad.ply")
    assert "bad.ply" in str(info.value)


# ----------------------------------------------------------------------------- KITTI and NumPy


def test_kitti_bin_round_trip_and_bad_size(tmp_path, rng):
    points = rng.normal(size=(100, 3)) * 30
    reflectance = rng.random(100)
    write_kitti_bin(tmp_path / "000000.bin", points, reflectance)
    cloud = read_pointcloud(tmp_path / "000000.bin")
    assert np.array_equal(cloud.points, points.astype(np.float32).astype(np.float64))
    assert np.array_equal(cloud.intensity, reflectance.astype(np.float32).astype(np.float64))
    (tmp_path / "bad.bin").write_bytes(bytes(100))
    with pytest.raises(InputError, match="not a multiple of 16") as info:
        read_pointcloud(tmp_path / "bad.bin")
    assert "bad.bin" in str(info.value)


def test_numpy_files(tmp_path, rng):
    xyzi = rng.normal(size=(50, 4))
    np.save(tmp_path / "a.npy", xyzi)
    cloud = read_pointcloud(tmp_path / "a.npy")
    assert np.array_equal(cloud.points, xyzi[:, :3]) and np.array_equal(cloud.intensity, xyzi[:, 3])
    np.save(tmp_path / "b.npy", xyzi[:, :3].astype(np.float32))
    assert read_pointcloud(tmp_path / "b.npy").intensity is None
    table = np.zeros(
        50, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("t", "u4"), ("reflectivity", "u2")]
    )
    table["t"] = np.arange(50) * 1000
    np.save(tmp_path / "c.npy", table)
    cloud = read_pointcloud(tmp_path / "c.npy")
    assert (
        np.allclose(cloud.times, np.arange(50) * 1e-6)
        and cloud.fields["reflectivity"].dtype == np.uint16
    )
    np.savez(
        tmp_path / "d.npz", points=xyzi[:, :3], intensity=xyzi[:, 3], t=np.linspace(0, 0.1, 50)
    )
    cloud = read_pointcloud(tmp_path / "d.npz")
    assert np.array_equal(cloud.intensity, xyzi[:, 3]) and np.allclose(cloud.times[-1], 0.1)
    np.savez(tmp_path / "e.npz", x=xyzi[:, 0], y=xyzi[:, 1], z=xyzi[:, 2])
    assert np.array_equal(read_pointcloud(tmp_path / "e.npz").points, xyzi[:, :3])
    np.save(tmp_path / "f.npy", np.zeros((5, 7)))
    with pytest.raises(InputError, match=r"\(N, 3\) / \(N, 4\)"):
        read_pointcloud(tmp_path / "f.npy")
    np.savez(tmp_path / "g.npz", x=np.zeros(3), y=np.zeros(3), z=np.zeros(4))
    with pytest.raises(InputError, match="different lengths"):
        read_pointcloud(tmp_path / "g.npz")
    (tmp_path / "h.npy").write_bytes(b"not numpy at all")
    with pytest.raises(InputError, match=r"not a readable \.npy"):
        read_pointcloud(tmp_path / "h.npy")


# ------------------------------------------------------------------------------------ real data


def test_real_kitti_bin(real_data):
    path = real_data / "kitti_raw_2011_09_26" / "0000000000" / "velodyne.bin"
    cloud = read_pointcloud(path)
    raw = np.fromfile(path, np.float32).reshape(-1, 4)
    assert len(cloud) == raw.shape[0] == 114278
    assert np.array_equal(cloud.points, raw[:, :3].astype(np.float64))
    assert 0.0 <= cloud.intensity.min() and cloud.intensity.max() <= 1.0  # reflectance 0..0.99
    assert cloud.times is None


def test_real_pjlab_binary_compressed(real_data):
    path = real_data / "pjlab" / "auto_calib" / "lidar.pcd"
    cloud = read_pointcloud(path)
    names = ["x", "y", "z", "intensity", "ring", "timestamp"]
    assert len(cloud) <= 85546 and list(cloud.fields) == names
    fields = read_pcd_fields(path)
    assert len(fields["x"]) == 85546  # POINTS in the header
    assert cloud.intensity.min() >= 0 and 200 < cloud.intensity.max() <= 255  # 0..254
    assert set(np.unique(cloud.fields["ring"])) <= set(range(64))
    assert cloud.times[0] == 0.0 and 0.09 < cloud.times.max() < 0.11  # one 10 Hz sweep
    assert np.abs(cloud.points).max() < 300


@pytest.mark.skipif(JIT_OFF, reason="compressing 2 MB in pure Python takes ~25 s")
def test_real_pjlab_rewritten_in_every_encoding(real_data, tmp_path):
    fields = read_pcd_fields(real_data / "pjlab" / "auto_calib" / "lidar.pcd")
    for encoding in ("ascii", "binary", "binary_compressed"):
        write_pcd(tmp_path / "copy.pcd", fields, encoding=encoding)
        again = read_pcd_fields(tmp_path / "copy.pcd")
        assert all(np.array_equal(again[k], fields[k], equal_nan=True) for k in fields), encoding


def test_real_pjlab_lzf_kernel_equals_reference(real_data):
    data = (real_data / "pjlab" / "auto_calib" / "lidar.pcd").read_bytes()
    body = data[data.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n") :]
    compressed_size, size = struct.unpack("<II", body[:8])
    stream = body[8 : 8 + compressed_size]
    assert size == 85546 * 26  # x y z intensity float32, ring uint16, timestamp float64
    assert lzf_decompress(stream, size).tobytes() == lzf_ref.lzf_decompress(stream, size)


def test_real_pjlab_ascii(real_data):
    cloud = read_pointcloud(real_data / "pjlab" / "manual_calib_0" / "lidar.pcd")
    assert len(read_pcd_fields(real_data / "pjlab" / "manual_calib_0" / "lidar.pcd")["x"]) == 78238
    assert list(cloud.fields) == ["x", "y", "z", "intensity"]
    assert cloud.intensity.min() >= 0 and 200 < cloud.intensity.max() <= 255
    assert cloud.times is None
