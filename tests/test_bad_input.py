"""The bad-input corpus: every user mistake gets a clear answer and changes nothing.

Each case is a command line as a user would type it, over a small synthetic base (plain input
files, a preprocessed work directory, a finished one with its report and exports). A case
expects an exit status (2 for a user error) and asserts that

- the error is one line, the last one, naming the file (or the option) concerned;
- no traceback is printed;
- nothing changed: every folder the case watches has the same files with the same bytes
  afterwards, and a work directory the command was to create was not left half-made.

Read-only folders: as root (CI runs as root) the mode bits do not stop writes, so the command
runs with the effective user ``nobody`` for that case, which the bits do stop.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.io.camera_file import save_camera
from nbcalib.io.image import write_png
from nbcalib.transforms import invert_T, pose_to_xyz_quat, se3_exp
from tests.test_nid import textured_scene

#: The true extrinsic: a LiDAR with REP 103 axes (x forward) at the camera's centre
T_TRUE = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
T_START = se3_exp(np.array([0.02, -0.01, 0.01, 0.006, -0.004, 0.005])) @ T_TRUE
INIT = ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T_START)))
#: A start that looks away from every point (the camera turned round)
INIT_AWAY = ",".join(
    f"{v:.9f}"
    for v in pose_to_xyz_quat(invert_T(se3_exp(np.array([0, 0, 0, 0, np.pi, 0])) @ T_TRUE))
)
NOBODY = 65534


# ------------------------------------------------------------------------------ the base
@pytest.fixture(scope="module")
def base():
    """Inputs, a preprocessed and a finished work directory, in a folder 'nobody' may enter."""
    # everything a command may load, loaded while numba can still write its cache beside it
    import nbcalib.pipeline
    import nbcalib.report.html
    import nbcalib.synthetic  # noqa: F401

    root = Path(tempfile.mkdtemp(prefix="nbcalib-corpus-"))
    root.chmod(0o755)
    inputs = root / "inputs"
    inputs.mkdir()
    rng = np.random.default_rng(7)
    camera = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(camera, rng, n=15000, blur=2.0)
    points = points @ T_TRUE[:3, :3]  # camera frame -> LiDAR frame
    cloud = np.column_stack([points, intensities]).astype(np.float32)
    np.save(inputs / "points.npy", cloud)
    write_png(inputs / "image.png", np.round(image * 255).astype(np.uint8))
    save_camera(inputs / "camera.yaml", camera)
    prep = root / "prep"
    assert main(["-q", "preprocess", *_plain(inputs), str(prep)]) == 0
    finished = root / "finished"
    argv = ["-q", "run", *_plain(inputs), str(finished), "--no-matching", f"--init={INIT}"]
    assert main([*argv, "--max-outer", "1", "--pyramid-levels", "0"]) == 0
    assert main(["-q", "export", str(finished)]) == 0
    assert (finished / "report" / "index.html").is_file()
    yield {"root": root, "inputs": inputs, "prep": prep, "finished": finished, "cloud": cloud}
    shutil.rmtree(root, ignore_errors=True)


def _plain(inputs: Path) -> list[str]:
    return [
        str(inputs / "points.npy"),
        str(inputs / "image.png"),
        "--camera",
        str(inputs / "camera.yaml"),
    ]


# ------------------------------------------------------------------------------ helpers
def _digest(folder: Path) -> dict[str, str]:
    """Relative path -> sha256 of every file under ``folder`` (folders as 'dir')."""
    if not folder.exists():
        return {}
    out = {}
    for path in sorted(folder.rglob("*")):
        key = str(path.relative_to(folder))
        out[key] = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
    return out


@contextlib.contextmanager
def _as_unprivileged(read_only: list[Path]):
    """Make ``read_only`` folders unwritable for the duration (as 'nobody' when root)."""
    modes = {p: p.stat().st_mode for p in read_only}
    for p in read_only:
        p.chmod(0o555)
    root = os.geteuid() == 0
    try:
        if root:
            os.setegid(NOBODY)
            os.seteuid(NOBODY)
        yield
    finally:
        if root:
            os.seteuid(0)
            os.setegid(0)
        for p, mode in modes.items():
            p.chmod(stat.S_IMODE(mode))


@dataclass
class Case:
    """One command line and what it must do.

    ``argv`` and ``setup`` get a dict of paths: the base's (``inputs``, ``prep``,
    ``finished``), and ``tmp`` (this case's folder), ``work`` (a copy of the base work
    directory ``copy``, if any) and whatever ``setup`` adds.
    """

    id: str
    argv: object  # callable(paths) -> list[str]
    names: object = None  # callable(paths) -> str the message must contain; None: no check
    status: int = 2
    copy: str | None = None  # "prep" or "finished": a fresh copy at paths["work"]
    setup: object = None  # callable(paths) -> None, prepares bad input under paths["tmp"]
    read_only: tuple = ()  # keys of paths made read-only
    absent: tuple = ()  # keys of paths that must not exist afterwards (a folder not made)
    message: str = ""  # text the error must contain
    extra: dict = field(default_factory=dict)
    during: object = None  # callable(paths) -> context manager around the command (a fault)


def hold_lock(path: Path):
    """Another process, holding the lock of work directory ``path`` until stopped (Popen)."""
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent(
        f"""
        import time
        from nbcalib.io.workdir_lock import workdir_lock
        with workdir_lock({str(path)!r}):
            print("held", flush=True)
            time.sleep(600)
        """
    )
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    if proc.stdout.readline().strip() != "held":
        proc.kill()
        proc.wait(timeout=30)
        raise AssertionError(f"the holder of {path}'s lock did not start")
    return proc


@contextlib.contextmanager
def _held_elsewhere(path: Path):
    """The work directory's lock held by another process while the block runs."""
    proc = hold_lock(path)
    try:
        yield proc
    finally:
        proc.kill()
        proc.wait(timeout=30)


