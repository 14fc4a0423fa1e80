"""`nbcalib preprocess`: plain files and bags to a work directory; bad input is one line, exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nbcalib.cli import main
from nbcalib.io.image import write_png
from nbcalib.io.pcd import write_pcd
from nbcalib.workdir import WorkDir


def room_scan(rng, n=20000):
    """Points on the walls of a 10 x 8 x 3 m room around the sensor, with some texture."""
    pts = []
    for axis, value in ((0, 5.0), (0, -5.0), (1, 4.0), (1, -4.0)):
        p = np.column_stack(
            [rng.uniform(-5, 5, n // 4), rng.uniform(-4, 4, n // 4), rng.uniform(-1.5, 1.5, n // 4)]
        )
        p[:, axis] = value
        pts.append(p)
    pts = np.concatenate(pts)
    intensity = 100 + 100 * np.sin(pts[:, 0] * 3) * np.cos(pts[:, 2] * 4)
    return pts, intensity


@pytest.fixture
def plain_files(tmp_path, rng):
    pts, inten = room_scan(rng)
    cloud = tmp_path / "scan.pcd"
    write_pcd(
        cloud,
        {
            "x": pts[:, 0].astype(np.float32),
            "y": pts[:, 1].astype(np.float32),
            "z": pts[:, 2].astype(np.float32),
            "intensity": inten.astype(np.float32),
        },
    )
    image = tmp_path / "image.png"
    write_png(image, (rng.random((240, 320)) * 255).astype(np.uint8))
    return cloud, image


CAMERA = [
    "--camera-model",
    "plumb_bob",
    "--intrinsics",
    "300,300,159.5,119.5",
    "--distortion",
    "0,0,0,0,0",
]


def test_plain_files_make_a_complete_workdir(plain_files, tmp_path, capsys):
    cloud, image = plain_files
    work = tmp_path / "work"
    assert main(["preprocess", str(cloud), str(image), str(work), *CAMERA]) == 0
    wd = WorkDir(work)
    assert wd.is_complete() and wd.names() == ["000000"]
    pair = wd.load_pair("000000")
    assert pair.image.shape == (240, 320)
    assert pair.points_lidar.shape[0] > 1000
    assert 0 <= pair.intensities.min() and pair.intensities.max() < 1
    # every filled LiDAR pixel points to a real point of the cloud
    idx = pair.lidar_index[pair.lidar_index >= 0]
    assert idx.max() < pair.points_lidar.shape[0]
    calib = json.loads((work / "calib.json").read_text())
    assert calib["camera"]["camera_model"] == "plumb_bob"
    assert calib["meta"]["bag_names"] == ["000000"]
    assert calib["nbcalib"]["preprocess"]["pairs"]["000000"]["mode"] == "static"
    assert "wrote" in capsys.readouterr().out


def test_points_option_form(plain_files, tmp_path):
    cloud, image = plain_files
    work = tmp_path / "w2"
    # WORKDIR after a greedy --points list is recognised
    assert (
        main(["preprocess", "--image", str(image), "--points", str(cloud), str(work), *CAMERA]) == 0
    )
    assert WorkDir(work).is_complete()


def test_camera_file(plain_files, tmp_path):
    from nbcalib.camera import create_camera
    from nbcalib.io.camera_file import save_camera

    cloud, image = plain_files
    cam_file = tmp_path / "camera.yaml"
    save_camera(cam_file, create_camera("pinhole", [300, 300, 159.5, 119.5], [], 320, 240))
    assert (
        main(
            ["preprocess", str(cloud), str(image), str(tmp_path / "w3"), "--camera", str(cam_file)]
        )
        == 0
    )


@pytest.mark.parametrize(
    "make_args, message",
    [
        (lambda c, i, t: [str(c), str(t / "w")], "exactly one image"),
        (lambda c, i, t: [str(c), str(i), str(t / "w")], "no camera info"),
        (lambda c, i, t: [str(t / "missing.pcd"), str(i), str(t / "w"), *CAMERA], "missing.pcd"),
        (lambda c, i, t: [str(t / "notes.txt"), str(i), str(t / "w"), *CAMERA], "notes.txt"),
        (
            lambda c, i, t: [
                str(c),
                str(i),
                str(t / "w"),
                "--camera-model",
                "plumb_bob",
                "--intrinsics",
                "300,300,160",
            ],
            "4 intrinsics",
        ),
        (
            lambda c, i, t: [
                str(c),
                str(i),
                str(t / "w"),
                "--camera-model",
                "pinhole",
                "--intrinsics",
                "600,600,320,240",
                "--distortion",
                "",
            ],
            None,
        ),
        (
            lambda c, i, t: [
                str(c),
                str(i),
                str(t / "w"),
                "--camera-model",
                "nope",
                "--intrinsics",
                "1,1,1,1",
            ],
            "unknown camera model",
        ),
        (lambda c, i, t: [str(c), str(i)], "last argument must be WORKDIR"),
        (
            lambda c, i, t: [str(c), str(i), str(t / "w"), *CAMERA, "--voxel-size", "0"],
            "voxel_size must be",
        ),
    ],
)
def test_user_errors(plain_files, tmp_path, capsys, make_args, message):
    cloud, image = plain_files
    (tmp_path / "notes.txt").write_text("hello")
    status = main(["preprocess", *make_args(cloud, image, tmp_path)])
    err = capsys.readouterr().err
    if message is None:  # a valid run with an empty --distortion
        assert status == 0
        return
    assert status == 2, err
    lines = [line for line in err.splitlines() if line.startswith("nbcalib")]
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in err


def test_image_size_must_match_camera(plain_files, tmp_path, capsys):
    cloud, image = plain_files
    from nbcalib.camera import create_camera
    from nbcalib.io.camera_file import save_camera

    cam_file = tmp_path / "camera.yaml"
    save_camera(cam_file, create_camera("pinhole", [300, 300, 320, 240], [], 640, 480))
    assert (
        main(["preprocess", str(cloud), str(image), str(tmp_path / "w"), "--camera", str(cam_file)])
        == 2
    )
    err = capsys.readouterr().err
    assert "320" in err and "640" in err and err.count("\n") == 1
    assert not (tmp_path / "w" / "calib.json").exists()


def test_empty_and_nan_clouds(tmp_path, capsys, plain_files):
    _, image = plain_files
    for name, values, message in (
        ("empty.pcd", np.zeros((0, 4)), "holds no points"),
        ("nan.pcd", np.full((10, 4), np.nan), "none of its 10 points has a finite x, y and z"),
    ):
        path = tmp_path / name
        write_pcd(
            path,
            {k: values[:, i].astype(np.float32) for i, k in enumerate("xyz")}
            | {"intensity": values[:, 3].astype(np.float32)},
        )
        assert main(["preprocess", str(path), str(image), str(tmp_path / "w"), *CAMERA]) == 2
        err = capsys.readouterr().err
        assert err == f"nbcalib preprocess: error: {path}: {message}\n"
        assert not (tmp_path / "w" / "calib.json").exists()


def test_real_kitti_scan(real_data, tmp_path):
    kitti = real_data / "kitti_raw_2011_09_26"
    work = tmp_path / "kitti"
    status = main(
        [
            "preprocess",
            str(kitti / "0000000000" / "velodyne.bin"),
            str(kitti / "0000000000" / "image_02.png"),
            str(work),
            "--camera",
            str(kitti / "calib" / "calib_normalized_cam2rect.json"),
        ]
    )
    assert status == 0
    pair = WorkDir(work).load_pair("000000")
    assert pair.image.shape == (375, 1242)
    assert pair.lidar_image.intensity.shape == (960, 1920)  # 360-degree LiDAR: equirectangular
    assert (pair.lidar_index >= 0).sum() > 90_000


@pytest.mark.parametrize(
    "bag", ["kitti_2011_09_26_udacity_5frames.bag", "kitti_2011_09_26_udacity_5frames_mcap"]
)
def test_real_bags(real_data, tmp_path, bag):
    work = tmp_path / "bag"
    status = main(["preprocess", str(real_data / "bags" / bag), str(work), "--max-scans", "1"])
    assert status == 0
    wd = WorkDir(work)
    assert wd.names() == [bag]  # the reference keeps a ROS 1 bag's .bag suffix in the name
    calib = json.loads((work / "calib.json").read_text())
    assert calib["meta"]["points_topic"] == "/kitti/velo/pointcloud"
    assert calib["camera"]["camera_model"] in ("plumb_bob", "pinhole")


def test_pairs_preprocessed_on_every_core_equal_one_after_another(tmp_path, monkeypatch):
    """Bags are read, integrated, rendered and written on two threads (nbcalib._threads): the
    work directory holds the same clouds, intensities and LiDAR images as one pair at a time."""
    from nbcalib import _threads

    data = tmp_path / "data"
    synth = ["synth", str(data), "--lidar", "livox", "--camera", "pinhole", "--pairs", "3"]
    assert main([*synth, "--format", "bag1", "--duration", "0.2", "--image-size", "128x96"]) == 0
    bags = sorted(str(p) for p in data.glob("pair_*.bag"))
    works = {}
    for workers in (1, 2):
        monkeypatch.setattr(_threads, "WORKERS", workers)
        works[workers] = WorkDir(tmp_path / f"work{workers}")
        assert main(["-q", "preprocess", *bags, str(works[workers].path)]) == 0
    names = works[1].names()
    assert names == works[2].names() and len(names) == 3
    for name in names:
        one, two = works[1].load_pair(name), works[2].load_pair(name)
        np.testing.assert_array_equal(one.points_lidar, two.points_lidar)
        np.testing.assert_array_equal(one.intensities, two.intensities)
        np.testing.assert_array_equal(one.lidar_index, two.lidar_index)
        np.testing.assert_array_equal(one.image, two.image)
    summary = [
        json.loads((w.path / "calib.json").read_text())["nbcalib"]["preprocess"]
        for w in works.values()
    ]
    assert summary[0] == summary[1]
