"""Data manifests: every shipped file passes the schema, and `nbcalib data` checks a fake copy.

Nothing downloads here: verification runs against a temporary directory made from a tiny test
manifest.
"""

from __future__ import annotations

import copy
import hashlib
import json
import shlex

import numpy as np
import pytest
import yaml
from numpy.testing import assert_allclose

from nbcalib.cli import build_parser, main
from nbcalib.data import (
    find_manifest,
    list_manifests,
    load_manifest,
    manifest_dir,
    manifest_paths,
    sha256_file,
    validate_manifest,
    verify_dataset,
)
from nbcalib.errors import InputError
from nbcalib.transforms import invert_T, pose_from_xyz_quat, rotation_angle_deg

SHIPPED = manifest_paths()
REQUIRED = {
    "dvlc_livox",
    "dvlc_ouster",
    "dvlc_faro_map",
    "kitti_raw_2011_09_26",
    "opencalib_auto_calib",
    "opencalib_manual_calib",
}


# ---------------------------------------------------------------------- shipped manifests
def test_the_expected_datasets_are_shipped():
    assert manifest_dir().name == "data_manifests"
    assert REQUIRED <= {path.stem for path in SHIPPED}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_manifest_passes_the_schema(path):
    manifest = load_manifest(path)
    assert manifest.name == path.stem
    assert manifest.files and all(not f.path.startswith("/") for f in manifest.files)


def _shipped_with(predicate):
    return [path for path in SHIPPED if predicate(load_manifest(path).data)]


#: manifests whose camera states its image size (the others leave it to the images)
SIZED_CAMERAS = _shipped_with(lambda d: (d["camera"] or {}).get("width") is not None)
#: manifests that ship a reference extrinsic
EXTRINSICS = _shipped_with(lambda d: d["reference_extrinsic"] is not None)


def test_the_expected_manifests_state_a_camera_and_an_extrinsic():
    """The two checks below run on these manifests at least (never on an empty list)."""
    sized = {"kitti_raw_2011_09_26", "opencalib_auto_calib", "opencalib_manual_calib"}
    assert {path.stem for path in SIZED_CAMERAS} >= sized
    assert {path.stem for path in EXTRINSICS} >= sized | {"dvlc_livox"}


@pytest.mark.parametrize("path", SIZED_CAMERAS, ids=lambda p: p.stem)
def test_shipped_camera_builds(path):
    from nbcalib.camera import create_camera

    camera = load_manifest(path).data["camera"]
    cam = create_camera(
        camera["camera_model"],
        camera["intrinsics"],
        camera["distortion_coeffs"],
        camera["width"],
        camera["height"],
    )
    assert (cam.width, cam.height) == (camera["width"], camera["height"])
    uv, valid = cam.project([0.0, 0.0, 1.0])  # the optical axis meets the principal point
    assert valid and cam.in_image(uv)
    assert_allclose(uv, camera["intrinsics"][2:4], rtol=0, atol=1e-9)


@pytest.mark.parametrize("path", EXTRINSICS, ids=lambda p: p.stem)
def test_shipped_extrinsic_is_a_pose(path):
    T = pose_from_xyz_quat(load_manifest(path).data["reference_extrinsic"]["T_lidar_camera"])
    assert 0.0 < np.linalg.norm(T[:3, 3]) < 2.0  # a rig, metres


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_run_command_parses_with_the_run_parser(path, tmp_path):
    """The printed command is accepted by `nbcalib run`'s own argument parser."""
    command = load_manifest(path).run_command(tmp_path / "data", tmp_path / "work")
    words = shlex.split(command)
    assert words[:2] == ["nbcalib", "run"]
    args = build_parser().parse_args(words[1:])
    assert args.inputs[-1] == str(tmp_path / "work")
    assert getattr(args, "points", None) or len(args.inputs) >= 2  # --points, or bags + WORKDIR


def _real_T_camera_lidar(path):
    data = json.loads(path.read_text())
    return np.array(data["T_cam_lidar"]), np.array(data["K"])


