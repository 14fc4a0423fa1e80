"""Kalibr camchain YAML -> nbcalib cameras and camera-to-camera extrinsics (nbcalib.io.rig)."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.rig import read_kalibr_camchain
from nbcalib.transforms import invert_T, se3_exp

T10 = se3_exp([0.10, -0.02, 0.01, 0.02, 1.2, -0.01])  # cam1 ~70 deg to the side of cam0
T21 = se3_exp([0.12, 0.01, -0.03, -0.01, 1.3, 0.02])


def _matrix(T) -> str:
    return "\n".join(f"  - [{', '.join(repr(float(x)) for x in row)}]" for row in T)


CAMCHAIN = f"""\
cam0:
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28, 0.07, 0.0002, -0.0001]
  distortion_model: radtan
  intrinsics: [461.6, 460.3, 366.2, 248.3]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cn_cnm1:
{_matrix(T10)}
  camera_model: pinhole
  distortion_coeffs: [0.01, -0.002, 0.0005, -0.0001]
  distortion_model: equidistant
  intrinsics: [380.0, 381.0, 640.0, 512.0]
  resolution: [1280, 1024]
  rostopic: /cam1/image_raw
cam2:
  T_cn_cnm1:
{_matrix(T21)}
  camera_model: omni
  distortion_coeffs: [-0.1, 0.02, 0.001, 0.0]
  distortion_model: radtan
  intrinsics: [0.9, 700.0, 701.0, 640.0, 480.0]
  resolution: [1280, 960]
"""


def _write(tmp_path, text, name="camchain.yaml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_cameras_models_and_the_chain(tmp_path):
    rig = read_kalibr_camchain(_write(tmp_path, CAMCHAIN))
    assert rig.names() == ["cam0", "cam1", "cam2"]
    c0, c1, c2 = (c.camera for c in rig.cameras)
    assert c0.model == "plumb_bob" and (c0.width, c0.height) == (752, 480)
    np.testing.assert_array_equal(c0.intrinsics, [461.6, 460.3, 366.2, 248.3])
    np.testing.assert_array_equal(c0.distortion_coeffs, [-0.28, 0.07, 0.0002, -0.0001, 0.0])
    assert c1.model == "fisheye"
    np.testing.assert_array_equal(c1.distortion_coeffs, [0.01, -0.002, 0.0005, -0.0001])
    # omni: Kalibr's [xi, fu, fv, pu, pv] is nbcalib's omnidir [fx, fy, cx, cy, xi]
    assert c2.model == "omnidir"
    np.testing.assert_array_equal(c2.intrinsics, [700.0, 701.0, 640.0, 480.0, 0.9])
    assert rig.cameras[0].topic == "/cam0/image_raw" and rig.cameras[2].topic is None
    np.testing.assert_array_equal(rig.cameras[0].T_cam_cam0, np.eye(4))
    np.testing.assert_allclose(rig.cameras[1].T_cam_cam0, T10, atol=1e-12)
    np.testing.assert_allclose(rig.cameras[2].T_cam_cam0, T21 @ T10, atol=1e-12)
    # T_a_b maps b's points into a's
    np.testing.assert_allclose(rig.T("cam2", "cam1"), T21, atol=1e-12)
    np.testing.assert_allclose(rig.T("cam0", "cam2"), invert_T(T21 @ T10), atol=1e-12)
    with pytest.raises(KeyError, match="cam7"):
        rig.T("cam7", "cam0")


def test_pinhole_without_distortion_and_the_fov_model(tmp_path):
    text = """\
cam0: {camera_model: pinhole, distortion_model: none, distortion_coeffs: [0, 0, 0, 0],
       intrinsics: [500, 500, 320, 240], resolution: [640, 480]}
