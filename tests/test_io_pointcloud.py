"""Point clouds by suffix: missing and empty files, the intensity and time rules, KITTI ``.bin``
and NumPy files, and the real KITTI scan. PCD and PLY: test_io_pcd.py and test_io_ply.py."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.kitti_bin import write_kitti_bin
from nbcalib.io.pointcloud import normalize_point_times, pointcloud_from_fields, read_pointcloud


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
