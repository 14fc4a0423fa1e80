"""Synthetic data on disk: PCD + PNG files, ROS 1 / ROS 2 / mcap bags, and ``nbcalib synth``."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from nbcalib.cli import main
from nbcalib.io.bag import read_camera_info, read_images, read_pointclouds, read_tf_static
from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.io.image import read_image
from nbcalib.io.pointcloud import read_pointcloud
from nbcalib.synthetic import RigConfig, lidar_preset
from nbcalib.synthetic import writer as export_module
from nbcalib.synthetic.rig import generate_sequence
from nbcalib.synthetic.writer import TOPICS, export_dataset, scan_fields

pytest.importorskip("rosbags")


def _config(**kw) -> RigConfig:
    return RigConfig(
        lidar="spinning16",
        camera="fisheye",
        image_size=(96, 72),
        duration=0.3,
        lidar_config=lidar_preset("spinning16", columns=180),
        seed=5,
        **kw,
    )


def test_files_read_back(tmp_path):
    config = _config(color=True)
    truth = export_dataset(config, tmp_path, pairs=2)
    assert_allclose(read_ground_truth(tmp_path / "ground_truth.json"), truth["T_camera_lidar"])
    for pair in range(2):
        seq = generate_sequence(config, pair=pair)
        assert_allclose(read_ground_truth(tmp_path / "ground_truth.json"), seq.T_camera_lidar)
        assert load_camera(tmp_path / "camera.yaml") == seq.camera
        assert_array_equal(read_image(tmp_path / f"pair_{pair:03d}.png", grey=False), seq.image)
        # one PCD with every scan, times since the image; one PCD per scan (the rig moves)
        cloud = read_pointcloud(tmp_path / f"pair_{pair:03d}.pcd")
        assert list(cloud.fields) == ["x", "y", "z", "intensity", "t", "ring"]
        assert cloud.fields["ring"].dtype == np.uint16 and cloud.fields["t"].dtype == np.float32
        points = np.concatenate([s.points for s in seq.scans])
        assert_allclose(cloud.points, points.astype(np.float32), rtol=0, atol=0)
        stamps = np.concatenate([s.times + s.stamp for s in seq.scans])
        assert_allclose(cloud.times, stamps.astype(np.float32), rtol=0, atol=0)
        assert len(truth["pairs"][pair]["scans"]) == len(seq.scans) == 3
        last = read_pointcloud(tmp_path / truth["pairs"][pair]["scans"][-1])
        assert_allclose(last.times, seq.scans[-1].times.astype(np.float32), rtol=0, atol=0)
        assert_allclose(last.intensity, seq.scans[-1].intensities.astype(np.float32), rtol=0)


@pytest.mark.parametrize("fmt", ["bag1", "bag2", "mcap"])
def test_bags_read_back_with_rosbags(tmp_path, fmt):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    config = _config()
    truth = export_dataset(config, tmp_path, fmt=fmt)
    seq = generate_sequence(config)
    bag = tmp_path / truth["pairs"][0]["bag"]
    assert bag.exists()
    # plain rosbags, no nbcalib: topics, types, counts, and one PointCloud2's layout
    store = get_typestore(Stores.ROS1_NOETIC if fmt == "bag1" else Stores.ROS2_HUMBLE)
    with AnyReader([bag], default_typestore=store) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        types = {c.topic: c.msgtype for c in reader.connections}
        assert counts == {
            TOPICS["points"]: 3,
            TOPICS["image"]: 1,
            TOPICS["camera_info"]: 1,
            "/tf_static": 1,
        }
        assert types[TOPICS["points"]] == "sensor_msgs/msg/PointCloud2"
        points = [c for c in reader.connections if c.topic == TOPICS["points"]]
        stamps = []
        for connection, timestamp, raw in reader.messages(connections=points):
            msg = reader.deserialize(raw, connection.msgtype)
            stamps.append(timestamp)
            names = [f.name for f in msg.fields]
            assert names == ["x", "y", "z", "intensity", "t", "ring"]
        assert np.all(np.diff(stamps) == 100_000_000)  # 10 Hz
    # nbcalib's readers: everything as simulated
    clouds = list(read_pointclouds(bag))
    for (_, cloud), scan in zip(clouds, seq.scans):
        fields = scan_fields(scan)
        assert_array_equal(cloud.points, np.column_stack([fields[c] for c in "xyz"]))
        assert_array_equal(cloud.fields["ring"], fields["ring"])
        assert_allclose(cloud.times, fields["t"], rtol=0, atol=0)
    (stamp, image), *_ = read_images(bag)
    assert_array_equal(image, seq.image)
    assert stamp == clouds[0][0]  # the image pairs with the first scan
    assert_allclose(
        read_camera_info(bag).project(np.array([[0.3, -0.2, 1.0]]))[0],
        seq.camera.project(np.array([[0.3, -0.2, 1.0]]))[0],
        atol=1e-9,
    )
    ((parent, child, T),) = read_tf_static(bag)
    assert (parent, child) == ("lidar", "camera")
    assert_allclose(T, seq.T_lidar_camera, atol=1e-9)


def test_ground_truth_is_written_last(tmp_path, monkeypatch):
    export_dataset(_config(), tmp_path)
    assert (tmp_path / "ground_truth.json").exists()

    def crash(config, pair=0, progress=None):
        if pair == 1:
            raise RuntimeError("simulated crash")
        return generate_sequence(config, pair=pair, progress=progress)

    monkeypatch.setattr(export_module, "generate_sequence", crash)
    with pytest.raises(RuntimeError):
        export_dataset(_config(), tmp_path, pairs=2)
    assert not (tmp_path / "ground_truth.json").exists()


def test_cli_livox_omnidir(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["synth", str(out), "--lidar", "livox", "--camera", "omnidir", "--pairs", "3"]
    assert main([*args, "--seed", "1", "--duration", "0.2", "--image-size", "128x96"]) == 0
    assert "3 pair(s)" in capsys.readouterr().out
    truth = json.loads((out / "ground_truth.json").read_text())
    assert len(truth["T_lidar_camera"]) == 7 and np.shape(truth["T_camera_lidar"]) == (4, 4)
    assert truth["lidar"] == "livox" and truth["camera_model"] == "omnidir" and truth["seed"] == 1
    for pair in range(3):
        assert (out / f"pair_{pair:03d}.png").exists() and (out / f"pair_{pair:03d}.pcd").exists()
    assert not (out / "pair_000_scans").exists()  # a static rig needs one file per pair
    assert load_camera(out / "camera.yaml").model == "omnidir"


def test_cli_bag2(tmp_path):
    out = tmp_path / "out"
    args = ["synth", str(out), "--format", "bag2", "--duration", "0.2", "--image-size", "64x48"]
    assert main([*args, "--lidar", "spinning16", "--camera", "equirectangular"]) == 0
    assert (out / "pair_000" / "metadata.yaml").exists()
    assert read_camera_info(out / "pair_000").model == "equirectangular"
    assert (out / "ground_truth.json").exists()


def test_cli_user_errors(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "a"), "--pairs", "0"]) == 2
    (tmp_path / "file").write_text("x")
    assert main(["synth", str(tmp_path / "file")]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["synth", str(tmp_path / "b"), "--without", "optics,shadow"]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--without: unknown effect 'shadow'; expected some of shading, shadows," in err
    assert "lidar-falloff, motion" in err
    assert not (tmp_path / "b" / "ground_truth.json").exists()


def test_motion_compensated_files(tmp_path):
    """``without=("motion",)``: one cloud per pair, deskewed with the true trajectory, t = 0."""
    config = _config(without=("motion",))
    truth = export_dataset(config, tmp_path)
    assert truth["without"] == ["motion"] and truth["modality_gap"] == 1.0
    seq = generate_sequence(config)
    assert len(seq.scans) == 3 and seq.motion.kind == "nod"  # a moving rig ...
    assert sorted(os.listdir(tmp_path)) == [  # ... written as a static one
        "camera.yaml",
        "ground_truth.json",
        "pair_000.pcd",
        "pair_000.png",
    ]
    cloud = read_pointcloud(tmp_path / "pair_000.pcd")
    points, intensities = seq.dense_cloud()
    assert_array_equal(cloud.points, points.astype(np.float32))
    assert_array_equal(cloud.intensity, intensities.astype(np.float32))
    assert np.all(cloud.times == 0.0)
    info = truth["pairs"][0]
    assert info["scan_stamps_ns"] == [info["image_stamp_ns"]]
    assert info["num_points"] == len(points)
    assert "scans" not in info and "T_world_lidar_scan_begin" not in info
    # the image and the simulated sweeps are those of the same pair without the switch
    plain = generate_sequence(_config())
    assert_array_equal(seq.image, plain.image)
    for a, b in zip(seq.scans, plain.scans):
        assert_array_equal(a.points, b.points)
    # preprocessing only accumulates: a static integration of the same points (2 mm voxels)
    work = tmp_path / "work"
    args = ["--points", str(tmp_path / "pair_000.pcd"), "--image", str(tmp_path / "pair_000.png")]
    camera = str(tmp_path / "camera.yaml")
    assert main(["-q", "preprocess", *args, "--camera", camera, str(work)]) == 0
    summary = json.loads((work / "calib.json").read_text())["nbcalib"]["preprocess"]["pairs"]
    (pair,) = summary.values()
    assert pair["mode"] == "static" and 0.99 * len(points) < pair["points"] <= len(points)


def test_motion_compensated_bag(tmp_path):
    config = _config(without=("motion", "lidar-noise"))
    truth = export_dataset(config, tmp_path, fmt="mcap")
    seq = generate_sequence(config)
    ((stamp, cloud),) = read_pointclouds(tmp_path / truth["pairs"][0]["bag"])
    ((image_stamp, _),) = read_images(tmp_path / truth["pairs"][0]["bag"])
    assert stamp == image_stamp == truth["pairs"][0]["image_stamp_ns"]
    points, _ = seq.dense_cloud()
    assert_array_equal(cloud.points, points.astype(np.float32))
    assert np.all(cloud.times == 0.0)
    assert truth["without"] == ["lidar-noise", "motion"]
    assert truth["pairs"][0]["lidar_config"]["range_noise"] == 0.0  # the LiDAR as simulated


def test_cli_without(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["synth", str(out), "--lidar", "livox", "--duration", "0.1", "--image-size", "64x48"]
    assert main([*args, "--seed", "2"]) == 0
    default = json.loads((out / "ground_truth.json").read_text())
    assert default["without"] == []
    image = read_image(out / "pair_000.png")
    assert main([*args, "--seed", "2", "--without", " optics, shading ,optics"]) == 0
    truth = json.loads((out / "ground_truth.json").read_text())
    assert truth["without"] == ["shading", "optics"]
    assert not np.array_equal(read_image(out / "pair_000.png"), image)


@pytest.mark.slow
def test_cli_documented_command(tmp_path):
    """The exact command of the issue, with the defaults (3 pairs of 10 s of Livox)."""
    out = tmp_path / "out"
    cmd = ["synth", str(out), "--lidar", "livox", "--camera", "omnidir", "--pairs", "3"]
    assert main([*cmd, "--seed", "1"]) == 0
    assert sorted(os.listdir(out)) == sorted(
        ["camera.yaml", "ground_truth.json"]
        + [f"pair_{p:03d}.{s}" for p in range(3) for s in ("png", "pcd")]
    )