@contextlib.contextmanager
def _full_disk():
    """Every file written while the block runs fails as on a full disk (ENOSPC)."""
    import errno

    from nbcalib.io import _files

    real = _files.os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    _files.os.fsync = full
    try:
        yield
    finally:
        _files.os.fsync = real


def _write(path: Path, data: bytes | str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    (path.write_bytes if isinstance(data, bytes) else path.write_text)(data)
    return path


def _pcd(points: np.ndarray, *, declared: int | None = None, data: str = "binary") -> bytes:
    n = len(points) if declared is None else declared
    header = (
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
        f"COUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
    return header.encode() + np.asarray(points, np.float32).tobytes()


def _points_case(id, make, message="", name=None, status=2):
    """preprocess of one bad point file (made by ``make(paths) -> Path``) with the good image."""

    def setup(p):
        p["bad"] = make(p)

    def argv(p):
        return ["preprocess", str(p["bad"]), str(p["inputs"] / "image.png"), str(p["tmp"] / "w"),
                "--camera", str(p["inputs"] / "camera.yaml")]  # fmt: skip

    return Case(id, argv, names=name or (lambda p: p["bad"].name), setup=setup, absent=("w",),
                message=message, status=status)  # fmt: skip


def _image_case(id, make, message="", camera=None):
    def setup(p):
        p["bad"] = make(p)
        if camera is not None:
            p["cam"] = camera(p)

    def argv(p):
        cam = p.get("cam", p["inputs"] / "camera.yaml")
        return ["preprocess", str(p["inputs"] / "points.npy"), str(p["bad"]), str(p["tmp"] / "w"),
                "--camera", str(cam)]  # fmt: skip

    return Case(id, argv, names=lambda p: p["bad"].name, setup=setup, absent=("w",),
                message=message)  # fmt: skip


def _camera_case(id, make, message="", name=None):
    def setup(p):
        p["bad"] = make(p)

    def argv(p):
        return ["preprocess", *_plain(p["inputs"])[:2], str(p["tmp"] / "w"), "--camera",
                str(p["bad"])]  # fmt: skip

    return Case(id, argv, names=name or (lambda p: p["bad"].name), setup=setup, absent=("w",),
                message=message)  # fmt: skip


def _camera_options_case(id, options, message, name):
    def argv(p):
        return ["preprocess", *_plain(p["inputs"])[:2], str(p["tmp"] / "w"), *options]

    return Case(id, argv, names=lambda p: name, absent=("w",), message=message)


def _stage_case(id, command, extra=(), *, copy="finished", message="", name=None, status=2,
                setup=None, read_only=(), during=None, names=None):  # fmt: skip
    def argv(p):
        extra_args = [a(p) if callable(a) else a for a in extra]
        return [command, str(p["work"]), *extra_args]

    names = names or name or (lambda p: p["work"].name)
    return Case(id, argv, names=names, copy=copy, message=message, status=status, setup=setup,
                read_only=read_only, during=during)  # fmt: skip


def _bag(p, fmt):
    """A small valid bag of the base's cloud and image (nbcalib's own writer)."""
    from nbcalib.io.bag_writer import BagWriter
    from nbcalib.io.camera_file import load_camera
    from nbcalib.io.image import read_image

    out = p["tmp"] / ("data.bag" if fmt == "bag1" else "data")
    cloud = p["base_cloud"]
    fields = {
        k: np.ascontiguousarray(cloud[:, i]) for i, k in enumerate(("x", "y", "z", "intensity"))
    }
    image = read_image(p["inputs"] / "image.png", grey=True)
    with BagWriter(out, fmt) as bag:
        for k in range(2):
            stamp = 10**9 + k * 10**8
            bag.write_pointcloud("/points", stamp, fields, "lidar")
            bag.write_image("/image", stamp, image, "camera")
        bag.write_camera_info(
            "/camera_info", 10**9, load_camera(p["inputs"] / "camera.yaml"), "camera"
        )
    return out


# ------------------------------------------------------------------------------ the cases
def _npy(p, array, name="bad.npy"):
    path = p["tmp"] / name
    path.parent.mkdir(parents=True, exist_ok=True)
    np.save(path, array)
    return path


def _nan_rows(p):
    cloud = p["base_cloud"].copy()
    cloud[:, 0] = np.nan
    return _npy(p, cloud)


CASES = [
    # ---- point clouds
    _points_case("cloud-missing", lambda p: p["tmp"] / "nope.pcd", "not found"),
    _points_case("cloud-empty-file", lambda p: _write(p["tmp"] / "empty.pcd", b"")),
    _points_case(
        "cloud-pcd-0-points", lambda p: _write(p["tmp"] / "zero.pcd", _pcd(np.zeros((0, 4))))
    ),
    _points_case(
        "cloud-pcd-truncated", lambda p: _write(p["tmp"] / "cut.pcd", _pcd(p["base_cloud"])[:-1000])
    ),
    _points_case(
        "cloud-pcd-lying-count",
        lambda p: _write(p["tmp"] / "lie.pcd", _pcd(p["base_cloud"][:10], declared=10**9)),
    ),
    _points_case("cloud-pcd-garbage", lambda p: _write(p["tmp"] / "junk.pcd", os.urandom(4096))),
    _points_case(
        "cloud-ply-bad-header",
        lambda p: _write(
            p["tmp"] / "bad.ply",
            "ply\nformat binary_little_endian 1.0\n"
            "element vertex 10\nproperty float64x x\nend_header\n",
        ),
    ),
    _points_case(
        "cloud-ply-no-vertex",
        lambda p: _write(p["tmp"] / "nov.ply", "ply\nformat ascii 1.0\nend_header\n"),
    ),
    _points_case("cloud-bin-odd-size", lambda p: _write(p["tmp"] / "odd.bin", b"\0" * 30)),
    _points_case("cloud-bin-empty", lambda p: _write(p["tmp"] / "zero.bin", b"")),
    _points_case(
        "cloud-npy-text", lambda p: _write(p["tmp"] / "text.npy", "x y z\n1 2 3\n"), "not a NumPy"
    ),
    _points_case("cloud-npy-all-nan", _nan_rows),
    _points_case("cloud-npy-2-columns", lambda p: _npy(p, np.zeros((100, 2), np.float32))),
    _points_case("cloud-npy-0-rows", lambda p: _npy(p, np.zeros((0, 4), np.float32))),
    _points_case("cloud-npy-strings", lambda p: _npy(p, np.array(["a", "b"]))),
    _points_case(
        "cloud-npz-no-points",
        lambda p: (np.savez(p["tmp"] / "w.npz", other=np.zeros(3)), p["tmp"] / "w.npz")[1],
    ),
    _points_case("cloud-unknown-suffix", lambda p: _write(p["tmp"] / "cloud.xyz", "1 2 3\n")),
    _points_case(
        "cloud-is-a-folder", lambda p: (p["tmp"] / "folder.pcd").mkdir() or p["tmp"] / "folder.pcd"
    ),
    # ---- images
    _image_case("image-missing", lambda p: p["tmp"] / "nope.png", "not found"),
    _image_case("image-garbage", lambda p: _write(p["tmp"] / "junk.png", os.urandom(2048))),
    _image_case("image-empty-file", lambda p: _write(p["tmp"] / "empty.png", b"")),
    _image_case("image-text", lambda p: _write(p["tmp"] / "text.jpg", "hello")),
    _image_case(
        "image-truncated",
        lambda p: _write(p["tmp"] / "cut.png", (p["inputs"] / "image.png").read_bytes()[:200]),
    ),
    _image_case(
        "image-size-differs-from-camera",
        lambda p: (
            write_png(p["tmp"] / "small.png", np.zeros((100, 120), np.uint8)),
            p["tmp"] / "small.png",
        )[1],
    ),
    _image_case(
        "image-1x1-camera-1x1",
        lambda p: (
            write_png(p["tmp"] / "one.png", np.zeros((1, 1), np.uint8)),
            p["tmp"] / "one.png",
        )[1],
        camera=lambda p: (
            save_camera(p["tmp"] / "one.yaml", example_camera("pinhole", 1, 1)),
            p["tmp"] / "one.yaml",
        )[1],
    ),
    # ---- cameras
    _camera_case("camera-missing", lambda p: p["tmp"] / "nope.yaml", "not found"),
    _camera_case(
        "camera-garbage-yaml", lambda p: _write(p["tmp"] / "cam.yaml", "camera: [unclosed\n")
    ),
    _camera_case(
        "camera-yaml-not-a-camera", lambda p: _write(p["tmp"] / "cam.yaml", "a: 1\nb: 2\n")
    ),
    _camera_case(
        "camera-wrong-intrinsics-count",
        lambda p: _write(
            p["tmp"] / "cam.yaml",
            (p["inputs"] / "camera.yaml").read_text().replace("intrinsics: [", "intrinsics: [1, "),
        ),
    ),
    _camera_case("camera-empty-file", lambda p: _write(p["tmp"] / "cam.yaml", "")),
    _camera_case(
        "camera-is-a-folder", lambda p: (p["tmp"] / "cam.yaml").mkdir() or p["tmp"] / "cam.yaml"
    ),
    _camera_case("camera-json-garbage", lambda p: _write(p["tmp"] / "cam.json", '{"camera": ')),
    _camera_options_case(
        "camera-model-unknown",
        ["--camera-model", "magic", "--intrinsics", "1,1,1,1"],
        "magic",
        "--camera-model",
    ),
    _camera_options_case(
        "intrinsics-count",
        ["--camera-model", "pinhole", "--intrinsics", "1,2,3"],
        "",
        "--intrinsics",
    ),
    _camera_options_case(
        "intrinsics-not-numbers",
        ["--camera-model", "pinhole", "--intrinsics", "a,b,c,d"],
        "",
        "--intrinsics",
    ),
    _camera_options_case(
        "distortion-count",
        [
            "--camera-model",
            "plumb_bob",
            "--intrinsics",
            "300,300,160,120",
            "--distortion",
            "-0.1,0.2",
        ],
        "",
        "--distortion",
    ),
    _camera_options_case(
        "intrinsics-nan",
        ["--camera-model", "pinhole", "--intrinsics", "nan,300,160,120"],
        "",
        "--intrinsics",
    ),
    _camera_options_case("no-camera", [], "camera", "--camera"),
    # ---- bags
    Case(
        "bag-missing",
        lambda p: ["preprocess", str(p["tmp"] / "nope.bag"), str(p["tmp"] / "w")],
        names=lambda p: "nope.bag",
        absent=("w",),
    ),
    Case(
        "bag-truncated",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w")],
        names=lambda p: p["bag"].name,
        absent=("w",),
        setup=lambda p: p.update(
            bag=_write(p["tmp"] / "cut.bag", _bag(p, "bag1").read_bytes()[:5000])
        ),
    ),
    Case(
        "bag-garbage",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w")],
        names=lambda p: p["bag"].name,
        absent=("w",),
        setup=lambda p: p.update(bag=_write(p["tmp"] / "junk.bag", os.urandom(8000))),
    ),
    Case(
        "bag-unknown-points-topic",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w"), "--points-topic", "/nope"],
        names=lambda p: p["bag"].name,
        absent=("w",),
        message="/nope",
        setup=lambda p: p.update(bag=_bag(p, "bag1")),
    ),
    Case(
        "bag-unknown-image-topic",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w"), "--image-topic", "/nope"],
        names=lambda p: p["bag"].name,
        absent=("w",),
        message="/nope",
        setup=lambda p: p.update(bag=_bag(p, "bag1")),
    ),
    Case(
        "bag2-folder-without-metadata",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w")],
        names=lambda p: p["bag"].name,
        absent=("w",),
        setup=lambda p: p.update(bag=(p["tmp"] / "rosbag2_x").mkdir() or p["tmp"] / "rosbag2_x"),
    ),
    Case(
        "bag2-metadata-garbage",
        lambda p: ["preprocess", str(p["bag"]), str(p["tmp"] / "w")],
        names=lambda p: "metadata.yaml",
        absent=("w",),
        setup=lambda p: p.update(
            bag=_write(p["tmp"] / "b2" / "metadata.yaml", "rosbag2_bagfile_information: [").parent
        ),
    ),
    # ---- work directories and stage commands
    Case(
        "find-matches-no-workdir",
        lambda p: ["find-matches", str(p["tmp"] / "nowhere")],
        names=lambda p: "nowhere",
        absent=("nowhere",),
    ),
    Case(
        "calibrate-empty-folder",
        lambda p: ["calibrate", str(p["tmp"] / "empty")],
        names=lambda p: "empty",
        setup=lambda p: (p["tmp"] / "empty").mkdir(),
    ),
    _stage_case(
        "calibrate-corrupt-calib-json",
        "calibrate",
        ["--force"],
        name=lambda p: "calib.json",
        setup=lambda p: _write(p["work"] / "calib.json", '{"camera": {'),
    ),
    _stage_case(
        "calibrate-calib-json-not-object",
        "calibrate",
        ["--force"],
        name=lambda p: "calib.json",
        setup=lambda p: _write(p["work"] / "calib.json", "[1, 2, 3]"),
    ),
    _stage_case(
        "calibrate-missing-cloud",
        "calibrate",
        ["--force"],
        name=lambda p: "000000.ply",
        setup=lambda p: (p["work"] / "000000.ply").unlink(),
    ),
    _stage_case(
        "calibrate-corrupt-cloud",
        "calibrate",
        ["--force"],
        name=lambda p: "000000.ply",
        setup=lambda p: _write(p["work"] / "000000.ply", b"ply\nformat binary_little_endian 1.0\n"),
    ),
    _stage_case(
        "calibrate-corrupt-index-map",
        "calibrate",
        ["--force"],
        name=lambda p: "000000_lidar_indices.png",
        setup=lambda p: _write(p["work"] / "000000_lidar_indices.png", os.urandom(500)),
    ),
    _stage_case(
        "calibrate-init-6-values",
        "calibrate",
        ["--init", "0,0,0,0,0,1"],
        copy="prep",
        name=lambda p: "--init",
    ),
    _stage_case(
        "calibrate-init-not-numbers",
        "calibrate",
        ["--init", "a,b,c,d,e,f,g"],
        copy="prep",
        name=lambda p: "--init",
    ),
    _stage_case(
        "calibrate-init-zero-quaternion",
        "calibrate",
        ["--init", "0,0,0,0,0,0,0"],
        copy="prep",
        name=lambda p: "--init",
    ),
    _stage_case(
        "calibrate-init-nan",
        "calibrate",
        ["--init", "nan,0,0,0,0,0,1"],
        copy="prep",
        name=lambda p: "--init",
    ),
    _stage_case(
        "calibrate-bins-1",
        "calibrate",
        ["--init", INIT, "--bins", "1"],
        copy="prep",
        name=lambda p: "--bins",
    ),
    _stage_case(
        "calibrate-bins-0",
        "calibrate",
        ["--init", INIT, "--bins", "0"],
        copy="prep",
        name=lambda p: "--bins",
    ),
    _stage_case(
        "calibrate-max-outer-0",
        "calibrate",
        ["--init", INIT, "--max-outer", "0"],
        copy="prep",
        name=lambda p: "--max-outer",
    ),
    _stage_case(
        "calibrate-trust-negative",
        "calibrate",
        ["--init", INIT, "--trust-translation", "-1"],
        copy="prep",
        name=lambda p: "--trust-translation",
    ),
    _stage_case(
        "calibrate-nothing-in-view",
        "calibrate",
        ["--init", INIT_AWAY, "--max-outer", "1"],
        copy="prep",
        name=lambda p: "calib.json",
        message="points",
    ),
    _stage_case(
        "calibrate-over-finished-result",
        "calibrate",
        ["--init", INIT],
        message="--force",
        name=lambda p: "calib.json",
    ),
    _stage_case(
        "calibrate-no-guess",
        "calibrate",
        [],
        copy="prep",
        name=lambda p: "calib.json",
        message="initial-guess",
    ),
    _stage_case(
        "initial-guess-manual-missing",
        "initial-guess",
        ["--manual", lambda p: str(p["tmp"] / "picks.json")],
        copy="prep",
        name=lambda p: "picks.json",
    ),
    _stage_case(
        "initial-guess-manual-corrupt",
        "initial-guess",
        ["--manual", lambda p: str(p["tmp"] / "picks.json")],
        copy="prep",
        name=lambda p: "picks.json",
        setup=lambda p: _write(p["tmp"] / "picks.json", "{["),
    ),
    _stage_case(
        "initial-guess-manual-too-few",
        "initial-guess",
        ["--manual", lambda p: str(p["tmp"] / "picks.json")],
        copy="prep",
        name=lambda p: "picks.json",
        setup=lambda p: _write(
            p["tmp"] / "picks.json",
            '{"correspondences": [{"camera": [10, 10], "lidar": [1, 2, 3]}]}',
        ),
    ),
    _stage_case(
        "initial-guess-over-finished-result",
        "initial-guess",
        [],
        message="--force",
        name=lambda p: "calib.json",
    ),
    _stage_case(
        "find-matches-over-finished-result",
        "find-matches",
        [],
        message="--force",
        name=lambda p: "calib.json",
    ),
    _stage_case(
        "find-matches-model-dir-missing",
        "find-matches",
        ["--matcher", "xfeat-lighterglue", "--model-dir", lambda p: str(p["tmp"] / "models")],
        copy="prep",
        name=lambda p: "models",
    ),
    _stage_case(
        "report-no-result",
        "report",
        [],
        copy="prep",
        name=lambda p: "calib.json",
        message="calibrate",
    ),
    _stage_case(
        "report-confidence-out-of-range",
        "report",
        ["--confidence", "1.5"],
        name=lambda p: "--confidence",
    ),
    _stage_case("export-no-result", "export", [], copy="prep", name=lambda p: "calib.json"),
    _stage_case(
        "evaluate-ground-truth-missing",
        "evaluate",
        ["--ground-truth", lambda p: str(p["tmp"] / "gt.json")],
        name=lambda p: "gt.json",
    ),
    _stage_case(
        "evaluate-ground-truth-corrupt",
        "evaluate",
        ["--ground-truth", lambda p: str(p["tmp"] / "gt.json")],
        name=lambda p: "gt.json",
        setup=lambda p: _write(p["tmp"] / "gt.json", '{"T_lidar_camera": [1, 2]}'),
    ),
    Case(
        "preprocess-over-finished-result",
        lambda p: [
            "preprocess",
            *_plain(p["inputs"])[:2],
            str(p["work"]),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
        ],
        names=lambda p: "calib.json",
        copy="finished",
        message="--force",
    ),
    Case(
        "preprocess-workdir-is-a-file",
        lambda p: ["preprocess", *_plain(p["inputs"]), str(p["tmp"] / "afile")],
        names=lambda p: "afile",
        setup=lambda p: _write(p["tmp"] / "afile", "x"),
    ),
    Case(
        "preprocess-workdir-under-a-file",
        lambda p: ["preprocess", *_plain(p["inputs"]), str(p["tmp"] / "afile" / "w")],
        names=lambda p: "afile",
        setup=lambda p: _write(p["tmp"] / "afile", "x"),
    ),
    # ---- the file system
    Case(
        "preprocess-into-read-only-folder",
        lambda p: ["preprocess", *_plain(p["inputs"]), str(p["ro"])],
        names=lambda p: "ro",
        setup=lambda p: p.update(ro=p["tmp"] / "ro") or p["ro"].mkdir(),
        read_only=("ro",),
    ),
    Case(
        "preprocess-into-subfolder-of-read-only",
        lambda p: ["preprocess", *_plain(p["inputs"]), str(p["ro"] / "sub" / "w")],
        names=lambda p: "ro",
        setup=lambda p: p.update(ro=p["tmp"] / "ro") or p["ro"].mkdir(),
        read_only=("ro",),
    ),
    _stage_case("report-read-only-workdir", "report", [], read_only=("work",)),
    _stage_case("export-read-only-workdir", "export", [], read_only=("work",)),
    _stage_case(
        "calibrate-read-only-workdir", "calibrate", ["--init", INIT, "--force"], read_only=("work",)
    ),
    _stage_case("find-matches-read-only-workdir", "find-matches", ["--force"], read_only=("work",)),
    Case(
        "synth-into-read-only-folder",
        lambda p: ["synth", str(p["ro"] / "out"), "--image-size", "64x48", "--duration", "0.1"],
        names=lambda p: "ro",
        setup=lambda p: p.update(ro=p["tmp"] / "ro") or p["ro"].mkdir(),
        read_only=("ro",),
    ),
    Case(
        "demo-into-a-file",
        lambda p: ["demo", str(p["tmp"] / "afile")],
        names=lambda p: "afile",
        setup=lambda p: _write(p["tmp"] / "afile", "x"),
    ),
    # ---- a work directory in use, a full disk (every stage and write: test_interrupts.py)
    _stage_case(
        "calibrate-workdir-in-use",
        "calibrate",
        ["--init", INIT, "--force"],
        during=lambda p: _held_elsewhere(p["work"]),
        message="in use by",
    ),
    _stage_case(
        "run-workdir-in-use",
        "run",
        ["--force", "--no-matching", "--init", INIT],
        during=lambda p: _held_elsewhere(p["work"]),
        message="in use by",
    ),
    _stage_case(
        "calibrate-full-disk",
        "calibrate",
        ["--init", INIT, "--force"],
        during=lambda p: _full_disk(),
        names=lambda p: "calib.json",
        message="no space left on device",
    ),
    _stage_case(
        "report-full-disk",
        "report",
        [],
        during=lambda p: _full_disk(),
        message="no space left on device",
    ),
    Case(
        "preprocess-full-disk",
        lambda p: ["preprocess", *_plain(p["inputs"]), str(p["tmp"] / "w")],
        names=lambda p: "w",
        during=lambda p: _full_disk(),
        message="no space left on device",
        absent=("w",),
    ),
    # ---- config files and run options
    Case(
        "run-config-missing",
        lambda p: [
            "run",
            *_plain(p["inputs"]),
            str(p["tmp"] / "w"),
            "--config",
            str(p["tmp"] / "job.toml"),
        ],
        names=lambda p: "job.toml",
        absent=("w",),
    ),
    Case(
        "run-config-bad-toml",
        lambda p: [
            "run",
            *_plain(p["inputs"]),
            str(p["tmp"] / "w"),
            "--config",
            str(p["tmp"] / "job.toml"),
        ],
        names=lambda p: "job.toml",
        absent=("w",),
        setup=lambda p: _write(p["tmp"] / "job.toml", "bins = \n"),
    ),
    Case(
        "run-config-bad-yaml",
        lambda p: [
            "run",
            *_plain(p["inputs"]),
            str(p["tmp"] / "w"),
            "--config",
            str(p["tmp"] / "job.yaml"),
        ],
        names=lambda p: "job.yaml",
        absent=("w",),
        setup=lambda p: _write(p["tmp"] / "job.yaml", "a: [\n"),
    ),
    Case(
        "run-config-not-a-table",
        lambda p: [
            "run",
            *_plain(p["inputs"]),
            str(p["tmp"] / "w"),
            "--config",
            str(p["tmp"] / "job.yaml"),
        ],
        names=lambda p: "job.yaml",
        absent=("w",),
        setup=lambda p: _write(p["tmp"] / "job.yaml", "- 1\n- 2\n"),
    ),
    Case(
        "run-config-bins-1",
        lambda p: [
            "run",
            *_plain(p["inputs"]),
            str(p["tmp"] / "w"),
            "--config",
            str(p["tmp"] / "job.toml"),
        ],
        names=lambda p: "job.toml",
        absent=("w",),
        setup=lambda p: _write(p["tmp"] / "job.toml", "[refine]\nbins = 1\n"),
    ),
    Case(
        "run-no-matching-without-init",
        lambda p: ["run", *_plain(p["inputs"]), str(p["tmp"] / "w"), "--no-matching"],
        names=lambda p: "--init",
        absent=("w",),
    ),
    Case(
        "run-over-finished-result",
        lambda p: ["run", *_plain(p["inputs"]), str(p["work"]), "--bins", "8"],
        names=lambda p: "calib.json",
        copy="finished",
        message="--force",
    ),
    Case(
        "run-voxel-negative",
        lambda p: ["run", *_plain(p["inputs"]), str(p["tmp"] / "w"), "--voxel-size", "-1"],
        names=lambda p: "--voxel-size",
        absent=("w",),
    ),
    Case(
        "run-voxel-nan",
        lambda p: ["run", *_plain(p["inputs"]), str(p["tmp"] / "w"), "--voxel-size", "nan"],
        names=lambda p: "--voxel-size",
        absent=("w",),
    ),
    Case(
        "run-frames-missing",
        lambda p: [
            "run",
            "--frames",
            str(p["tmp"] / "frames"),
            str(p["tmp"] / "w"),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
        ],
        names=lambda p: "frames",
        absent=("w",),
    ),
    Case(
        "run-frames-empty",
        lambda p: [
            "run",
            "--frames",
            str(p["tmp"] / "frames"),
            str(p["tmp"] / "w"),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
        ],
        names=lambda p: "frames",
        absent=("w",),
        setup=lambda p: (p["tmp"] / "frames").mkdir(),
    ),
    Case(
        "preprocess-two-workdirs",
        lambda p: [
            "preprocess",
            *_plain(p["inputs"])[:2],
            str(p["tmp"] / "w"),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
            "--voxel-size",
            "0.01",
            "other",
        ],
        names=lambda p: str(p["tmp"] / "w"),
        absent=("w",),
    ),
    Case(
        "preprocess-image-as-workdir",
        lambda p: [
            "preprocess",
            str(p["inputs"] / "points.npy"),
            str(p["inputs"] / "image.png"),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
        ],
        names=lambda p: "image.png",
    ),
    # ---- what works
    Case(
        "works-paths-with-spaces-and-unicode",
        lambda p: [
            "preprocess",
            str(p["sp"] / "points.npy"),
            str(p["sp"] / "image.png"),
            str(p["tmp"] / "wörk dir"),
            "--camera",
            str(p["sp"] / "camera.yaml"),
        ],
        status=0,
        setup=lambda p: p.update(sp=Path(shutil.copytree(p["inputs"], p["tmp"] / "my data ü"))),
    ),
    Case(
        "works-interleaved-workdir",
        lambda p: [
            "preprocess",
            str(p["inputs"] / "points.npy"),
            "--image",
            str(p["inputs"] / "image.png"),
            str(p["tmp"] / "w"),
            "--camera",
            str(p["inputs"] / "camera.yaml"),
        ],
        status=0,
    ),
    Case(
        "works-negative-distortion-space-separated",
        lambda p: [
            "preprocess",
            *_plain(p["inputs"])[:2],
            str(p["tmp"] / "w"),
            "--camera-model",
            "plumb_bob",
            "--intrinsics",
            "300,300,160,120",
            "--distortion",
            "-0.01,0.002,0,0,0",
        ],
        status=0,
    ),
]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(case: Case, base, tmp_path_factory, capsys):
    tmp = Path(tempfile.mkdtemp(dir=base["root"], prefix="case-"))
    tmp.chmod(0o755)
    paths = {**base, "tmp": tmp, "base_cloud": base["cloud"]}
    if case.copy:
        paths["work"] = Path(shutil.copytree(base[case.copy], tmp / "work"))
    if case.setup:
        case.setup(paths)
    argv = case.argv(paths)
    watched = [paths["inputs"], tmp]
    read_only = [paths[k] for k in case.read_only]
    capsys.readouterr()
    with case.during(paths) if case.during else contextlib.nullcontext():
        before = {str(w): _digest(w) for w in watched}
        with _as_unprivileged(read_only) if read_only else contextlib.nullcontext():
            status = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert status == case.status, err
    if case.status == 0:
        return
    lines = [line for line in err.splitlines() if line.strip()]
    errors = [line for line in lines if ": error:" in line]
    assert len(errors) == 1 and lines[-1] == errors[0], err
    if case.names is not None:
        assert case.names(paths) in errors[0], errors[0]
    assert case.message in errors[0], errors[0]
    after = {str(w): _digest(w) for w in watched}
    assert after == before, "the command changed files"
    for key in case.absent:
        assert not (tmp / key).exists(), f"{key} was created"


# ------------------------------------------------------------------------------ nothing stale
RERUNS = {
    "preprocess": lambda p: ["preprocess", *_plain(p["inputs"]), str(p["work"])],
    "find-matches": lambda p: ["find-matches", str(p["work"]), "--matcher", "sift", "--views", "0"],
    "initial-guess": lambda p: ["initial-guess", str(p["work"]), "--manual", str(p["picks"])],
    "calibrate": lambda p: ["calibrate", str(p["work"]), "--init", INIT, "--max-outer", "1"],
}


def _picks(path: Path, cloud: np.ndarray) -> Path:
    """Manual correspondences: 12 cloud points and their true pixels."""
    import json

    from nbcalib.camera import example_camera as camera_of

    camera = camera_of("plumb_bob", 320, 240)
    rows = np.linspace(0, len(cloud) - 1, 12).astype(int)
    p_cam = cloud[rows, :3] @ T_TRUE[:3, :3].T
    uv, _ = camera.project(p_cam.astype(np.float64))
    entries = [
        {"name": "000000", "camera_uv": [float(u), float(v)], "point_lidar": [float(x) for x in q]}
        for (u, v), q in zip(uv, cloud[rows, :3])
    ]
    doc = {"format": "nbcalib-manual-correspondences", "version": 1, "correspondences": entries}
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("stage", sorted(RERUNS))
def test_a_stage_run_again_leaves_nothing_stale(stage, base, tmp_path, capsys):
    """--force replaces a finished result; the report, exports and stored quality go with it."""
    from nbcalib.io.calib_json import read_calib_json

    paths = {**base, "work": Path(shutil.copytree(base["finished"], tmp_path / "work"))}
    paths["picks"] = _picks(tmp_path / "picks.json", base["cloud"])
    argv = RERUNS[stage](paths)
    assert main(argv) == 2  # a finished result is not replaced by accident
    assert "--force" in capsys.readouterr().err
    assert main([*argv, "--force"]) == 0, capsys.readouterr().err
    work = paths["work"]
    assert not (work / "report").exists() and not (work / "export").exists()
    calib = read_calib_json(work / "calib.json")
    assert "quality" not in calib.to_dict().get("nbcalib", {})
    if stage != "calibrate":
        assert not calib.has_result("T_lidar_camera")
    capsys.readouterr()
    # what is left to do is named, with a reason
    assert main(["run", str(work), "--no-report", "--until", "initial-guess"]) in (0, 2)
    err = capsys.readouterr().err
    assert "()" not in err


def test_kernels_compile_where_no_cache_can_be_written(monkeypatch):
    """A read-only install run by a user without a home: no cache, but working kernels."""
    from types import SimpleNamespace

    import numba
    from numba import prange

    from nbcalib.kernels import _jit

    real = numba.njit

    def njit(**options):
        if options.get("cache"):
            raise RuntimeError("cannot cache function 'f': no locator available for file 'x.py'")
        return real(**options)

    monkeypatch.setattr(_jit, "numba", SimpleNamespace(njit=njit))

    def add_one(x):
        return x + 1

    def total(x):
        s = 0.0
        for i in prange(x.size):
            s += x[i]
        return s

    assert _jit.jit(add_one)(1) == 2
    assert _jit.jit_parallel(total)(np.ones(10)) == 10.0
