"""Several pairs from one recording: frames, scans with several images, bags cut per image.

The analytic scene of the odometry tests (tests/odometry_scene.py: a spinning LiDAR moving at
constant velocity, ground truth known to rounding) is written as frames, image sequences and a
bag; the pairs made from them must have the right names, scans and image times, and the dense
cloud of a pair made per image must sit in the LiDAR frame at the image's time.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from odometry_scene import SCAN_PERIOD, constant_velocity, make_sequence, scene_distance

from nbcalib.cli import main
from nbcalib.errors import InputError
from nbcalib.io.image import write_png
from nbcalib.io.pcd import write_pcd
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.inputs import InputSpec
from nbcalib.preprocess.prepare import prepare_pair
from nbcalib.preprocess.recording import parse_times, scan_window, select_images
from nbcalib.transforms import interpolate_pose, invert_T, make_T
from nbcalib.workdir import WorkDir

CAMERA = ["--camera-model", "pinhole", "--intrinsics", "300,300,159.5,119.5"]
SPEC_CAMERA = {"camera_model": "pinhole", "intrinsics": "300,300,159.5,119.5"}
N_SCANS = 4


@pytest.fixture(scope="module")
def sequence():
    return make_sequence(N_SCANS)


def _write_scan(path, scan, times):
    fields = {k: scan[:, i].astype(np.float32) for i, k in enumerate("xyz")}
    fields["intensity"] = (200 * scan[:, 3]).astype(np.float32)
    fields["t"] = times.astype(np.float32)
    write_pcd(path, fields)


def _image(k):
    rng = np.random.default_rng(k)
    return (rng.random((240, 320)) * 255).astype(np.uint8)


@pytest.fixture(scope="module")
def frames(tmp_path_factory, sequence):
    """frame_<k>/scan.pcd + image.png for the sequence's scans, and a folder that is no frame."""
    root = tmp_path_factory.mktemp("frames")
    scans, times, _ = sequence
    for k in range(N_SCANS):
        folder = root / f"frame_{k}"
        folder.mkdir()
        _write_scan(folder / "scan.pcd", scans[k], times[k])
        write_png(folder / "image.png", _image(k))
    (root / "calib").mkdir()
    (root / "calib" / "notes.txt").write_text("not a frame")
    return root


def _true_pose(t):
    R, p = constant_velocity(np.array([float(t)]))
    return make_T(R[0], p[0])


# ---------------------------------------------------------------------------------------------
# Choosing images and scans


def test_select_images_and_scan_windows():
    assert select_images(5) == [0, 1, 2, 3, 4]
    assert select_images(7, every=3) == [0, 3, 6]
    assert select_images(20, pair_count=4) == [0, 6, 13, 19]
    assert select_images(5, pair_count=1) == [0]
    with pytest.raises(InputError, match="more pairs than the 3 images"):
        select_images(3, pair_count=4)
    assert scan_window(5, 1, 20) == range(5, 6)
    assert scan_window(5, 3, 20) == range(4, 7)
    assert scan_window(5, 10, 20) == range(1, 11)  # one more after than before
    assert scan_window(0, 3, 20) == range(0, 3)  # shifted at the ends
    assert scan_window(19, 3, 20) == range(17, 20)
    assert scan_window(1, 10, 3) == range(0, 3)  # clipped


def test_parse_times_numbers_and_kitti_files(tmp_path):
    np.testing.assert_array_equal(parse_times("0.5,1.25", "--image-times"), [0.5, 1.25])
    stamps = tmp_path / "timestamps.txt"
    stamps.write_text("2011-09-26 13:02:25.964389445\n\n2011-09-26 13:02:26.064 \n")
    times = parse_times(str(stamps), "--image-times")
    assert times[1] - times[0] == pytest.approx(0.099610555, abs=1e-6)
    stamps.write_text("1.0\nlater\n")
    with pytest.raises(InputError, match=r"timestamps.txt: line 2 is not a time"):
        parse_times(str(stamps), "--image-times")
    with pytest.raises(InputError, match="comma-separated seconds or a file"):
        parse_times("soon", "--image-times")


