"""`nbcalib run` then `nbcalib evaluate` on the real data of ../shared/data/real (issue 7).

Every stage runs as a user would run it from the command line, once per input:

- KITTI raw frame 0 as plain files (one HDL-64E scan + the rectified camera image, pinhole);
- the same frames 0-4 as a ROS1 bag, a ROS2 sqlite3 bag and a ROS2 mcap bag (camera from
  CameraInfo);
- the two PJLab frames (distorted plumb_bob camera).

The automatic initial guess fails on these frames (docs/BENCHMARKS.md, "Matching against
camera-shaped LiDAR views"), so every run also gets `--init`: the reference extrinsic perturbed
by 1 degree and 5 cm in a seeded random direction, which `run` uses only when the automatic
guess fails (and says so). The error of the final result is measured with `nbcalib evaluate`
against the reference.

Run:  python benchmarks/bench_real_pipeline.py [--data ../shared/data/real] [--matcher M]
The last line printed is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nbcalib.transforms import invert_T, pose_to_xyz_quat, se3_exp

HERE = Path(__file__).resolve().parent


def perturbed(T_camera_lidar: np.ndarray, seed: int) -> np.ndarray:
    """The pose moved by exactly 1 degree and 5 cm in seeded random directions."""
    rng = np.random.default_rng(seed)
    v, w = rng.normal(size=3), rng.normal(size=3)
    delta = np.concatenate([0.05 * v / np.linalg.norm(v), np.radians(1.0) * w / np.linalg.norm(w)])
    return se3_exp(delta) @ T_camera_lidar


def ground_truth_file(folder: Path, T_camera_lidar: np.ndarray) -> Path:
    path = folder / "ground_truth.json"
    path.write_text(
        json.dumps(
            {
                "T_lidar_camera": [float(x) for x in pose_to_xyz_quat(invert_T(T_camera_lidar))],
                "T_camera_lidar": T_camera_lidar.tolist(),
            }
        )
    )
    return path


def cases(data: Path):
    kitti = data / "kitti_raw_2011_09_26"
    k = json.loads((kitti / "calib" / "calib_normalized_cam2rect.json").read_text())
    K = np.array(k["K"])
    pinhole = ["--camera-model", "pinhole", f"--intrinsics={K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}"]
    frame = kitti / "0000000000"
    yield (
        "kitti frame 0 (files)",
        ["--points", str(frame / "velodyne.bin"), "--image", str(frame / "image_02.png"), *pinhole],
        np.array(k["T_cam_lidar"]),
    )
    bags = data / "bags"
    for label, bag in (
        ("kitti frames 0-4 (ROS1 bag)", bags / "kitti_2011_09_26_udacity_5frames.bag"),
        ("kitti frames 0-4 (ROS2 sqlite3)", bags / "kitti_2011_09_26_udacity_5frames_db3"),
        ("kitti frames 0-4 (ROS2 mcap)", bags / "kitti_2011_09_26_udacity_5frames_mcap"),
    ):
        yield label, [str(bag)], np.array(k["T_cam_lidar"])
    for name in ("auto_calib", "manual_calib_0"):
        folder = data / "pjlab" / name
        c = json.loads(next(folder.glob("calib_normalized*.json")).read_text())
        K, d = np.array(c["K"]), c["dist"]
        yield (
            f"pjlab {name}",
            [
                "--points",
                str(folder / "lidar.pcd"),
                "--image",
                str(folder / "image.png"),
                "--camera-model",
                "plumb_bob",
                f"--intrinsics={K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}",
                f"--distortion={','.join(str(x) for x in d)}",
            ],
            np.array(c["T_cam_lidar"]),
        )


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--data", type=Path, default=HERE.parent.parent / "shared" / "data" / "real")
    ap.add_argument("--matcher", default="auto")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if not args.data.is_dir():
        sys.exit(f"{args.data}: no real data here (see ../shared/data/real/README.md)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, (label, inputs, T_ref) in enumerate(cases(args.data)):
            folder = Path(tmp) / f"case{i}"
            folder.mkdir()
            truth = ground_truth_file(folder, T_ref)
            init = pose_to_xyz_quat(invert_T(perturbed(T_ref, args.seed + i)))
            work = folder / "work"
            cmd = [
                sys.executable,
                "-m",
                "nbcalib",
                "run",
                *inputs,
                str(work),
                f"--init={','.join(f'{x:.9f}' for x in init)}",
                "--matcher",
                args.matcher,
            ]
            t0, c0 = time.perf_counter(), os.times()
            run = subprocess.run(cmd, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            c1 = os.times()
            cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
            log = run.stdout + run.stderr
            row = {"case": label, "exit": run.returncode, "wall_s": round(wall, 1)}
            row["cpu_s"] = round(cpu, 1)
            row["auto_guess_used"] = (
                "calibrating from --init instead" not in log and "start: --init" not in log
            )
            verdict = [line for line in log.splitlines() if line.startswith("verdict:")]
            row["verdict"] = verdict[-1].split(":", 1)[1].strip() if verdict else None
            if run.returncode == 0:
                ev = subprocess.run(
                    [
                        sys.executable,
                        "-m",
                        "nbcalib",
                        "evaluate",
                        str(work),
                        "--ground-truth",
                        str(truth),
                    ],
                    capture_output=True,
                    text=True,
                )
                row.update(json.loads(ev.stdout.strip().splitlines()[-1]))
            else:
                row["error"] = log.strip().splitlines()[-1] if log.strip() else ""
            rows.append(row)
            print(json.dumps(row), flush=True)
    print("| input | exit | start | final error | verdict | wall s | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        err = (
            f"{100 * r['translation_error_m']:.1f} cm / {r['rotation_error_deg']:.2f} deg"
            if "translation_error_m" in r
            else r.get("error", "")
        )
        start = "automatic guess" if r["auto_guess_used"] else "--init (1 deg / 5 cm off)"
        print(
            f"| {r['case']} | {r['exit']} | {start} | {err} | {r['verdict']} | {r['wall_s']} "
            f"| {r['cpu_s']} |"
        )
    print(json.dumps({"cases": rows}))


if __name__ == "__main__":
    main()