cam1:
  T_cn_cnm1: [[1, 0, 0, 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
  camera_model: pinhole
  distortion_model: fov
  distortion_coeffs: [0.9]
  intrinsics: [400, 400, 320, 240]
  resolution: [640, 480]
"""
    rig = read_kalibr_camchain(_write(tmp_path, text))
    assert [c.camera.model for c in rig.cameras] == ["pinhole", "atan"]
    np.testing.assert_array_equal(rig.cameras[1].camera.distortion_coeffs, [0.9])
    np.testing.assert_allclose(rig.cameras[1].T_cam_cam0[:3, 3], [0.1, 0, 0])


def _one(tmp_path, **changes):
    entry = {
        "camera_model": "pinhole",
        "distortion_model": "radtan",
        "distortion_coeffs": "[0.1, 0.01, 0, 0]",
        "intrinsics": "[500, 500, 320, 240]",
        "resolution": "[640, 480]",
    }
    entry.update(changes)
    lines = [f"  {k}: {v}" for k, v in entry.items() if v is not None]
    return _write(tmp_path, "cam0:\n" + "\n".join(lines) + "\n")


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"camera_model": "ds"}, "camera_model 'ds' is not supported"),
        ({"distortion_model": "radtan8"}, "distortion_model 'radtan8' is not supported"),
        ({"intrinsics": "[500, 500, 320]"}, "takes 4 intrinsics"),
        ({"distortion_coeffs": "[0.1, 0.01]"}, "takes 4 distortion_coeffs, got 2"),
        ({"intrinsics": "[500, .nan, 320, 240]"}, "non-finite"),
        ({"resolution": "[640.5, 480]"}, "resolution must be two positive whole numbers"),
        ({"resolution": None}, "has no resolution"),
        ({"camera_model": "omni", "intrinsics": "[500, 500, 320, 240]"}, "takes 5 intrinsics"),
        ({"intrinsics": "[-500, 500, 320, 240]"}, "cam0: "),
    ],
)
def test_a_bad_camera_is_a_one_line_error_naming_the_file(tmp_path, changes, message):
    path = _one(tmp_path, **changes)
    with pytest.raises(InputError, match=message) as info:
        read_kalibr_camchain(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_bad_files_and_chains(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_kalibr_camchain(tmp_path / "missing.yaml")
    with pytest.raises(InputError, match="is a directory"):
        read_kalibr_camchain(tmp_path)
    with pytest.raises(InputError, match="invalid YAML"):
        read_kalibr_camchain(_write(tmp_path, "cam0: [unclosed\n"))
    with pytest.raises(InputError, match="no cam0"):
        read_kalibr_camchain(_write(tmp_path, "image_width: 640\n"))
    with pytest.raises(InputError, match="expected a mapping"):
        read_kalibr_camchain(_write(tmp_path, "- 1\n- 2\n"))
    cam = "{camera_model: pinhole, intrinsics: [500, 500, 320, 240], resolution: [640, 480]}"
    with pytest.raises(InputError, match="without gaps"):
        read_kalibr_camchain(_write(tmp_path, f"cam0: {cam}\ncam2: {cam}\n"))
    with pytest.raises(InputError, match="cam1 has no T_cn_cnm1"):
        read_kalibr_camchain(_write(tmp_path, f"cam0: {cam}\ncam1: {cam}\n"))
    bad_transforms = [
        ("[[1, 0.2, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", "not a rotation"),  # skew
        ("[[-1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]", "not a rotation"),  # mirror
        ("[[1, 0, 0], [0, 1, 0], [0, 0, 1]]", "must have 16 numbers"),
        ("[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]", "last row"),
    ]
    for T, message in bad_transforms:
        cam1 = cam[:-1] + f", T_cn_cnm1: {T}}}"
        with pytest.raises(InputError, match=message):
            read_kalibr_camchain(_write(tmp_path, f"cam0: {cam}\ncam1: {cam1}\n"))


def test_nbcalib_rig_round_trip_and_either_format_recognised(tmp_path):
    from nbcalib.io.rig import read_rig, save_rig

    kalibr = read_rig(_write(tmp_path, CAMCHAIN))  # a camchain, recognised by its content
    assert kalibr.names() == ["cam0", "cam1", "cam2"]
    for name in ("rig.yaml", "rig.json"):
        save_rig(tmp_path / name, kalibr)
        again = read_rig(tmp_path / name)
        assert again.names() == kalibr.names()
        for a, b in zip(kalibr.cameras, again.cameras):
            assert a.camera.to_dict() == b.camera.to_dict() and a.topic == b.topic
            np.testing.assert_allclose(b.T_cam_cam0, a.T_cam_cam0, atol=1e-12)
    # a rig frame other than the first camera's: the camera-to-camera transforms are the same
    T_rig_cam0 = se3_exp([1.0, 2.0, 0.5, 0.3, -0.2, 0.1])
    text = (tmp_path / "rig.yaml").read_text()
    import yaml

    from nbcalib.transforms import pose_to_xyz_quat

    data = yaml.safe_load(text)
    for entry, cam in zip(data["cameras"], kalibr.cameras):
        T_rig_cam = T_rig_cam0 @ invert_T(cam.T_cam_cam0)
        entry["T_rig_camera"] = [float(x) for x in pose_to_xyz_quat(T_rig_cam)]
    moved = read_rig(_write(tmp_path, yaml.safe_dump(data), "moved.yaml"))
    np.testing.assert_allclose(moved.T("cam2", "cam1"), T21, atol=1e-9)
    np.testing.assert_allclose(moved.cameras[0].T_cam_cam0, np.eye(4), atol=1e-9)


def test_bad_nbcalib_rigs(tmp_path):
    from nbcalib.io.rig import read_rig

    cam = (
        "{name: front, camera_model: pinhole, intrinsics: [500, 500, 320, 240], width: 640, "
        "height: 480, T_rig_camera: [0, 0, 0, 0, 0, 0, 1]}"
    )
    cases = [
        ("cameras: []\n", "non-empty list"),
        (f"cameras: [{cam}, {cam}]\n", "'front' used twice"),
        ("cameras: [{name: a, camera_model: pinhole}]\n", r"cameras\[0\] has no intrinsics"),
        (f"cameras: [{cam.replace('0, 0, 0, 1]', '0, 0, 0, 0]')}]\n", "zero quaternion"),
        (f"cameras: [{cam.replace('0, 0, 1]', '1]')}]\n", "must have 7 numbers"),
        (f"cameras: [{cam.replace('320, 240]', '320]')}]\n", r"cameras\[0\] \(front\): .*takes 4"),
        ("width: 640\n", "not a rig file"),
    ]
    for k, (text, message) in enumerate(cases):
        path = _write(tmp_path, text, f"bad{k}.yaml")
        with pytest.raises(InputError, match=message) as info:
            read_rig(path)
        assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)
    with pytest.raises(InputError, match="not found"):
        read_rig(tmp_path / "none.yaml")