# ---------------------------------------------------------------------------------------------
# Frames


def test_frames_make_one_pair_each_named_after_its_folder(frames, tmp_path, capsys):
    work = tmp_path / "work"
    assert main(["-q", "preprocess", "--frames", str(frames), str(work), *CAMERA]) == 0
    assert WorkDir(work).names() == [f"frame_{k}" for k in range(N_SCANS)]
    summary = json.loads((work / "calib.json").read_text())["nbcalib"]["preprocess"]["pairs"]
    for k in range(N_SCANS):  # one scan each, static, not moved: as a plain pair of files
        pair = summary[f"frame_{k}"]
        assert pair["scans"] == 1 and pair["mode"] == "static" and pair["image_scan"] == k
        assert pair["image_fraction"] == 0.5 and "image_frame_offset_m" not in pair
    inputs = json.loads((work / "calib.json").read_text())["nbcalib"]["inputs"]
    assert InputSpec.from_dict(inputs).frames == str(frames.absolute())


def test_run_takes_the_recording_from_a_config_file_and_resumes_with_it(frames, tmp_path):
    job = tmp_path / "job.toml"
    job.write_text(
        f'frames = "{frames}"\nevery = 2\ncamera-model = "pinhole"\n'
        'intrinsics = "300,300,159.5,119.5"\n'
    )
    work = tmp_path / "work"
    assert main(["-q", "run", "--config", str(job), str(work), "--until", "preprocess"]) == 0
    assert WorkDir(work).names() == ["frame_0", "frame_2"]
    recorded = json.loads((work / "calib.json").read_text())["nbcalib"]["inputs"]
    assert recorded["every"] == 2 and recorded["frames"] == str(frames.absolute())
    spec = InputSpec.from_dict(recorded)
    assert spec.every == 2 and spec.to_dict() == recorded


def test_neighbours_make_a_denser_cloud_at_the_image_time(frames, sequence):
    """K = 3: the scans around the image, deskewed, in the LiDAR frame at the image's time."""
    from nbcalib.odometry import integrate_dynamic

    spec = InputSpec(frames=str(frames), **SPEC_CAMERA)
    config = PreprocessConfig(neighbors=3, voxel_size=0.01)
    pairs, _, _ = spec.gather(config)
    single, _, _ = InputSpec(frames=str(frames), pair_count=1, **SPEC_CAMERA).gather(
        PreprocessConfig(voxel_size=0.01)
    )
    assert [len(p.scans) for p in pairs] == [3, 3, 3, 3]
    pair = pairs[2]  # image during scan 2, the window is scans 1-3
    assert pair.info == {"first_scan": 1, "image_scan": 2, "image_fraction": 0.5}
    assert pair.scans[0] is pairs[1].scans[1]  # each scan is read once
    dense = prepare_pair(pair, config)
    sparse = prepare_pair(single[0], PreprocessConfig(voxel_size=0.01))
    assert dense.summary["mode"] == "dynamic"
    assert len(dense.points_lidar) > 2 * len(sparse.points_lidar)

    # the direct computation: integrate, interpolate the trajectory at the image, move the cloud
    cloud = integrate_dynamic(pair.scans, voxel_size=0.01)
    T_first_image = interpolate_pose(cloud.T_first_scanbegin[1], cloud.T_first_scanend[1], 0.5)
    T_image_first = invert_T(T_first_image)
    expected = cloud.points @ T_image_first[:3, :3].T + T_image_first[:3, 3]
    np.testing.assert_allclose(dense.points_lidar, expected, atol=1e-5)
    offset = dense.summary["image_frame_offset_m"]
    assert offset == pytest.approx(np.linalg.norm(T_first_image[:3, 3]))

    # and the truth: the frame at the image is where the LiDAR was then
    _, times, _ = sequence
    t_image = 2 * SCAN_PERIOD + 0.5 * times[2][-1]
    T_true = invert_T(_true_pose(1 * SCAN_PERIOD)) @ _true_pose(t_image)
    assert offset == pytest.approx(np.linalg.norm(T_true[:3, 3]), abs=0.01)
    assert offset > 0.2  # 1.5 scans at 1.55 m/s: far from the first scan's start
    world = dense.points_lidar @ _true_pose(t_image)[:3, :3].T + _true_pose(t_image)[:3, 3]
    assert np.median(scene_distance(world)) < 0.01
    at_start = cloud.points @ _true_pose(t_image)[:3, :3].T + _true_pose(t_image)[:3, 3]
    assert np.median(scene_distance(at_start)) > 0.05  # the first scan's frame is not it