@pytest.mark.parametrize(
    ("name", "calib"),
    [
        ("kitti_raw_2011_09_26", "kitti_raw_2011_09_26/calib/calib_normalized_cam2rect.json"),
        ("opencalib_auto_calib", "pjlab/auto_calib/calib_normalized.json"),
        ("opencalib_manual_calib", "pjlab/manual_calib_0/calib_normalized.json"),
    ],
)
def test_published_values_agree_with_the_real_data_folder(real_data, name, calib):
    """The manifests' extrinsics and K against the independently derived copies in shared data."""
    data = find_manifest(name).data
    T_camera_lidar, K = _real_T_camera_lidar(real_data / calib)
    T_lidar_camera = pose_from_xyz_quat(data["reference_extrinsic"]["T_lidar_camera"])
    T_expected = invert_T(_orthonormalised(T_camera_lidar))
    assert_allclose(T_lidar_camera[:3, 3], T_expected[:3, 3], rtol=0, atol=1e-6)
    assert rotation_angle_deg(T_lidar_camera[:3, :3] @ T_expected[:3, :3].T) < 1e-5
    fx, fy, cx, cy = data["camera"]["intrinsics"]
    assert_allclose([fx, fy, cx, cy], [K[0, 0], K[1, 1], K[0, 2], K[1, 2]], rtol=0, atol=1e-9)


def _orthonormalised(T):
    T = T.copy()
    U, _, Vt = np.linalg.svd(T[:3, :3])
    T[:3, :3] = U @ Vt
    return T


# ---------------------------------------------------------------------- schema check
def _tiny_manifest(name="tiny_set"):
    return {
        "schema": 1,
        "name": name,
        "title": "A tiny test dataset",
        "description": "Two small files made by the test.",
        "homepage": "https://example.org/tiny",
        "downloads": ["https://example.org/tiny/scan.bin"],
        "licence": {"name": "CC0-1.0", "url": None},
        "size": {"bytes": None, "text": "a few bytes"},
        "sensors": {
            "lidar": {"kind": "spinning", "model": None},
            "camera": {"model": None},
        },
        "topics": None,
        "camera": {
            "camera_model": "plumb_bob",
            "width": 640,
            "height": 480,
            "intrinsics": [500.0, 500.0, 319.5, 239.5],
            "distortion_coeffs": [-0.1, 0.01, 0.0, 0.0, 0.0],
            "source": "made up for the test",
        },
        "reference_extrinsic": {
            "T_lidar_camera": [0.1, 0.0, -0.05, -0.5, 0.5, -0.5, 0.5],
            "source": "made up for the test",
        },
        "files": [
            {"path": "scan.bin", "bytes": None, "sha256": None},
            {"path": "sub/image.png", "bytes": None, "sha256": None},
            {"path": "archive.tar.gz", "bytes": 5, "sha256": None, "extracts_to": "unpacked"},
            {"path": "extra.txt", "bytes": None, "sha256": None, "optional": True},
        ],
        "run": "nbcalib run --points {dir}/scan.bin --image {dir}/sub/image.png {workdir}",
        "sources": ["https://example.org/tiny"],
    }


def _mutations():
    def setter(*keys, value):
        def apply(data):
            target = data
            for key in keys[:-1]:
                target = target[key]
            target[keys[-1]] = value

        return apply

    def deleter(key):
        return lambda data: data.pop(key)

    return [
        (deleter("licence"), "missing licence"),
        (setter("typo_key", value=1), "unknown key"),
        (setter("schema", value=2), "schema"),
        (setter("name", value="Tiny Set"), "name"),
        (setter("homepage", value="ftp://x"), "homepage"),
        (setter("downloads", value=[]), "downloads"),
        (setter("sensors", "lidar", "kind", value="solid_state"), "sensors.lidar.kind"),
        (
            setter("topics", value={"points": "points", "image": None, "camera_info": None}),
            "topics.points",
        ),
        (setter("camera", "intrinsics", value=[500.0, 500.0, 319.5]), "camera.intrinsics"),
        (setter("camera", "distortion_coeffs", value=[0.1, 0.2]), "camera.distortion_coeffs"),
        (setter("camera", "camera_model", value="kb8"), "camera.camera_model"),
        (setter("camera", "width", value=None), "camera"),
        (
            setter("reference_extrinsic", "T_lidar_camera", value=[0, 0, 0, 0, 0, 0, 2]),
            "unit length",
        ),
        (setter("reference_extrinsic", "T_lidar_camera", value=[0, 0, 0, 1]), "7 numbers"),
        (setter("files", 0, "sha256", value="ABC"), "files[0].sha256"),
        (setter("files", 0, "bytes", value=-1), "files[0].bytes"),
        (setter("files", 0, "path", value="/etc/passwd"), "files[0].path"),
        (setter("files", 1, "path", value="../outside"), "files[1].path"),
        (setter("files", 1, "path", value="scan.bin"), "listed twice"),
        (setter("files", 3, "optional", value="yes"), "files[3].optional"),
        (setter("files", value=[]), "files"),
        (setter("run", value="nbcalib preprocess {dir} {workdir}"), "run"),
        (setter("run", value="nbcalib run scan.bin {workdir}"), "run"),
        (setter("licence", value={"name": None, "url": None}), "licence.note"),
    ]


