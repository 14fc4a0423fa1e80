"""Several cameras on the user's path: one ``nbcalib run`` of a camera ring, and one per camera.

For each seed: ``nbcalib synth OUT --cameras pinhole,fisheye,fisheye --format bag2 --seed S``
(front pinhole 1280 x 960, two side fisheyes at 1024 x 768; every other option at its
default), then, each timed as a whole command:

- **alone**: ``nbcalib run OUT/pair_000 WORK_k --image-topic /camk/image --camera-info-topic
  /camk/camera_info`` for each camera, one after the other (three separate runs);
- **ring**: ``nbcalib run OUT/pair_000 WORK`` (every camera, each on its own);
- **rig**: ``nbcalib run OUT/pair_000 WORK --rig RIG`` with the true camera-to-camera
  extrinsics written as an nbcalib rig file (one rig pose from every camera);

and ``nbcalib evaluate`` of each work directory against ``OUT/ground_truth.json``.

Run it alone on an idle machine (warm numba cache):

    python benchmarks/bench_rig.py                       # seed 0, spinning64
    python benchmarks/bench_rig.py --seeds 0 1 --lidar livox
    python benchmarks/bench_rig.py --from-truth [--without motion]

``--from-truth`` measures where the error comes from instead (in this process, no timing):
fine registration started at the truth of each camera alone and of the rig jointly (every
camera's pairs through the true rig), and how far the preprocessed dense cloud sits from the
simulation's true cloud (point-to-point ICP of 200 000 of its points).

The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CAMERAS = "pinhole,fisheye,fisheye"


def nbcalib(*args) -> tuple[subprocess.CompletedProcess, float]:
    """``python -m nbcalib ARGS`` as a user types it, and its wall time."""
    t0 = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True
    )
    if done.returncode not in (0, 3):
        raise SystemExit(f"nbcalib {' '.join(map(str, args))} failed:\n{done.stderr[-2000:]}")
    return done, time.perf_counter() - t0


def evaluate(work: Path, truth: Path) -> list[dict]:
    done, _ = nbcalib("evaluate", work, "--ground-truth", truth)
    return [json.loads(line) for line in done.stdout.splitlines() if line.strip()]


def write_rig(truth: Path, path: Path) -> None:
    """The true camera-to-camera extrinsics as an nbcalib rig file."""
    from nbcalib.io.camera_file import load_camera
    from nbcalib.io.rig import Rig, RigCamera, save_rig
    from nbcalib.transforms import invert_T, pose_from_xyz_quat

    doc = json.loads(truth.read_text())
    cameras = []
    for entry in doc["cameras"]:
        camera = load_camera(truth.parent / entry["name"] / "camera.yaml")
        T_cam0_cam = pose_from_xyz_quat(entry["T_cam0_camera"])
        topic = entry["topics"]["image"]
        cameras.append(RigCamera(entry["name"], camera, invert_T(T_cam0_cam), topic))
    save_rig(path, Rig(tuple(cameras)))


def one_seed(root: Path, lidar: str, seed: int) -> dict:
    out = root / f"data_{lidar}_{seed}"
    nbcalib("synth", out, "--cameras", CAMERAS, "--lidar", lidar, "--seed", seed,
            "--format", "bag2", "-q")  # fmt: skip
    bag, truth = out / "pair_000", out / "ground_truth.json"
    names = [c["name"] for c in json.loads(truth.read_text())["cameras"]]
    figures: dict = {"seed": seed, "lidar": lidar, "alone": {}, "seconds": {}}
    alone_seconds = 0.0
    for name in names:
        work = root / f"alone_{lidar}_{seed}_{name}"
        _, seconds = nbcalib("run", bag, work, "--image-topic", f"/{name}/image",
                             "--camera-info-topic", f"/{name}/camera_info", "-q")  # fmt: skip
        alone_seconds += seconds
        figures["alone"][name] = {"seconds": round(seconds, 1), **_camera_errors(work, truth, name)}
    figures["seconds"]["alone"] = round(alone_seconds, 1)
    write_rig(truth, root / f"rig_{lidar}_{seed}.yaml")
    for mode, extra in (("ring", ()), ("rig", ("--rig", root / f"rig_{lidar}_{seed}.yaml"))):
        work = root / f"{mode}_{lidar}_{seed}"
        _, seconds = nbcalib("run", bag, work, *extra, "-q")
        figures["seconds"][mode] = round(seconds, 1)
        lines = evaluate(work, truth)
        figures[mode] = {x.get("camera", "rig"): _errors(x) for x in lines}
    return figures


def _errors(line: dict) -> dict:
    return {
        "cm": round(100 * line["translation_error_m"], 3),
        "deg": round(line["rotation_error_deg"], 4),
    }


def _camera_errors(work: Path, truth: Path, name: str) -> dict:
    """One camera's errors against its entry of a ring's ground truth."""
    doc = json.loads(truth.read_text())
    entry = next(c for c in doc["cameras"] if c["name"] == name)
    one = work.parent / f"{work.name}_truth.json"
    one.write_text(json.dumps({"T_lidar_camera": entry["T_lidar_camera"]}))
    (line,) = evaluate(work, one)
    return _errors(line)


def from_truth(root: Path, lidar: str, seed: int, without: str | None) -> dict:
    """Registration started at the truth (each camera, the rig) and the dense cloud's offset."""
    from dataclasses import replace

    import numpy as np
    from scipy.spatial import cKDTree

    from nbcalib.config import CalibrationConfig
    from nbcalib.preprocess.inputs import InputSpec
    from nbcalib.registration.refine import refine
    from nbcalib.rig_pipeline import RigCalibrator, find_cameras
    from nbcalib.synthetic import RigConfig
    from nbcalib.synthetic.rig import generate_ring
    from nbcalib.transforms import invert_T, pose_error, pose_from_xyz_quat, so3_log

    out = root / f"data_{lidar}_{seed}{'_without_' + without if without else ''}"
    extra = ["--without", without] if without else []
    nbcalib("synth", out, "--cameras", CAMERAS, "--lidar", lidar, "--seed", seed,
            "--format", "bag2", "-q", *extra)  # fmt: skip
    doc = json.loads((out / "ground_truth.json").read_text())
    truth = {c["name"]: invert_T(pose_from_xyz_quat(c["T_lidar_camera"])) for c in doc["cameras"]}
    config = CalibrationConfig()
    spec = InputSpec(inputs=(str(out / "pair_000"),))
    job = RigCalibrator(config)
    job.run(spec, find_cameras(spec, config.preprocess), until="preprocess")
    pairs = {name: c._registration_pairs() for name, c in job.calibrators.items()}

    def error(T, name):
        dt, dr = pose_error(invert_T(T), invert_T(truth[name]))
        return {"cm": round(100 * dt, 3), "deg": round(dr, 4)}

    figures = {"seed": seed, "lidar": lidar, "without": without, "alone": {}}
    for name in truth:
        figures["alone"][name] = error(
            refine(pairs[name], truth[name], config.refine).T_camera_lidar, name
        )
    ref, others = "cam0", []
    for name in truth:
        if name != ref:
            T = truth[name] @ invert_T(truth[ref])
            others += [replace(p, name=f"{name}/{p.name}", T_camera_rig=T, classes=None)
                       for p in pairs[name]]  # fmt: skip
    joint = refine(pairs[ref] + others, truth[ref], config.refine)
    figures["joint"] = error(joint.T_camera_lidar, ref)
    # the dense cloud against the simulation's own (the LiDAR frame at time 0)
    config_ring = RigConfig(lidar=lidar, seed=seed, cameras=tuple(CAMERAS.split(",")),
                            without=tuple(without.split(",")) if without else ())  # fmt: skip
    true_points, _ = generate_ring(config_ring)[0].dense_cloud()
    cloud = pairs[ref][0].points_lidar
    rng = np.random.default_rng(0)
    source = cloud[rng.choice(len(cloud), min(200_000, len(cloud)), replace=False)]
    tree, R, t = cKDTree(true_points), np.eye(3), np.zeros(3)
    for _ in range(30):
        moved = source @ R.T + t
        d, idx = tree.query(moved)
        keep = d < 0.05
        a, b = moved[keep], true_points[idx[keep]]
        U, _, Vt = np.linalg.svd((a - a.mean(0)).T @ (b - b.mean(0)))
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        dR = Vt.T @ D @ U.T
        R, t = dR @ R, dR @ t + b.mean(0) - dR @ a.mean(0)
    figures["cloud_offset"] = {
        "cm": [round(float(v), 3) for v in 100 * t],
        "deg": [round(float(v), 4) for v in np.degrees(so3_log(R))],
    }
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0])
    parser.add_argument("--lidar", default="spinning64")
    parser.add_argument("--keep", type=Path, default=None, help="keep the data and work here")
    parser.add_argument("--from-truth", action="store_true", help="where the error comes from")
    parser.add_argument("--without", default=None, help="with --from-truth: synth's --without")
    args = parser.parse_args()
    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_rig_"))
    root.mkdir(parents=True, exist_ok=True)
    rows = []
    if args.from_truth:
        for seed in args.seeds:
            figures = from_truth(root, args.lidar, seed, args.without)
            rows.append(figures)
            print(f"seed {seed} ({args.lidar}, without {args.without}): from the truth, alone "
                  f"{figures['alone']}, joint {figures['joint']}; dense cloud offset "
                  f"{figures['cloud_offset']}", flush=True)  # fmt: skip
        print(json.dumps({"cameras": CAMERAS, "from_truth": rows}))
        return
    for seed in args.seeds:
        figures = one_seed(root, args.lidar, seed)
        rows.append(figures)
        print(f"seed {seed} ({args.lidar}): seconds alone (3 runs) {figures['seconds']['alone']}, "
              f"ring {figures['seconds']['ring']}, rig {figures['seconds']['rig']}")  # fmt: skip
        for name in figures["alone"]:
            a, r, g = figures["alone"][name], figures["ring"][name], figures["rig"][name]
            print(f"  {name}: alone {a['cm']:.2f} cm {a['deg']:.3f} deg | ring {r['cm']:.2f} cm "
                  f"{r['deg']:.3f} deg | rig {g['cm']:.2f} cm {g['deg']:.3f} deg")  # fmt: skip
        print(f"  rig pose: {figures['rig']['rig']}")
        sys.stdout.flush()
    print(json.dumps({"cameras": CAMERAS, "rows": rows}))


if __name__ == "__main__":
    main()