def test_more_neighbours_than_scans_are_clipped_with_a_warning(frames, caplog):
    spec = InputSpec(frames=str(frames), every=3, **SPEC_CAMERA)
    with caplog.at_level(logging.WARNING, logger="nbcalib"):
        pairs, _, _ = spec.gather(PreprocessConfig(neighbors=10))
    assert [p.name for p in pairs] == ["frame_0", "frame_3"]
    assert all(len(p.scans) == N_SCANS for p in pairs)
    assert "the recording has 4: each pair accumulates 4" in caplog.text


def test_kitti_raw_layout_with_timestamps(tmp_path, sequence):
    from nbcalib.io.kitti_bin import write_kitti_bin

    scans, _, _ = sequence
    root = tmp_path / "2011_09_26_drive_0001_sync"
    (root / "velodyne_points" / "data").mkdir(parents=True)
    (root / "image_02" / "data").mkdir(parents=True)
    for k in range(3):
        name = f"{k:010d}"
        write_kitti_bin(root / "velodyne_points" / "data" / f"{name}.bin", scans[k][:, :3],
                        scans[k][:, 3])  # fmt: skip
        write_png(root / "image_02" / "data" / f"{name}.png", _image(k))
    spec = InputSpec(frames=str(root), **SPEC_CAMERA)
    pairs, _, data_path = spec.gather(PreprocessConfig())
    assert [p.name for p in pairs] == ["0000000000", "0000000001", "0000000002"]
    assert [p.image_fraction for p in pairs] == [0.5, 0.5, 0.5] and data_path == str(root)

    def stamps(path, values):
        path.write_text("".join(f"2011-09-26 13:02:{v:012.9f}\n" for v in values))

    stamps(root / "velodyne_points" / "timestamps_start.txt", [10.0, 10.1, 10.2])
    stamps(root / "velodyne_points" / "timestamps_end.txt", [10.1, 10.2, 10.3])
    stamps(root / "image_02" / "timestamps.txt", [10.05, 10.125, 10.2])
    pairs, _, _ = spec.gather(PreprocessConfig())
    np.testing.assert_allclose([p.image_fraction for p in pairs], [0.5, 0.25, 0.0], atol=1e-6)

    (root / "image_02" / "data" / "0000000001.png").unlink()
    with pytest.raises(InputError, match=r"0000000001\.bin: scan without an image"):
        spec.gather(PreprocessConfig())


@pytest.mark.parametrize(
    "layout, message",
    [
        ({}, "no frame in the folder"),
        ({"a": ["scan.pcd"]}, "a: frame has a point cloud but no image"),
        ({"a": ["image.png"]}, "a: frame has an image but no point cloud"),
        ({"a": ["scan.pcd", "more.pcd", "image.png"]}, "a: frame holds 2 point clouds"),
    ],
)
def test_bad_frame_folders_are_one_line_errors(tmp_path, sequence, capsys, layout, message):
    scans, times, _ = sequence
    root = tmp_path / "frames"
    root.mkdir()
    for folder, files in layout.items():
        (root / folder).mkdir()
        for name in files:
            if name.endswith(".pcd"):
                _write_scan(root / folder / name, scans[0], times[0])
            else:
                write_png(root / folder / name, _image(0))
    status = main(["preprocess", "--frames", str(root), str(tmp_path / "w"), *CAMERA])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1 and message in err, err