def test_tiny_manifest_is_valid(tmp_path):
    data = _tiny_manifest()
    assert validate_manifest(copy.deepcopy(data), path="tiny_set.yaml") is None
    path = tmp_path / "tiny_set.yaml"
    path.write_text(yaml.safe_dump(data))
    manifest = load_manifest(path)
    assert manifest.name == "tiny_set" and manifest.data == data
    assert [(f.path, f.optional) for f in manifest.files] == [
        ("scan.bin", False),
        ("sub/image.png", False),
        ("archive.tar.gz", False),
        ("extra.txt", True),
    ]


@pytest.mark.parametrize(("mutate", "message"), _mutations(), ids=[m for _, m in _mutations()])
def test_schema_check_names_the_problem(mutate, message):
    data = copy.deepcopy(_tiny_manifest())
    mutate(data)
    with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]")):
        validate_manifest(data, path="tiny_set.yaml")


def test_name_must_match_file_name(tmp_path):
    path = tmp_path / "other_name.yaml"
    path.write_text(yaml.safe_dump(_tiny_manifest()))
    with pytest.raises(InputError, match="differs from the file name") as exc:
        load_manifest(path)
    assert str(path) in str(exc.value)


def test_invalid_yaml_is_an_input_error(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("name: [unclosed\n")
    with pytest.raises(InputError, match="invalid YAML"):
        load_manifest(path)


# ---------------------------------------------------------------------- verifying a copy
@pytest.fixture
def fake_dataset(tmp_path, rng):
    """(manifest path, data directory): a tiny manifest with known sizes and hashes."""
    data_dir = tmp_path / "download"
    (data_dir / "sub").mkdir(parents=True)
    (data_dir / "unpacked").mkdir()
    (data_dir / "scan.bin").write_bytes(rng.bytes(3_000_000))  # 3 chunks of the hasher
    (data_dir / "sub" / "image.png").write_bytes(b"\x89PNG not really")
    manifest = _tiny_manifest()
    for entry in manifest["files"][:2]:
        content = (data_dir / entry["path"]).read_bytes()
        entry["bytes"] = len(content)
        entry["sha256"] = hashlib.sha256(content).hexdigest()
    folder = tmp_path / "manifests"
    folder.mkdir()
    path = folder / "tiny_set.yaml"
    path.write_text(yaml.safe_dump(manifest, sort_keys=False))
    return path, data_dir


def test_verify_good_copy(fake_dataset):
    path, data_dir = fake_dataset
    calls = []
    checks = verify_dataset(load_manifest(path), data_dir, progress=lambda *a: calls.append(a))
    assert [c.status for c in checks] == ["ok", "ok", "extracted", "absent"]
    assert not any(c.failed for c in checks)
    assert "sha256 matches" in checks[0].detail
    # progress: per chunk, ending at the file size, for both hashed files
    scan_calls = [c for c in calls if c[2] == "scan.bin"]
    assert len(scan_calls) == 3 and scan_calls[-1][:2] == (3_000_000, 3_000_000)
    assert calls[-1][2] == "image.png"


def test_verify_detects_size_hash_and_missing(fake_dataset):
    path, data_dir = fake_dataset
    manifest = load_manifest(path)
    scan = data_dir / "scan.bin"
    content = bytearray(scan.read_bytes())
    content[1_234_567] ^= 0xFF  # same size, other hash
    scan.write_bytes(bytes(content))
    (data_dir / "sub" / "image.png").write_bytes(b"short")
    (data_dir / "unpacked").rmdir()
    checks = verify_dataset(manifest, data_dir)
    assert [c.status for c in checks] == ["hash_mismatch", "size_mismatch", "missing", "absent"]
    assert all(c.failed for c in checks[:3])
    # sizes only: the changed byte goes unnoticed, the wrong size does not
    checks = verify_dataset(manifest, data_dir, hashes=False)
    assert [c.status for c in checks[:2]] == ["ok", "size_mismatch"]
    with pytest.raises(InputError, match="dataset directory not found"):
        verify_dataset(manifest, data_dir / "nowhere")


def test_sha256_file_matches_hashlib(tmp_path, rng):
    path = tmp_path / "blob"
    data = rng.bytes(2_500_001)
    path.write_bytes(data)
    assert sha256_file(path) == hashlib.sha256(data).hexdigest()


# ---------------------------------------------------------------------- command line
def test_data_list_and_show(capsys, fake_dataset):
    assert main(["data", "list"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].split() == ["NAME", "SENSORS", "SIZE", "LICENCE"]
    assert all(name in out for name in REQUIRED)
    assert "CC-BY-NC-SA-3.0" in out

    path, _ = fake_dataset
    assert main(["data", "list", "--manifests", str(path.parent)]) == 0
    out = capsys.readouterr().out
    assert "tiny_set" in out and "CC0-1.0" in out and "kitti" not in out

    assert main(["data", "show", "kitti_raw_2011_09_26"]) == 0
    out = capsys.readouterr().out
    assert "Velodyne HDL-64E" in out and "721.5377" in out and "nbcalib run" in out
    assert main(["data", "show", str(path)]) == 0
    assert "A tiny test dataset" in capsys.readouterr().out


def test_data_verify_prints_the_run_command(capsys, fake_dataset, tmp_path):
    path, data_dir = fake_dataset
    status = main(["data", "verify", str(path), str(data_dir), "--workdir", "w"])
    assert status == 0
    out = capsys.readouterr().out
    command = next(line.strip() for line in out.splitlines() if "nbcalib run" in line)
    assert shlex.split(command) == [
        "nbcalib",
        "run",
        "--points",
        f"{data_dir}/scan.bin",
        "--image",
        f"{data_dir}/sub/image.png",
        "w",
    ]


def test_data_verify_mismatch_exit_2_one_line(capsys, fake_dataset):
    path, data_dir = fake_dataset
    (data_dir / "sub" / "image.png").write_bytes(b"short")
    assert main(["data", "verify", str(path), str(data_dir)]) == 2
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err
    assert "image.png" in captured.err and "size mismatch" in captured.err
    assert "nbcalib run" not in captured.out


def test_data_user_errors(capsys, tmp_path):
    assert main(["data", "show", "no_such_dataset"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no dataset named 'no_such_dataset'" in err
    assert main(["data", "verify", "kitti_raw_2011_09_26", str(tmp_path)]) == 2
    assert "2011_09_26_calib.zip" in capsys.readouterr().err
    assert main(["data"]) == 2  # no action: help, usage error


def test_all_shipped_manifests_load_together():
    names = [m.name for m in list_manifests()]
    assert names == sorted(names) and len(set(names)) == len(names)


@pytest.mark.parametrize(
    ("name", "folder"),
    [("opencalib_auto_calib", "auto_calib"), ("opencalib_manual_calib", "manual_calib_0")],
)
def test_published_hashes_match_the_real_data_copies(real_data, name, folder):
    """The JSON files whose hashes the manifests give are in the shared data folder too."""
    manifest = find_manifest(name)
    hashed = [entry for entry in manifest.files if entry.sha256 is not None]
    assert len(hashed) == 2
    for entry in hashed:
        path = real_data / "pjlab" / folder / entry.path
        assert path.stat().st_size == entry.bytes
        assert sha256_file(path) == entry.sha256


def test_manifest_dir_prefers_the_copy_inside_an_installed_package(tmp_path, monkeypatch):
    """A wheel ships the manifests as nbcalib/data_manifests (pyproject force-include)."""
    import nbcalib.data

    package = tmp_path / "site-packages" / "nbcalib"
    (package / "data_manifests").mkdir(parents=True)
    (package / "data_manifests" / "tiny_set.yaml").write_text(yaml.safe_dump(_tiny_manifest()))
    monkeypatch.setattr(nbcalib.data, "__file__", str(package / "data.py"))
    assert manifest_dir() == package / "data_manifests"
    assert [m.name for m in list_manifests()] == ["tiny_set"]
    (package / "data_manifests" / "tiny_set.yaml").unlink()
    (package / "data_manifests").rmdir()
    with pytest.raises(InputError, match="not installed"):
        manifest_dir()
