"""Several cameras, one LiDAR: the synthetic ring, the rig's cost, inputs and the job's layout."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.config import CalibrationConfig
from nbcalib.errors import InputError
from nbcalib.preprocess.inputs import InputSpec
from nbcalib.registration.config import RefineConfig
from nbcalib.registration.costs import build_cost
from nbcalib.registration.refine import RegistrationPair, refine
from nbcalib.rig_pipeline import camera_name, find_cameras
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.synthetic.lidar import lidar_preset
from nbcalib.synthetic.rig import generate_ring, ring_cameras
from nbcalib.synthetic.writer import export_dataset
from nbcalib.transforms import invert_T, pose_error, se3_exp
from tests.test_nid import textured_scene

SMALL = dict(
    lidar="livox",
    image_size=(160, 120),
    duration=0.3,
    lidar_config=lidar_preset("livox"),
)


# ---------------------------------------------------------------- the synthetic ring
def test_a_ring_shares_the_scans_and_its_first_camera_is_the_one_camera_rig():
    ring = RigConfig(cameras=("pinhole", "fisheye:128x96", "omnidir"), **SMALL)
    one = generate_sequence(RigConfig(**SMALL))
    sequences = generate_ring(ring)
    assert len(sequences) == 3
    np.testing.assert_array_equal(sequences[0].image, one.image)  # bit for bit
    np.testing.assert_array_equal(sequences[0].T_camera_lidar, one.T_camera_lidar)
    assert all(s.scans is sequences[0].scans for s in sequences)
    cams = ring_cameras(ring)
    assert [c.name for c in cams] == ["cam0", "cam1", "cam2"]
    assert (cams[1].camera.model, cams[1].camera.width, cams[1].camera.height) == (
        "fisheye",
        128,
        96,
    )
    assert (cams[2].camera.width, cams[2].camera.height) == (1024, 768)  # the ring's default
    for a in range(3):
        for b in range(a + 1, 3):
            dt, dr = pose_error(cams[a].T_camera_lidar, cams[b].T_camera_lidar)
            assert dt > 0.001 and dr > 1.0  # each camera has its own extrinsic


def test_a_ring_bag_has_a_topic_pair_per_camera_and_the_truth_of_each(tmp_path):
    from nbcalib.io.bag import list_topics
    from nbcalib.io.ground_truth import read_ground_truth, read_ground_truth_cameras

    config = RigConfig(cameras=("pinhole", "fisheye:128x96"), **SMALL)
    export_dataset(config, tmp_path, fmt="bag2")
    topics = list_topics(tmp_path / "pair_000")
    for name in ("cam0", "cam1"):
        assert topics[f"/{name}/image"] == "sensor_msgs/msg/Image"
        assert topics[f"/{name}/camera_info"] == "sensor_msgs/msg/CameraInfo"
        assert (tmp_path / name / "camera.yaml").is_file()
    truth = read_ground_truth_cameras(tmp_path / "ground_truth.json")
    cams = ring_cameras(config)
    for cam in cams:
        np.testing.assert_allclose(truth[cam.name], cam.T_camera_lidar, atol=1e-9)
    # one-camera tools judge the first camera
    np.testing.assert_allclose(read_ground_truth(tmp_path / "ground_truth.json"), truth["cam0"])
    doc = json.loads((tmp_path / "ground_truth.json").read_text())
    assert doc["cameras"][0]["T_cam0_camera"] == pytest.approx([0, 0, 0, 0, 0, 0, 1], abs=1e-9)


def test_a_ring_as_files_puts_an_image_per_camera_beside_the_shared_clouds(tmp_path):
    export_dataset(RigConfig(cameras=("pinhole", "atan"), **SMALL), tmp_path, fmt="files")
    assert (tmp_path / "pair_000.pcd").is_file()
    for name in ("cam0", "cam1"):
        assert (tmp_path / name / "pair_000.png").is_file()


def test_synth_refuses_an_unknown_ring_camera(tmp_path, capsys):
    assert main(["synth", str(tmp_path / "out"), "--cameras", "pinhole,fishy"]) == 2
    assert "--cameras: unknown camera 'fishy'" in capsys.readouterr().err


# ---------------------------------------------------------------- the rig's cost
def _rig_pairs(rng):
    """Two cameras, the reference at the LiDAR's truth (identity), the other 20 degrees aside."""
    cam_a = example_camera("plumb_bob", 160, 120)
    cam_b = example_camera("fisheye", 192, 144)
    image_a, points_a, values_a = textured_scene(cam_a, rng, n=6000, blur=1.5)
    image_b, points_b, values_b = textured_scene(cam_b, rng, n=6000, blur=1.5)
    T_b_ref = se3_exp(np.array([0.1, -0.05, 0.02, 0.0, np.radians(20.0), 0.01]))
    # camera b's points in the LiDAR frame: the truth is T_b_lidar = T_b_ref @ I
    lidar_b = points_b @ invert_T(T_b_ref)[:3, :3].T + invert_T(T_b_ref)[:3, 3]
    a = RegistrationPair(cam_a, image_a, points_a, values_a, "a")
    b = RegistrationPair(cam_b, image_b, lidar_b, values_b, "b", T_camera_rig=T_b_ref)
    return a, b, T_b_ref


