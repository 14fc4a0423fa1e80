"""A real recording calibrated from its frames, on the user's path (issue 45).

Every many-frame set of ``../shared/data/real`` (skipped with a message when absent) is
calibrated with ``nbcalib run --frames DIR --camera FILE WORK`` exactly as a user types it,
then judged with ``nbcalib evaluate`` against the set's reference:

- ``kitti-raw``: KITTI raw 2011-09-26, 20 consecutive frames as a sequence, each pair the
  ``--neighbors 5`` scans around its image (dynamic integration, the cloud at the image time);
- ``kitti-odometry``: KITTI odometry sequence 00, 13 frames of different streets, one scan each;
- ``acfr``: the ACFR Ouster + fisheye recording, 11 poses of one static garage;
- ``waymo``: 5 Waymo frames, the cloud in the vehicle frame (not centred on the LiDAR).

For each set, with 1, 3, 10 or all of its frames (``--pair-count N``: spread evenly over the
recording) and from each start:

- ``auto``: no ``--init``: the automatic guess from the frames' matches;
- ``D:C``: ``--no-matching --init POSE``, the reference turned by exactly D degrees and moved by
  exactly C cm in ``--directions`` seeded directions (:func:`nbcalib.transforms.offset_pose`).

A row: the guess's and the result's error against the reference (camera centre cm / degrees),
the verdict (a refused guess is written afterwards with ``initial-guess --force`` to learn its
error, shown in brackets), the seconds of each stage as ``run`` records them in ``calib.json``
and the wall time of the command. A run that exits with an error is a row with its last line.
With starts ``1:5`` and ``3:20`` both measured, the basin line says how many ``3:20`` runs end
within 0.1 deg / 1 cm of the ``1:5`` run of the same direction.

Run one at a time on an idle machine, warm numba cache:

    python benchmarks/bench_real_frames.py                                   # every set, auto
    python benchmarks/bench_real_frames.py --sets kitti-odometry --frames 10 --starts 1:5,3:20 \
        --directions 5                                                       # the basin
    python benchmarks/bench_real_frames.py --run-args "--no-report"

Prints one Markdown table, then one JSON line with every run.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
STAGES = ("preprocess", "find-matches", "initial-guess", "calibrate", "report")
#: A result this close to the 1 deg / 5 cm run's counts as the same end (the basin target).
SAME_END = (1.0, 0.1)  # cm, deg


def sets(data: Path) -> dict[str, dict]:
    """name -> (frames folder, camera file, reference file, extra run options, frame count)."""
    kitti = data / "kitti_raw_2011_09_26"
    kcal = kitti / "calib" / "calib_normalized_cam2rect.json"
    odo = data / "kitti_odometry_claim"
    acfr = data / "acfr_os64_fisheye" / "2022-11-09_00-54-42"
    waymo = data / "waymo_claim"
    return {
        "kitti-raw": dict(folder=kitti, camera=kcal, reference=kcal, options=["--neighbors", "5"]),
        "kitti-odometry": dict(folder=odo, camera=odo / "000000" / "calib_normalized.json"),
        "acfr": dict(folder=acfr, camera=acfr / "pose1" / "calib_normalized.json"),
        "waymo": dict(folder=waymo, camera=waymo / "00000" / "calib_normalized.json"),
    }


def frame_count(folder: Path) -> int:
    """Frames of a folder as ``--frames`` reads it: subfolders holding an image."""
    return sum(1 for f in folder.iterdir() if f.is_dir() and any(f.glob("*.png")))


def nbcalib(*args) -> subprocess.CompletedProcess:
    """``python -m nbcalib ARGS`` as a user types it."""
    return subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True
    )


def reference_pose(path: Path) -> np.ndarray:
    from nbcalib.io.ground_truth import read_ground_truth

    return read_ground_truth(path)


def start_values(T_ref: np.ndarray, angle_deg: float, distance_m: float, seed: int) -> str:
    """``--init`` values of the reference turned and moved by exactly the given amounts."""
    from nbcalib.transforms import invert_T, offset_pose, pose_to_xyz_quat

    T = offset_pose(T_ref, angle_deg, distance_m, np.random.default_rng([seed, 45]))
    return ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T)))


def evaluate(work: Path, reference: Path, stage: str) -> tuple[float, float] | None:
    ev = nbcalib("evaluate", work, "--ground-truth", reference, "--stage", stage)
    if ev.returncode != 0:
        return None
    e = json.loads(ev.stdout.strip().splitlines()[-1])
    return round(100 * e["translation_error_m"], 3), round(e["rotation_error_deg"], 4)


def run_job(spec: dict, frames: int | None, start: str, direction: int, work: Path, args) -> dict:
    shutil.rmtree(work, ignore_errors=True)  # a failed run must not report the last one's figures
    options = ["--frames", spec["folder"], "--camera", spec["camera"], *spec.get("options", [])]
    if frames is not None:
        options += ["--pair-count", frames]
    if start != "auto":
        deg, cm = (float(v) for v in start.split(":"))
        T_ref = reference_pose(spec.get("reference", spec["camera"]))
        init = start_values(T_ref, deg, cm / 100.0, args.seed + direction)
        options += ["--no-matching", "--init", init]
    options += shlex.split(args.run_args)
    t0 = time.perf_counter()
    run = nbcalib("run", *options, work)
    wall = time.perf_counter() - t0
    row = {"exit": run.returncode, "wall_s": round(wall, 1), "verdict": None}
    if run.returncode != 0:
        row["error"] = (run.stderr.strip().splitlines() or [""])[-1][:400]
    calib = work / "calib.json"
    info = json.loads(calib.read_text()).get("nbcalib", {}) if calib.is_file() else {}
    row["seconds"] = {s: info.get("seconds", {}).get(s) for s in STAGES}
    row["verdict"] = (info.get("quality") or {}).get("verdict")
    row["reasons"] = (info.get("quality") or {}).get("reasons")
    reference = spec.get("reference", spec["camera"])
    if start == "auto":
        row["guess"] = evaluate(work, reference, "init_T_lidar_camera_auto")
        if row["guess"] is None and (work / "calib.json").is_file():
            # a refused guess: written anyway (initial-guess --force) to learn how far off it was
            if nbcalib("initial-guess", work, "--force", "-q").returncode == 0:
                row["refused_guess"] = evaluate(work, reference, "init_T_lidar_camera_auto")
    row["result"] = evaluate(work, reference, "T_lidar_camera") if run.returncode == 0 else None
    if row["result"] is not None:
        row["result_T_lidar_camera"] = json.loads(calib.read_text())["results"]["T_lidar_camera"]
    row["intrinsics"] = intrinsics_figures(info)
    return row


def intrinsics_figures(info: dict) -> dict:
    """The refined intrinsics (``--refine-intrinsics``) and the report's check, when present."""
    out = {}
    refined = (info.get("calibration") or {}).get("intrinsics")
    if refined:
        keys = ("refined", "reason", "focal_scale", "center_shift_px", "focal_bound_percent",
                "center_bound_px", "correlation_focal_forward")  # fmt: skip
        out["refinement"] = {k: refined.get(k) for k in keys}
        out["pose_only_T_lidar_camera"] = refined.get("pose_only_T_lidar_camera")
    check = (info.get("quality") or {}).get("intrinsics_check")
    if check:
        out["check"] = check
    return out


