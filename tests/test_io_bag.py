"""Bag round trips (ROS 1, ROS 2 sqlite3, ROS 2 mcap) with BagWriter, Livox CustomMsg, topic
selection, corrupt bags, and the three real KITTI bags."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nbcalib.errors import InputError

pytest.importorskip("rosbags")

from nbcalib.camera import create_camera
from nbcalib.io.bag import (
    list_topics,
    open_bag,
    read_camera_info,
    read_images,
    read_pointclouds,
    read_tf_static,
)
from nbcalib.io.bag_messages import parse_livox_raw
from nbcalib.io.bag_writer import BagWriter
from nbcalib.io.image import read_image, rgb_to_grey
from nbcalib.io.pointcloud import read_pointcloud

FORMATS = [("bag1", "test.bag"), ("bag2", "test_db3"), ("mcap", "test_mcap")]

# ------------------------------------------------------------------------------ bag round trips


def _cloud_fields(rng, n):
    return {
        "x": rng.normal(size=n).astype(np.float32) * 10,
        "y": rng.normal(size=n).astype(np.float32) * 10,
        "z": rng.normal(size=n).astype(np.float32),
        "intensity": rng.uniform(0, 255, n).astype(np.float32),
        "t": np.linspace(0, 0.1, n).astype(np.float32),
        "ring": rng.integers(0, 32, n).astype(np.uint16),
    }


CAMERAS = [
    ("plumb_bob", [500, 510, 320, 240], [0.1, -0.05, 0.001, 0.002, 0.01]),
    ("rational_polynomial", [500, 500, 320, 240], [0.1, -0.05, 0.001, 0.002, 0.01, 0.1, 0, 0]),
    ("fisheye", [300, 300, 320, 240], [0.01, -0.02, 0.003, -0.001]),
    ("atan", [400, 400, 320, 240], [0.9]),
    ("omnidir", [400, 400, 320, 240, 0.8], [-0.1, 0.02, 0.001, 0.001]),
    ("equirectangular", [640, 480], []),
]


@pytest.mark.parametrize(("fmt", "name"), FORMATS)
def test_bag_round_trip(tmp_path, rng, fmt, name):
    path = tmp_path / name
    clouds = [_cloud_fields(rng, 300 + 10 * k) for k in range(3)]
    rgb = rng.integers(0, 256, (24, 32, 3)).astype(np.uint8)
    mono = rng.integers(0, 256, (24, 32)).astype(np.uint8)
    cameras = [create_camera(m, i, d, 640, 480) for m, i, d in CAMERAS]
    T_cam_lidar = np.array(
        [[0.0, -1.0, 0.0, 0.05], [0.0, 0.0, -1.0, -0.07], [1.0, 0.0, 0.0, -0.27], [0, 0, 0, 1]]
    )
    stamps = [1_317_046_000_000_000_000 + k * 100_000_000 + 7 for k in range(3)]
    with BagWriter(path, fmt) as bag:
        bag.write_tf_static(stamps[0], "camera", "lidar", T_cam_lidar)
        for k, stamp in enumerate(stamps):
            bag.write_pointcloud("/points", stamp, clouds[k], "lidar")
            bag.write_image("/image_rgb", stamp, rgb, "camera")
            bag.write_image("/image_mono", stamp, mono, "camera")
            bag.write_compressed_image("/image/compressed", stamp, rgb, "camera")
        for k, camera in enumerate(cameras):
            bag.write_camera_info(f"/camera_info_{k}", stamps[0], camera, "camera")
    assert list(tmp_path.iterdir()) == [path]  # written under a temporary name, then renamed
    topics = list_topics(path)
    assert topics["/points"] == "sensor_msgs/msg/PointCloud2"
    assert topics["/tf_static"] == "tf2_msgs/msg/TFMessage"

    read = list(read_pointclouds(path))
    assert [s for s, _ in read] == stamps
    for (_, cloud), fields in zip(read, clouds):
        assert list(cloud.fields) == list(fields)
        for key, values in fields.items():
            assert cloud.fields[key].dtype == values.dtype
            assert np.array_equal(cloud.fields[key], values), key
        assert np.array_equal(cloud.times, fields["t"].astype(np.float64))

    images = list(read_images(path, "/image_rgb", grey=False))
    assert [s for s, _ in images] == stamps and np.array_equal(images[0][1], rgb)

    # stamps read from the serialised headers, and only the chosen messages decoded
    with open_bag(path) as bag:
        for topic in ("/points", "/image_rgb", "/image/compressed"):
            assert bag.stamps(topic) == stamps, topic
        [(stamp, cloud)] = list(bag.pointclouds("/points", only={2}))
        assert stamp == stamps[2] and np.array_equal(cloud.fields["x"], clouds[2]["x"])
        assert [s for s, _ in bag.images("/image_mono", only={0, 2})] == [stamps[0], stamps[2]]
        assert list(bag.pointclouds("/points", only=set())) == []
    assert np.array_equal(next(read_images(path, "/image_rgb"))[1], rgb_to_grey(rgb))
    assert np.array_equal(next(read_images(path, "/image_mono"))[1], mono)
    assert np.array_equal(next(read_images(path, "/image/compressed", grey=False))[1], rgb)

    for k, camera in enumerate(cameras):
        assert read_camera_info(path, f"/camera_info_{k}") == camera, camera.model

    [(parent, child, T)] = read_tf_static(path)
    assert (parent, child) == ("camera", "lidar")
    np.testing.assert_allclose(T, T_cam_lidar, rtol=0, atol=1e-15)


def test_pinhole_camera_info_is_plumb_bob_with_zero_distortion(tmp_path):
    camera = create_camera("pinhole", [500, 500, 320, 240], [], 640, 480)
    with BagWriter(tmp_path / "p.bag", "bag1") as bag:
        bag.write_camera_info("/info", 0, camera, "cam")
    with open_bag(tmp_path / "p.bag") as bag:
        [(_, msg)] = list(bag.messages("/info"))
    assert msg.distortion_model == "plumb_bob" and list(msg.D) == [0.0] * 5
    read = read_camera_info(tmp_path / "p.bag")
    np.testing.assert_array_equal(
        read.project(np.array([[0.3, -0.2, 2.0]]))[0],
        camera.project(np.array([[0.3, -0.2, 2.0]]))[0],
    )


@pytest.mark.parametrize(("fmt", "name"), FORMATS)
@pytest.mark.parametrize("package", ["livox_ros_driver2", "livox_ros_driver"])
def test_livox_custom_msg(tmp_path, rng, fmt, name, package):
    n = 1000
    fields = {
        "x": rng.normal(size=n).astype(np.float32),
        "y": rng.normal(size=n).astype(np.float32),
        "z": rng.normal(size=n).astype(np.float32),
        "reflectivity": rng.integers(0, 256, n).astype(np.uint8),
        "offset_time": np.sort(rng.integers(0, 100_000_000, n)).astype(np.uint32),
        "tag": rng.integers(0, 4, n).astype(np.uint8),
        "line": rng.integers(0, 6, n).astype(np.uint8),
    }
    fields["offset_time"][0] = 0
    path = tmp_path / name
    with BagWriter(path, fmt) as bag:
        bag.write_livox("/livox/lidar", 5_000_000_123, fields, "livox_frame", package=package)
        bag.write_livox(
            "/livox/lidar",
            5_100_000_000,
            {k: v[:1] for k, v in fields.items()},
            "livox_frame",
            package=package,
        )
    assert list_topics(path)["/livox/lidar"] == f"{package}/msg/CustomMsg"
    (stamp, cloud), (_, single) = list(read_pointclouds(path))
    assert stamp == 5_000_000_123 and len(single) == 1
    with open_bag(path) as bag:
        assert bag.stamps("/livox/lidar") == [5_000_000_123, 5_100_000_000]
    for key, values in fields.items():
        assert np.array_equal(cloud.fields[key], values), key
    assert np.array_equal(cloud.intensity, fields["reflectivity"].astype(np.float64))
    assert np.allclose(cloud.times, fields["offset_time"] * 1e-9, rtol=0, atol=1e-15)
    # the byte-level fast path agrees with rosbags' own deserialisation (the fallback)
    with open_bag(path) as bag:
        [(_, msgtype, raw), _] = list(bag.raw_messages("/livox/lidar"))
        parsed_stamp, parsed = parse_livox_raw(bytes(raw), cdr=fmt != "bag1")
        msg = bag._deserialize(raw, msgtype, "/livox/lidar")
    assert parsed_stamp == 5_000_000_123
    assert np.array_equal(parsed["offset_time"], [p.offset_time for p in msg.points])
    assert np.array_equal(parsed["line"], [p.line for p in msg.points])


def test_livox_fallback_equals_fast_path(tmp_path, rng, monkeypatch):
    import nbcalib.io.bag as bag_module

    n = 50
    fields = {c: rng.normal(size=n).astype(np.float32) for c in "xyz"}
    fields["reflectivity"] = rng.integers(0, 256, n).astype(np.uint8)
    fields["offset_time"] = np.arange(n, dtype=np.uint32) * 1000
    with BagWriter(tmp_path / "l_mcap", "mcap") as bag:
        bag.write_livox("/livox", 1_000, fields, "livox")
    fast = next(read_pointclouds(tmp_path / "l_mcap"))
    monkeypatch.setattr(bag_module, "parse_livox_raw", lambda raw, cdr: None)
    slow = next(read_pointclouds(tmp_path / "l_mcap"))
    assert fast[0] == slow[0] == 1_000
    for key in fast[1].fields:
        assert fast[1].fields[key].dtype == slow[1].fields[key].dtype
        assert np.array_equal(fast[1].fields[key], slow[1].fields[key]), key
    assert np.array_equal(fast[1].times, slow[1].times)


def test_topic_selection_errors(tmp_path, rng):
    path = tmp_path / "two.bag"
    with BagWriter(path, "bag1") as bag:
        bag.write_pointcloud("/velodyne_points", 1, _cloud_fields(rng, 10), "lidar")
        bag.write_pointcloud("/ouster/points", 1, _cloud_fields(rng, 10), "lidar")
        bag.write_image("/image", 1, np.zeros((4, 4), np.uint8), "cam")
    with pytest.raises(
        InputError, match=r"several point cloud topics: /ouster/points .*, /velodyne_points"
    ) as info:
        next(read_pointclouds(path))
    assert str(path) in str(info.value)
    assert len(next(read_pointclouds(path, "/ouster/points"))[1]) == 10
    with pytest.raises(
        InputError, match=r"no camera info topic .*; the bag has: /image \(sensor_msgs/msg/Image\)"
    ) as info:
        read_camera_info(path)
    assert str(path) in str(info.value)
    with pytest.raises(
        InputError,
        match="no topic '/lidar' in the bag; point cloud topics: /ouster/points, /velodyne_points",
    ):
        next(read_pointclouds(path, "/lidar"))
    with pytest.raises(
        InputError, match="topic '/image' has type sensor_msgs/msg/Image, not a point cloud type"
    ):
        next(read_pointclouds(path, "/image"))
    assert read_tf_static(path) == []


def test_topics_command_lists_and_says_what_preprocess_reads(tmp_path, rng, capsys):
    from nbcalib.cli import main

    path = tmp_path / "two.bag"
    with BagWriter(path, "bag1") as bag:
        for stamp in (1, 2):
            bag.write_pointcloud("/velodyne_points", stamp, _cloud_fields(rng, 10), "lidar")
        bag.write_pointcloud("/ouster/points", 1, _cloud_fields(rng, 10), "lidar")
        bag.write_image("/image", 1, np.zeros((4, 4), np.uint8), "cam")
    assert main(["topics", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{path}: 3 topics"
    rows = {line.split()[0]: line.split()[1:] for line in out[1:4]}
    assert rows == {
        "/image": ["sensor_msgs/msg/Image", "1", "messages"],
        "/ouster/points": ["sensor_msgs/msg/PointCloud2", "1", "messages"],
        "/velodyne_points": ["sensor_msgs/msg/PointCloud2", "2", "messages"],
    }
    reads = "\n".join(out[4:])
    assert "point cloud:  one of /ouster/points, /velodyne_points: name it with --points-topic" in (
        reads
    )
    assert "image:        /image" in reads
    assert "camera info:  nothing: no camera info topic" in reads
    # a bad bag: the one-line error, exit 2
    (tmp_path / "junk.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    assert main(["topics", str(tmp_path / "junk.bag")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "junk.bag" in err[0] and "cannot open as a ROS bag" in err[0]


def test_bad_bags_raise_input_error(tmp_path):
    with pytest.raises(InputError, match="bag not found") as info:
        list_topics(tmp_path / "missing.bag")
    assert "missing.bag" in str(info.value)
    (tmp_path / "junk.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    with pytest.raises(InputError, match="cannot open as a ROS bag") as info:
        list_topics(tmp_path / "junk.bag")
    assert "junk.bag" in str(info.value)
    (tmp_path / "folder").mkdir()
    with pytest.raises(InputError, match="not a ROS 2 bag"):
        list_topics(tmp_path / "folder")
    (tmp_path / "scan.txt").write_text("hello")
    with pytest.raises(InputError, match="unknown bag suffix"):
        list_topics(tmp_path / "scan.txt")


def test_writer_refuses_existing_and_cleans_up_after_errors(tmp_path, rng):
    path = tmp_path / "out.bag"
    with BagWriter(path, "bag1") as bag:
        bag.write_image("/image", 1, np.zeros((4, 4), np.uint8), "cam")
    with pytest.raises(InputError, match="exists already"):
        BagWriter(path, "bag1")
    with pytest.raises(RuntimeError, match="boom"), BagWriter(path, "bag1", overwrite=True) as bag:
        bag.write_image("/other", 1, np.zeros((4, 4), np.uint8), "cam")
        raise RuntimeError("boom")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bag"]  # old bag kept, no leftovers
    assert list(list_topics(path)) == ["/image"]
    with BagWriter(path, "bag1", overwrite=True) as bag:
        bag.write_image("/other", 1, np.zeros((4, 4), np.uint8), "cam")
    assert list(list_topics(path)) == ["/other"]
    with pytest.raises(ValueError, match=r"end in \.bag"):
        BagWriter(tmp_path / "x.db3", "bag1")
    with pytest.raises(ValueError, match="fmt must be"):
        BagWriter(tmp_path / "x", "rosbag3")


# ------------------------------------------------------------------------------------ real bags

REAL_BAGS = [
    "kitti_2011_09_26_udacity_5frames.bag",
    "kitti_2011_09_26_udacity_5frames_db3",
    "kitti_2011_09_26_udacity_5frames_mcap",
]


@pytest.mark.parametrize("name", REAL_BAGS)
def test_real_bags(real_data, name):
    path = real_data / "bags" / name
    kitti = real_data / "kitti_raw_2011_09_26"
    topics = list_topics(path)
    assert topics == {
        "/kitti/camera_color_left/camera_info": "sensor_msgs/msg/CameraInfo",
        "/kitti/camera_color_left/image_raw": "sensor_msgs/msg/Image",
        "/kitti/velo/pointcloud": "sensor_msgs/msg/PointCloud2",
        "/tf_static": "tf2_msgs/msg/TFMessage",
    }
    clouds = list(read_pointclouds(path))
    assert len(clouds) == 5
    assert [s for s, _ in clouds] == [1_317_046_000_000_000_000 + k * 100_000_000 for k in range(5)]
    first = clouds[0][1]
    assert list(first.fields) == ["x", "y", "z", "intensity"]
    assert all(first.fields[k].dtype == np.float32 for k in first.fields)
    # the first scan is frame 0000000000 of the KITTI folder
    assert np.array_equal(
        first.points, read_pointcloud(kitti / "0000000000" / "velodyne.bin").points
    )
    assert 0.0 <= first.intensity.min() and first.intensity.max() <= 1.0

    images = list(read_images(path, grey=False))
    assert len(images) == 5 and images[0][1].shape == (375, 1242, 3)
    assert np.array_equal(
        images[0][1], read_image(kitti / "0000000000" / "image_02.png", grey=False)
    )
    assert next(read_images(path))[1].shape == (375, 1242)

    calib = json.loads((kitti / "calib" / "calib_normalized_cam2rect.json").read_text())
    camera = read_camera_info(path)
    assert camera.model == "plumb_bob" and np.all(camera.distortion_coeffs == 0)
    np.testing.assert_allclose(camera.K, calib["K"], rtol=0, atol=1e-4)
    [(parent, child, T)] = read_tf_static(path)
    assert (parent, child) == ("camera_color_left", "velo_link")
    # KITTI's rotation is orthonormal to ~2e-8 only; the bag stores a unit quaternion
    np.testing.assert_allclose(T[:3, :3], np.array(calib["T_cam_lidar"])[:3, :3], rtol=0, atol=1e-7)
    np.testing.assert_allclose(T[:3, 3], np.array(calib["T_cam_lidar"])[:3, 3], rtol=0, atol=1e-12)