def test_a_rig_term_is_its_pair_seen_through_the_rig_with_the_adjoint_gradient(rng):
    _, b, T_b_ref = _rig_pairs(rng)
    config = RefineConfig(hidden_point_removal=False, parallel=False)
    T = se3_exp(np.array([0.004, -0.003, 0.002, 0.002, -0.001, 0.003]))
    rig_cost, _ = build_cost([b], T, config)
    plain = RegistrationPair(b.camera, b.image, b.points_lidar, b.intensities, "b")
    own_cost, _ = build_cost([plain], T_b_ref @ T, config)
    assert rig_cost.value(T) == pytest.approx(own_cost.value(T_b_ref @ T), abs=1e-12)
    _, grad = rig_cost.value_and_grad(T)
    eps = 1e-6
    numeric = np.array(
        [
            (rig_cost.value(se3_exp(eps * e) @ T) - rig_cost.value(se3_exp(-eps * e) @ T))
            / (2 * eps)
            for e in np.eye(6)
        ]
    )
    np.testing.assert_allclose(grad, numeric, rtol=1e-3, atol=1e-4)


def test_a_rig_pose_is_refined_from_both_cameras(rng):
    a, b, _ = _rig_pairs(rng)
    start = se3_exp(np.array([0.02, -0.015, 0.01, 0.008, -0.006, 0.005]))
    config = RefineConfig(
        optimizer="lbfgs", min_pyramid_size=16, hidden_point_removal=False, parallel=False
    )
    for pairs in ([b], [a, b]):  # the other camera alone finds the reference's pose too
        result = refine(pairs, start, config)
        dt, dr = pose_error(invert_T(result.T_camera_lidar), np.eye(4))
        assert dt < 0.003 and dr < 0.05, (len(pairs), dt, dr)


# ---------------------------------------------------------------- inputs and the job
@pytest.fixture(scope="module")
def ring_bag(tmp_path_factory):
    out = tmp_path_factory.mktemp("ring")
    export_dataset(RigConfig(cameras=("pinhole", "fisheye:160x120"), **SMALL), out, fmt="bag2")
    return out


def test_cameras_are_every_image_topic_or_those_named(ring_bag):
    pre = CalibrationConfig().preprocess
    spec = InputSpec(inputs=(str(ring_bag / "pair_000"),))
    cameras = find_cameras(spec, pre)
    assert [(c.name, c.image_topic, c.camera_info_topic) for c in cameras] == [
        ("cam0", "/cam0/image", "/cam0/camera_info"),
        ("cam1", "/cam1/image", "/cam1/camera_info"),
    ]
    assert find_cameras(spec, pre, ["/cam1/image"]) is None  # one camera: the one-camera job
    with pytest.raises(InputError, match="no topic '/cam9/image'"):
        find_cameras(spec, pre, ["/cam0/image", "/cam9/image"])
    with pytest.raises(InputError, match="one pair per bag"):
        find_cameras(InputSpec(inputs=spec.inputs, every=2), pre)
    assert camera_name("/front/left/image_raw") == "front_left"
    assert camera_name("/image") == "image"