# ---------------------------------------------------------------------------------------------
# A scan sequence and several images


@pytest.fixture(scope="module")
def sequence_files(tmp_path_factory, sequence):
    root = tmp_path_factory.mktemp("sequence")
    scans, times, _ = sequence
    clouds, images = [], []
    for k in range(N_SCANS):
        clouds.append(root / f"scan_{k}.pcd")
        _write_scan(clouds[-1], scans[k], times[k])
    for k in range(3):
        images.append(root / f"cam_{k}.png")
        write_png(images[-1], _image(k))
    return clouds, images


def test_several_images_one_pair_each(sequence_files, tmp_path):
    clouds, images = sequence_files
    work = tmp_path / "work"
    argv = ["-q", "preprocess", *map(str, clouds), "--images", *map(str, images), str(work)]
    assert main([*argv, *CAMERA, "--every", "2"]) == 0  # WORKDIR after the --images list
    assert WorkDir(work).names() == ["cam_0", "cam_2"]

    # placed by their times on the scans' clock (a scan was dropped at 10.2 s: the image at
    # 10.25 s was taken after scan 1 ended, and is placed at its end)
    spec = InputSpec(
        points=tuple(map(str, clouds)),
        images=tuple(map(str, images)),
        image_times="10.03,10.25,10.499",
        scan_times="10.0,10.1,10.3,10.4",
        **SPEC_CAMERA,
    )
    pairs, _, _ = spec.gather(PreprocessConfig())
    assert [(p.name, p.info["image_scan"]) for p in pairs] == [("cam_0", 0), ("cam_1", 1),
                                                                ("cam_2", 3)]  # fmt: skip
    sweep = 599 * SCAN_PERIOD / 600  # the span of the scans' point times
    np.testing.assert_allclose(
        [p.image_fraction for p in pairs], [0.03 / sweep, 1.0, 0.099 / sweep], atol=1e-5
    )
    # the default clock: scan k begins at k / frame_rate
    pairs, _, _ = InputSpec(
        points=tuple(map(str, clouds)), images=(str(images[0]),), image_times="0.35", **SPEC_CAMERA
    ).gather(PreprocessConfig())
    assert pairs[0].info["image_scan"] == 3


@pytest.mark.parametrize(
    "extra, message",
    [
        ({"image_times": "1,2"}, r"inputs\.image_times gives 2 times for 3 images"),
        (
            {"scan_times": "1,2", "image_times": "1,2,3"},
            r"inputs\.scan_times gives 2 times for 4 scans",
        ),
        ({"pair_count": 5}, r"inputs\.pair_count 5 asks more pairs than the 3 images"),
    ],
)
def test_image_sequence_errors(sequence_files, extra, message):
    clouds, images = sequence_files
    spec = InputSpec(points=tuple(map(str, clouds)), images=tuple(map(str, images)), **extra)
    with pytest.raises(InputError, match=message):
        spec.gather(PreprocessConfig())


def test_more_images_than_scans_need_times(sequence_files):
    clouds, images = sequence_files
    spec = InputSpec(points=tuple(map(str, clouds[:2])), images=tuple(map(str, images)))
    with pytest.raises(InputError, match="3 images but 2 scans"):
        spec.gather(PreprocessConfig())


def test_recording_options_need_a_recording(plain_pair, capsys, tmp_path):
    cloud, image = plain_pair
    base = ["preprocess", str(cloud), str(image), str(tmp_path / "w"), *CAMERA]
    for extra, message in (
        (["--neighbors", "3"], "neighbors=3: plain files with one image makes one pair"),
        (["--every", "2"], "are for several images"),
        (["--scan-times", "0"], "are for several images"),
        (["--every", "0"], "expected a whole number >= 1"),
        (["--image-scan-fraction", "1.5"], "image_scan_fraction must be in [0, 1]"),
    ):
        try:
            status = main([*base, *extra])
        except SystemExit as exc:  # argparse refuses the value itself
            status = exc.code
        err = capsys.readouterr().err
        assert status == 2
        assert message in err and err.count("\n") == 1, err