def _error(e) -> str:
    return "-" if e is None else f"{e[0]:.2f} / {e[1]:.3f}"


def _guess(row) -> str:
    if row.get("refused_guess") is not None:
        return f"refused ({_error(row['refused_guess'])})"
    return _error(row.get("guess"))


def _seconds(row) -> str:
    s = row["seconds"]
    return " | ".join("-" if s[k] is None else f"{s[k]:.1f}" for k in STAGES)


def basin_lines(rows) -> list[str]:
    """Per set and frame count: ``3:20`` runs within 1 cm / 0.1 deg of the ``1:5`` run."""
    from nbcalib.transforms import pose_error, pose_from_xyz_quat

    lines = []
    keys = sorted({(r["set"], r["frames"]) for r in rows})
    for name, frames in keys:
        of = [r for r in rows if (r["set"], r["frames"]) == (name, frames)]
        near = {r["direction"]: r for r in of if r["start"] == "1:5"}
        for far_start in sorted({r["start"] for r in rows} - {"auto", "1:5"}):
            far = [r for r in of if r["start"] == far_start]
            same = 0
            for r in far:
                n = near.get(r["direction"]) or next(iter(near.values()), None)
                if (
                    n is None
                    or "result_T_lidar_camera" not in r
                    or "result_T_lidar_camera" not in n
                ):
                    continue
                dt, dr = pose_error(
                    pose_from_xyz_quat(r["result_T_lidar_camera"]),
                    pose_from_xyz_quat(n["result_T_lidar_camera"]),
                )
                r["from_near_end"] = (round(100 * dt, 3), round(dr, 4))
                same += 100 * dt <= SAME_END[0] and dr <= SAME_END[1]
            if near and far:
                lines.append(
                    f"{name}, {frames} frames: from {far_start.replace(':', ' deg / ')} cm, "
                    f"{same} of {len(far)} runs end within {SAME_END[0]:g} cm / {SAME_END[1]:g} "
                    f"deg of the run from 1 deg / 5 cm"
                )
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--sets", default="kitti-raw,kitti-odometry,acfr,waymo")
    ap.add_argument("--frames", default="all", help="frame counts: 1,3,10,all (default all)")
    ap.add_argument("--starts", default="auto", help="auto and/or DEG:CM starts (1:5,2:10,3:20)")
    ap.add_argument("--directions", type=int, default=1, help="seeded directions per DEG:CM")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--run-args", default="", help="options added to every nbcalib run")
    ap.add_argument("--keep", type=Path, help="keep the work directories here")
    args = ap.parse_args(argv)
    if not args.data.is_dir():
        print(f"no real data at {args.data}: nothing to measure", file=sys.stderr)
        return 0
    specs = sets(args.data)
    names = [s for s in args.sets.split(",") if s]
    unknown = sorted(set(names) - set(specs))
    if unknown:
        ap.error(f"unknown set(s) {', '.join(unknown)}; known: {', '.join(specs)}")
    starts = [s for s in args.starts.split(",") if s]
    root = Path(args.keep or tempfile.mkdtemp(prefix="nbcalib_real_frames_"))
    rows = []
    print(
        "| set | frames | start | guess cm / deg | result cm / deg | verdict | "
        + " | ".join(STAGES)
        + " | wall s |"
    )
    print("|---" * (len(STAGES) + 7) + "|")
    for name in names:
        spec = specs[name]
        if not spec["folder"].is_dir():
            print(f"{name}: {spec['folder']} absent, skipped", file=sys.stderr)
            continue
        total = frame_count(spec["folder"])
        for count in args.frames.split(","):
            frames = None if count == "all" or int(count) >= total else int(count)
            n = total if frames is None else frames
            for start in starts:
                for direction in range(1 if start == "auto" else args.directions):
                    work = root / f"{name}_{n}_{start.replace(':', '-')}_{direction}"
                    row = run_job(spec, frames, start, direction, work, args)
                    row.update(set=name, frames=n, start=start, direction=direction)
                    rows.append(row)
                    verdict = row["verdict"] or f"exit {row['exit']}"
                    print(
                        f"| {name} | {n} | {start} | {_guess(row)} | "
                        f"{_error(row['result'])} | {verdict} | {_seconds(row)} | "
                        f"{row['wall_s']:.1f} |",
                        flush=True,
                    )
                    if row.get("error"):
                        print(f"    {row['error']}", file=sys.stderr, flush=True)
                    if row["intrinsics"]:
                        print(f"    {json.dumps(row['intrinsics'])}", file=sys.stderr, flush=True)
    for line in basin_lines(rows):
        print(line)
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    machine = {
        "machine": platform.processor() or platform.machine(),
        "python": sys.version.split()[0],
    }
    print(json.dumps({"bench": "real_frames", **machine, "run_args": args.run_args, "runs": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