def test_a_ring_run_makes_a_work_directory_per_camera_with_one_dense_cloud(
    ring_bag, tmp_path, monkeypatch, capsys
):
    import nbcalib.preprocess.prepare as prepare

    made = []
    accumulate = prepare._accumulate
    monkeypatch.setattr(
        prepare, "_accumulate", lambda *a, **k: made.append(1) or accumulate(*a, **k)
    )
    work = tmp_path / "work"
    assert main(["run", str(ring_bag / "pair_000"), str(work), "--until", "preprocess"]) == 0
    assert len(made) == 1  # the dense cloud made once, for both cameras
    job = json.loads((work / "rig.json").read_text())
    assert [c["name"] for c in job["cameras"]] == ["cam0", "cam1"]
    for name, size in (("cam0", (160, 120)), ("cam1", (160, 120))):
        calib = json.loads((work / name / "calib.json").read_text())
        assert calib["nbcalib"]["config"]["preprocess"]["image_topic"] == f"/{name}/image"
        assert (calib["nbcalib"]["camera"]["width"], calib["nbcalib"]["camera"]["height"]) == size
        assert (work / name / "pair_000.ply").is_file()
    a = (work / "cam0" / "pair_000.ply").read_bytes()
    assert a == (work / "cam1" / "pair_000.ply").read_bytes()  # the same cloud
    assert "2 cameras" in capsys.readouterr().out


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--init", "0,0,0,0,0,0,1"], "--init/--no-matching with several cameras need --rig"),
        (["--manual", "picks.json"], "--manual is for one camera"),
        (["--prior", "0,0,0,0,0,0,1"], "--prior is for one camera"),
    ],
)
def test_a_ring_run_refuses_one_camera_options(ring_bag, tmp_path, capsys, extra, message):
    args = ["run", str(ring_bag / "pair_000"), str(tmp_path / "w"), *extra]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def _rig_workdir(path):
    """A finished two-camera work directory: cam0 1 cm off its truth, cam1 3 cm."""
    from nbcalib.transforms import pose_to_xyz_quat
    from nbcalib.workdir import make_calib

    truth = {"cameras": []}
    job = {"cameras": [], "reference": "cam0", "joint": False}
    for k, offset in enumerate((0.01, 0.03)):
        T_true = se3_exp(np.array([0.1 * k, 0.0, 0.0, 0.0, 0.0, 0.3 * k]))
        values = [float(v) for v in pose_to_xyz_quat(invert_T(T_true))]
        truth["cameras"].append({"name": f"cam{k}", "T_lidar_camera": values})
        calib = make_calib(example_camera("fisheye" if k else "pinhole", 160, 120), ["pair_000"])
        calib.set_T_camera_lidar(
            "T_lidar_camera", se3_exp(np.array([offset, 0, 0, 0, 0, 0])) @ T_true
        )
        (path / f"cam{k}").mkdir()
        (path / f"cam{k}" / "calib.json").write_text(json.dumps(calib.to_dict()))
        job["cameras"].append({"name": f"cam{k}", "image_topic": f"/cam{k}/image"})
    (path / "rig.json").write_text(json.dumps(job))
    (path / "gt.json").write_text(json.dumps(truth))
    return job


def test_evaluate_prints_the_rig_then_each_camera(tmp_path, capsys):
    _rig_workdir(tmp_path)
    assert main(["evaluate", str(tmp_path), "--ground-truth", str(tmp_path / "gt.json")]) == 0
    lines = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert [x.get("camera") for x in lines] == [None, "cam0", "cam1"]
    assert lines[0]["rig"] == "cam0" and lines[0]["cameras"] == 2
    assert lines[1]["translation_error_m"] == pytest.approx(0.01, abs=1e-6)
    assert lines[2]["translation_error_m"] == pytest.approx(0.03, abs=1e-6)
    assert lines[0]["worst_translation_error_m"] == pytest.approx(0.03, abs=1e-6)


