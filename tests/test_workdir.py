"""Work directory: index-map PNG encoding, full round trip, crash safety, bad files."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from nbcalib.camera import create_camera
from nbcalib.errors import InputError
from nbcalib.io.index_map import (
    decode_index_map,
    encode_index_map,
    read_index_map,
    write_index_map,
)
from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
from nbcalib.preprocess.lidar_image import make_virtual_camera, render_lidar_image
from nbcalib.products import PairData, VirtualCamera
from nbcalib.workdir import (
    PLAIN_FILES_NAME,
    WorkDir,
    get_virtual_camera,
    make_calib,
    set_virtual_camera,
)

INT32_MAX = np.iinfo(np.int32).max

JIT_OFF = os.environ.get("NUMBA_DISABLE_JIT") == "1"  # coverage runs: kernels in Python


def _index_map(rng):
    index = rng.integers(-1, 2**31 - 1, size=(7, 9), dtype=np.int64).astype(np.int32)
    index[0, :4] = [-1, 0, 2**24 + 1, INT32_MAX]
    index[1, :3] = [255, 256, 65536 * 255 + 7]
    return index


def test_index_map_encoding_is_the_raw_little_endian_bytes(rng):
    index = _index_map(rng)
    encoded = encode_index_map(index)
    assert encoded.shape == (7, 9, 4) and encoded.dtype == np.uint8
    assert np.array_equal(encoded[0, 0], [255, 255, 255, 255])  # -1: all bytes 0xFF
    assert np.array_equal(encoded[1, 1], [0, 1, 0, 0])  # 256
    assert np.array_equal(encoded[0, 2], [1, 0, 0, 1])  # 2**24 + 1
    assert np.array_equal(decode_index_map(encoded), index)
    with pytest.raises(ValueError):
        encode_index_map(np.array([[-2]]))
    with pytest.raises(ValueError):
        encode_index_map(np.array([[2**31]]))


def test_index_map_file_decodes_as_the_spec_says(rng, tmp_path):
    import cv2

    index = _index_map(rng)
    path = tmp_path / "x_lidar_indices.png"
    write_index_map(path, index)
    # reference_toolbox.md section 1.1: the decoding recipe for Python
    decoded = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).view("<i4")[..., 0]
    assert np.array_equal(decoded, index)
    assert np.array_equal(read_index_map(path), index)
    PIL = pytest.importorskip("PIL.Image")
    rgba = np.asarray(PIL.open(path))  # PNG channel order: R, G, B, A = bytes 2, 1, 0, 3
    raw = index.astype("<i4").view(np.uint8).reshape(7, 9, 4)
    assert np.array_equal(rgba, raw[..., [2, 1, 0, 3]])


def test_read_index_map_rejects_other_images(tmp_path):
    import cv2

    grey = tmp_path / "grey.png"
    cv2.imwrite(str(grey), np.zeros((4, 4), np.uint8))
    with pytest.raises(InputError, match="4-channel"):
        read_index_map(grey)
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(InputError, match=r"broken\.png"):
        read_index_map(broken)
    with pytest.raises(InputError, match="not found"):
        read_index_map(tmp_path / "missing.png")
    bad = tmp_path / "bad.png"
    cv2.imwrite(str(bad), encode_index_map(np.array([[-1, 5]])).copy())
    raw = cv2.imread(str(bad), cv2.IMREAD_UNCHANGED)
    raw[0, 1] = [0, 0, 0, 0x80]  # int32 min
    cv2.imwrite(str(bad), raw)
    with pytest.raises(InputError, match="< -1"):
        read_index_map(bad)


def _scene(rng, n=5000):
    points = rng.normal(size=(n, 3)) * [20.0, 20.0, 2.0]
    intensities = equalize_point_intensities(rng.integers(0, 100, n))
    return points, intensities


def _write_job(workdir: WorkDir, rng, names):
    camera = create_camera("plumb_bob", [400, 401, 319.5, 239.5], [-0.1, 0.02, 0, 0, 0], 640, 480)
    vcam, T_vcam_lidar = make_virtual_camera(math.radians(120.0), pinhole_size=128)
    workdir.prepare()
    written = {}
    for name in names:
        points, intensities = _scene(rng)
        image = equalize_image(rng.integers(0, 120, size=(480, 640), dtype=np.uint8))
        lidar_image = render_lidar_image(vcam, T_vcam_lidar, points, intensities)
        workdir.write_pair(PairData(name, image, points, intensities, lidar_image))
        written[name] = (image, points, intensities, lidar_image)
    calib = make_calib(camera, list(names), data_path="/data/in")
    set_virtual_camera(calib, VirtualCamera(vcam, T_vcam_lidar))
    calib.set_T_camera_lidar("init_T_lidar_camera_auto", T_vcam_lidar)
    workdir.write_calib(calib)
    return camera, vcam, T_vcam_lidar, written


def test_work_directory_round_trip(rng, tmp_path):
    workdir = WorkDir(tmp_path / "job")
    names = ["rosbag2_2023_03_09-13_42_46", "second.bag"]
    camera, vcam, T_vcam_lidar, written = _write_job(workdir, rng, names)
    assert sorted(p.name for p in workdir.path.iterdir()) == sorted(
        ["calib.json"] + [p.name for n in names for p in workdir.product_paths(n)]
    )  # nothing else, no temporary files left
    assert workdir.is_complete()
    assert workdir.names() == names
    calib = workdir.read_calib()
    assert calib.camera_model() == camera
    assert calib.meta["bag_names"] == names and calib.meta["image_topic"] == "N/A"
    got = get_virtual_camera(calib)
    assert got.camera == vcam and np.array_equal(got.T_vcam_lidar, T_vcam_lidar)
    for name in names:
        image, points, intensities, lidar_image = written[name]
        pair = workdir.load_pair(name)
        assert pair.name == name
        assert np.array_equal(pair.image, image)
        assert np.array_equal(pair.points_lidar, points.astype(np.float32))
        assert np.array_equal(pair.intensities, intensities.astype(np.float32))
        assert np.array_equal(pair.lidar_image.intensity, lidar_image.intensity)
        assert np.array_equal(pair.lidar_index, lidar_image.index)
        # the index map points at the .ply vertices that were rendered
        filled = pair.lidar_index >= 0
        assert filled.sum() > 100
        expected = np.rint(255 * pair.intensities[pair.lidar_index[filled]])
        assert np.array_equal(pair.lidar_image.intensity[filled], expected.astype(np.uint8))


def test_names_without_calib_come_from_the_clouds(rng, tmp_path):
    workdir = WorkDir(tmp_path)
    workdir.prepare()
    points, intensities = _scene(rng, 50)
    vcam, T = make_virtual_camera(1.0, pinhole_size=32)
    for name in ["b", PLAIN_FILES_NAME]:
        workdir.write_pair(
            PairData(
                name,
                np.zeros((4, 4), np.uint8),
                points,
                intensities,
                render_lidar_image(vcam, T, points, intensities),
            )
        )
    assert workdir.names() == [PLAIN_FILES_NAME, "b"]
    assert not workdir.is_complete()  # no calib.json yet


def test_an_interrupted_run_does_not_look_complete(rng, tmp_path):
    workdir = WorkDir(tmp_path / "job")
    _write_job(workdir, rng, ["a"])
    assert workdir.is_complete()
    # a new run starts: the old calib.json goes first, so a crash now leaves no complete dir
    workdir.prepare()
    assert not workdir.calib_path.exists() and not workdir.is_complete()
    with pytest.raises(InputError, match=r"calib\.json"):
        workdir.read_calib()
    # calib.json is refused while products are missing
    camera = create_camera("pinhole", [100, 100, 63.5, 47.5], [], 128, 96)
    with pytest.raises(ValueError, match="missing"):
        workdir.write_calib(make_calib(camera, ["a", "never_written"]))
    assert not workdir.calib_path.exists()


def test_write_pair_removes_stale_matches_and_checks_inputs(rng, tmp_path):
    workdir = WorkDir(tmp_path)
    workdir.prepare()
    points, intensities = _scene(rng, 100)
    vcam, T = make_virtual_camera(1.0, pinhole_size=32)
    lidar_image = render_lidar_image(vcam, T, points, intensities)
    for path in workdir.match_paths("a"):
        path.write_text("{}")
    workdir.write_pair(PairData("a", np.zeros((4, 4), np.uint8), points, intensities, lidar_image))
    assert not any(path.exists() for path in workdir.match_paths("a"))
    with pytest.raises(ValueError, match="refers to point"):
        workdir.write_pair(
            PairData("a", np.zeros((4, 4), np.uint8), points[:10], intensities[:10], lidar_image)
        )
    with pytest.raises(ValueError, match="uint8"):
        workdir.write_pair(
            PairData("a", np.zeros((4, 4), np.uint16), points, intensities, lidar_image)
        )
    with pytest.raises(ValueError, match="plain file name"):
        workdir.write_pair(
            PairData("../x", np.zeros((4, 4), np.uint8), points, intensities, lidar_image)
        )


def test_load_pair_reports_inconsistent_files(rng, tmp_path):
    from nbcalib.io.ply import write_ply

    workdir = WorkDir(tmp_path / "job")
    _write_job(workdir, rng, ["a"])
    points = workdir.load_pair("a").points_lidar
    write_ply(workdir.cloud_path("a"), points[:10], np.zeros(10))  # a truncated cloud
    with pytest.raises(InputError, match=r"a_lidar_indices\.png.*refers to point"):
        workdir.load_pair("a")
    write_ply(workdir.cloud_path("a"), points)  # no intensity
    with pytest.raises(InputError, match=r"a\.ply.*intensity"):
        workdir.load_pair("a")
    workdir.image_path("a").unlink()
    with pytest.raises(InputError, match=r"a\.png.*not found"):
        workdir.load_pair("a")
    assert not workdir.is_complete()


@pytest.mark.realdata
@pytest.mark.skipif(JIT_OFF, reason="120 000 points through the z-buffer in pure Python")
def test_kitti_scan_to_a_work_directory(real_data, tmp_path):
    """One real KITTI scan through the automatic virtual camera into a work directory."""
    from nbcalib.io.image import read_image
    from nbcalib.preprocess.lidar_image import estimate_lidar_fov

    frame = real_data / "kitti_raw_2011_09_26" / "0000000000"
    scan = np.fromfile(frame / "velodyne.bin", dtype=np.float32).reshape(-1, 4)
    points = scan[:, :3].astype(np.float64)
    intensities = equalize_point_intensities(scan[:, 3])
    vcam, T_vcam_lidar = make_virtual_camera(estimate_lidar_fov(points))
    assert vcam.model == "equirectangular"
    images = sorted(frame.glob("*.png"))
    image = equalize_image(read_image(images[0])) if images else np.zeros((375, 1242), np.uint8)
    workdir = WorkDir(tmp_path / "kitti")
    workdir.prepare()
    lidar_image = render_lidar_image(vcam, T_vcam_lidar, points, intensities)
    workdir.write_pair(PairData(PLAIN_FILES_NAME, image, points, intensities, lidar_image))
    camera = create_camera("pinhole", [721.5, 721.5, 609.6, 172.9], [], *image.shape[::-1])
    calib = make_calib(camera, [PLAIN_FILES_NAME], data_path=str(frame))
    set_virtual_camera(calib, VirtualCamera(vcam, T_vcam_lidar))
    workdir.write_calib(calib)
    pair = workdir.load_pair(PLAIN_FILES_NAME)
    assert np.array_equal(pair.lidar_index, lidar_image.index)
    assert len(pair.points_lidar) == len(points)
