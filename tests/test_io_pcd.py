"""PCD files: LZF kernels vs reference, round trips in every encoding, PCL's layouts, corrupt
files, atomic writes, and the real PJLab clouds."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.pcd import lzf_compress, lzf_decompress, read_pcd_fields, write_pcd
from nbcalib.io.pointcloud import read_pointcloud
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


def test_write_is_atomic_when_interrupted(tmp_path, rng, monkeypatch):
    import nbcalib.io.pcd as pcd

    path = tmp_path / "keep.pcd"
    write_pcd(path, _mixed_fields(rng, n=10))
    before = path.read_bytes()

    def failing_compress(data):
        raise KeyboardInterrupt  # a crash between header and data

    monkeypatch.setattr(pcd, "lzf_compress", failing_compress)
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


# ------------------------------------------------------------------------------------ real data


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