def test_export_writes_every_camera_in_one_tree(tmp_path, capsys):
    import xml.etree.ElementTree as ET

    from nbcalib.io.calib_json import read_calib_json
    from nbcalib.io.camera_file import load_camera

    _rig_workdir(tmp_path)
    assert main(["export", str(tmp_path), "--parent-frame", "velodyne"]) == 0
    out = tmp_path / "export"
    robot = ET.parse(out / "lidar_cameras.urdf").getroot()
    joints = {j.get("name"): j for j in robot.findall("joint")}
    assert sorted(joints) == ["velodyne_to_cam0", "velodyne_to_cam1"]
    script = (out / "tf2_static_transforms.sh").read_text()
    assert script.count("static_transform_publisher --x") == 2 and "--child-frame-id cam1" in script
    compile((out / "static_transforms.launch.py").read_text(), "launch", "exec")
    for name in ("cam0", "cam1"):
        calib = read_calib_json(tmp_path / name / "calib.json")
        camera = load_camera(out / name / "camera_lidar_opencv.yaml")
        point = np.array([[0.3, -0.2, 2.0]])
        np.testing.assert_allclose(
            camera.project(point)[0], calib.camera_model().project(point)[0], atol=1e-9
        )
    assert "exported 2 cameras (cam0, cam1)" in capsys.readouterr().out
    assert main(["export", str(tmp_path), "--child-frame", "front"]) == 2


def test_the_rig_report_has_a_section_per_camera_and_the_rig(tmp_path):
    from nbcalib.report.rig import write_rig_report

    job = _rig_workdir(tmp_path)
    job["cameras"][1]["T_ref_camera"] = [0.1, 0, 0, 0, 0, 0, 1]
    page = write_rig_report(tmp_path, job).read_text()
    for text in ("Camera cam0", "Camera cam1", "The rig", "T_cam0_camera", "/cam1/image"):
        assert text in page
    assert "No report yet" in page  # the fake cameras have results but no report


def test_a_rig_that_does_not_fit_the_cameras_guesses_is_refused():
    from nbcalib.io.rig import Rig, RigCamera
    from nbcalib.products import Start
    from nbcalib.rig_pipeline import CameraSource, RigCalibrator

    T_cam1_cam0 = se3_exp(np.array([0.1, 0.0, 0.0, 0.0, np.radians(90.0), 0.0]))
    rig = Rig((RigCamera("cam0", None, np.eye(4)), RigCamera("cam1", None, T_cam1_cam0)))
    job = RigCalibrator(rig=rig)
    job._check_rig([CameraSource("cam0", "/cam0/image"), CameraSource("cam1", "/cam1/image")])
    T0 = se3_exp(np.array([0.05, 0.02, 0.0, 0.1, 0.2, 0.0]))
    fits = {"cam0": Start.from_matrix(T0, "a"), "cam1": Start.from_matrix(T_cam1_cam0 @ T0, "b")}
    job._check_starts(fits, "cam0", T0, "cam0")
    assert job.start_disagreement["cam1"][1] < 1e-6
    swapped = {"cam0": fits["cam0"], "cam1": Start.from_matrix(T0, "b")}  # a rig of other cameras
    with pytest.raises(InputError, match="the rig does not fit the cameras"):
        job._check_starts(swapped, "cam0", T0, "cam0")