@pytest.fixture
def plain_pair(tmp_path, sequence):
    scans, times, _ = sequence
    cloud = tmp_path / "scan.pcd"
    _write_scan(cloud, scans[0], times[0])
    image = tmp_path / "image.png"
    write_png(image, _image(0))
    return cloud, image


# ---------------------------------------------------------------------------------------------
# Bags


@pytest.fixture(scope="module")
def bag(tmp_path_factory, sequence):
    """A ROS 1 bag: 4 scans at 10 Hz, and 4 images each taken in the middle of a scan."""
    pytest.importorskip("rosbags")
    from nbcalib.camera import create_camera
    from nbcalib.io.bag_writer import BagWriter
    from nbcalib.synthetic.writer import BASE_STAMP_NS

    path = tmp_path_factory.mktemp("bag") / "drive.bag"
    scans, times, _ = sequence
    camera = create_camera("pinhole", [300, 300, 159.5, 119.5], [], 320, 240)
    with BagWriter(path, "bag1") as writer:
        writer.write_camera_info("/camera_info", BASE_STAMP_NS, camera, "camera")
        for k in range(N_SCANS):
            stamp = BASE_STAMP_NS + round(k * SCAN_PERIOD * 1e9)
            writer.write_image("/image", stamp + 50_000_000, _image(k), "camera")
            fields = {n: scans[k][:, i].astype(np.float32) for i, n in enumerate("xyz")}
            fields["intensity"] = (200 * scans[k][:, 3]).astype(np.float32)
            fields["t"] = times[k].astype(np.float32)
            writer.write_pointcloud("/points", stamp, fields, "lidar")
    return path


def test_a_bag_makes_one_pair_per_chosen_image(bag, tmp_path):
    from nbcalib.synthetic.writer import BASE_STAMP_NS

    work = tmp_path / "work"
    assert main(["-q", "preprocess", str(bag), str(work), "--every", "2"]) == 0
    assert WorkDir(work).names() == ["drive_000000", "drive_000002"]
    calib = json.loads((work / "calib.json").read_text())
    pairs = calib["nbcalib"]["preprocess"]["pairs"]
    sweep = 599 * SCAN_PERIOD / 600
    assert pairs["drive_000002"]["image_scan"] == 2
    assert pairs["drive_000002"]["image_fraction"] == pytest.approx(0.05 / sweep, abs=1e-6)
    assert pairs["drive_000002"]["image_time"] == pytest.approx(0.25)
    assert calib["meta"]["image_topic"] == "/image"

    spec = InputSpec(inputs=(str(bag),), pair_count=2)
    assert [p.name for p in spec.gather(PreprocessConfig())[0]] == ["drive_000000", "drive_000003"]
    stamp = BASE_STAMP_NS / 1e9 + 0.16  # nearest image: the one at 0.15 s
    pairs, camera, _ = InputSpec(inputs=(str(bag),), image_times=str(stamp)).gather(
        PreprocessConfig(neighbors=3)
    )
    assert [p.name for p in pairs] == ["drive_000001"] and camera.width == 320
    assert pairs[0].info["first_scan"] == 0 and len(pairs[0].scans) == 3
    with pytest.raises(InputError, match=r"no image within 0\.100 s of 5\.000000"):
        InputSpec(inputs=(str(bag),), image_times="5").gather(PreprocessConfig())