def test_the_api_calibrates_a_ring_by_camera_name_through_its_rig():
    import nbcalib
    from nbcalib.io.rig import Rig, RigCamera

    config = RigConfig(cameras=("pinhole:640x480", "fisheye:512x384"), **{**SMALL, "duration": 2.0})
    sequences = generate_ring(config)
    points, values = sequences[0].dense_cloud()
    T0 = sequences[0].T_camera_lidar
    rig = Rig(
        tuple(
            RigCamera(f"cam{k}", s.camera, s.T_camera_lidar @ invert_T(T0))
            for k, s in enumerate(sequences)
        )
    )
    start = se3_exp(np.array([0.01, -0.01, 0.005, 0.004, -0.003, 0.002])) @ T0
    result = nbcalib.calibrate(
        points,
        values,
        {f"cam{k}": s.image for k, s in enumerate(sequences)},
        {f"cam{k}": s.camera for k, s in enumerate(sequences)},
        rig=rig,
        T_init=start,
        progress=False,
        restarts=0,
    )
    assert result.joint and sorted(result.cameras) == ["cam0", "cam1"]
    for k, s in enumerate(sequences):
        dt, dr = pose_error(
            invert_T(result.cameras[f"cam{k}"].T_camera_lidar), invert_T(s.T_camera_lidar)
        )
        # measured 0.86 cm / 0.115 deg for both, from 1.5 cm / 0.36 deg
        assert dt < 0.012 and dr < 0.2, (k, dt, dr)
    with pytest.raises(ValueError, match="needs their rig"):
        nbcalib.calibrate(points, values, {"a": sequences[0].image}, {"a": sequences[0].camera},
                          T_init=start)  # fmt: skip


def test_a_ring_camera_is_preprocessed_as_the_one_camera_job_of_its_topic(ring_bag, tmp_path):
    """The several-camera path hands each camera the one-camera pipeline's products, to the bit."""
    import hashlib

    ring, alone = tmp_path / "ring", tmp_path / "alone"
    bag = str(ring_bag / "pair_000")
    assert main(["run", bag, str(ring), "--until", "preprocess", "-q"]) == 0
    one = ["--image-topic", "/cam1/image", "--camera-info-topic", "/cam1/camera_info"]
    assert main(["run", bag, str(alone), "--until", "preprocess", "-q", *one]) == 0
    names = sorted(p.name for p in alone.iterdir() if p.suffix in (".ply", ".png"))
    assert names == sorted(
        p.name for p in (ring / "cam1").iterdir() if p.suffix in (".ply", ".png")
    )
    for name in names:
        digest = [
            hashlib.sha256((d / name).read_bytes()).hexdigest() for d in (alone, ring / "cam1")
        ]
        assert digest[0] == digest[1], name
    a = json.loads((alone / "calib.json").read_text())
    b = json.loads((ring / "cam1" / "calib.json").read_text())
    for key in ("camera", "virtual_camera", "preprocess", "config", "inputs"):
        assert a["nbcalib"][key] == b["nbcalib"][key], key
    assert a["camera"] == b["camera"]


def test_topics_says_run_takes_every_camera(ring_bag, capsys):
    assert main(["topics", str(ring_bag / "pair_000")]) == 0
    assert "nbcalib run calibrates each of the 2 cameras" in capsys.readouterr().out


def test_several_cameras_from_files_each_with_its_image_and_camera(tmp_path, capsys):
    data, work = tmp_path / "ring", tmp_path / "work"
    export_dataset(RigConfig(cameras=("pinhole", "fisheye:160x120"), **SMALL), data, fmt="files")
    cams = []
    for name in ("cam0", "cam1"):
        cams += ["--camera-image", name, str(data / name / "pair_000.png")]
        cams += [str(data / name / "camera.yaml")]
    args = ["run", str(data / "pair_000.pcd"), str(work), "--until", "preprocess", "-q", *cams]
    assert main(args) == 0
    job = json.loads((work / "rig.json").read_text())
    assert sorted(job["inputs"]["per_camera"]) == ["cam0", "cam1"]
    for name, model in (("cam0", "pinhole"), ("cam1", "fisheye")):
        calib = json.loads((work / name / "calib.json").read_text())
        assert calib["nbcalib"]["camera"]["camera_model"] == model
        assert calib["nbcalib"]["inputs"]["image"].endswith(f"{name}/pair_000.png")
    assert main(["run", str(work), "--until", "preprocess", "-q"]) == 0  # continues from rig.json
    bad = ["run", str(data / "pair_000.pcd"), str(tmp_path / "w2"), "--image", "x.png", *cams]
    assert main(bad) == 2
    assert "--camera-image gives each camera its image" in capsys.readouterr().err