def test_a_bag_without_selection_is_one_pair_of_all_its_scans(bag):
    pairs, _, _ = InputSpec(inputs=(str(bag),)).gather(PreprocessConfig())
    assert [p.name for p in pairs] == ["drive.bag"] and len(pairs[0].scans) == N_SCANS
    assert pairs[0].image_scan is None  # the cloud stays in the first scan's frame
    with pytest.raises(InputError, match=r"a bag without inputs\.every"):
        InputSpec(inputs=(str(bag),)).gather(PreprocessConfig(neighbors=2))


# ---------------------------------------------------------------------------------------------
# Records of earlier jobs


def test_a_job_recorded_before_the_recording_options_is_kept(plain_pair, tmp_path):
    """Inputs and settings added later, at their defaults, do not redo a recorded stage."""
    from nbcalib.config import CalibrationConfig
    from nbcalib.io.calib_json import write_calib_json
    from nbcalib.pipeline import Calibrator
    from nbcalib.resume import plan_stages

    cloud, image = plain_pair
    work = tmp_path / "work"
    assert main(["-q", "preprocess", str(cloud), str(image), str(work), *CAMERA]) == 0
    wd = WorkDir(work)
    calib = wd.read_calib()
    recorded = calib.to_dict()["nbcalib"]["made"]["preprocess"]
    assert "frames" not in recorded["inputs"]
    for key in ("neighbors", "image_scan_fraction"):  # as an older version recorded it
        del recorded["preprocess"][key]
    write_calib_json(wd.calib_path, calib)
    spec = InputSpec(inputs=(str(cloud), str(image)), **SPEC_CAMERA)

    def plan(config):
        calibrator = Calibrator(config, workdir=work)
        calibrator._inputs = spec
        return plan_stages(calibrator)[0]

    assert plan(CalibrationConfig()) == ("preprocess", False, "done")
    changed = plan(CalibrationConfig(preprocess=PreprocessConfig(image_scan_fraction=0.0)))
    assert changed == ("preprocess", True, "settings changed: preprocess.image_scan_fraction")


# ---------------------------------------------------------------------------------------------
# Real data


@pytest.fixture
def kitti_frames(real_data, tmp_path):
    """A folder of the first 3 KITTI frames (links), with the calib/ folder beside them."""
    kitti = real_data / "kitti_raw_2011_09_26"
    root = tmp_path / "kitti"
    root.mkdir()
    for k in range(3):
        (root / f"{k:010d}").symlink_to(kitti / f"{k:010d}")
    (root / "calib").symlink_to(kitti / "calib")
    return root, str(kitti / "calib" / "calib_normalized_cam2rect.json")


def test_real_kitti_frames_neighbours_and_the_image_time(kitti_frames):
    from nbcalib.odometry import integrate_dynamic

    root, camera = kitti_frames
    config = PreprocessConfig(voxel_size=0.05)
    pairs, cam, _ = InputSpec(frames=str(root), camera=camera).gather(config)
    assert [p.name for p in pairs] == ["0000000000", "0000000001", "0000000002"]
    assert cam.width == 1242 and all(len(p.scans) == 1 for p in pairs)

    dense_config = PreprocessConfig(voxel_size=0.05, neighbors=3)
    pairs3, _, _ = InputSpec(frames=str(root), camera=camera, pair_count=1).gather(dense_config)
    dense = prepare_pair(pairs3[0], dense_config)
    single = prepare_pair(pairs[0], config)
    assert len(dense.points_lidar) > 1.5 * len(single.points_lidar)
    cloud = integrate_dynamic(pairs3[0].scans, voxel_size=0.05)
    T_first_image = cloud.pose_at(0, 0.5)
    T_image_first = invert_T(T_first_image)
    expected = cloud.points @ T_image_first[:3, :3].T + T_image_first[:3, 3]
    np.testing.assert_allclose(dense.points_lidar, expected, atol=1e-4)
    # the car drives forward at about 2.2 m/s: half a sweep is about 11 cm ahead
    assert 0.05 < dense.summary["image_frame_offset_m"] < 0.2
    assert T_first_image[0, 3] > 0.05
