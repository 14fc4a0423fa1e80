"""The automatic initial guess on real data: ``nbcalib run`` with no ``--init``, as typed.

The sets are those of ``bench_real.py`` (its ``sets()``: the same command lines), plus the three
bags:

- **a** one scan + its image: KITTI frames 0, 5, 10, 15 and both PJLab frames;
- **b** single shot: one KITTI image + the 10 scans around it, cloud at the image time; images 0,
  5, 10, 15;
- **bags** the ROS 1, ROS 2 (sqlite3) and mcap bags of KITTI frames 0-4 (``nbcalib run BAG``);
- **c** (only with ``--protocols`` holding c) five KITTI pairs via ``--frames``.

Per set: ``nbcalib run INPUTS WORK`` (every stage, no start given), then ``nbcalib evaluate`` of
the initial guess and of the final result against the reference calibration. A guess that
failed its success test is not written by ``run``; it is written afterwards with ``nbcalib
initial-guess WORK --force`` to learn its error (a good guess refused counts against the test).
A guess within the paper's criterion is < 1 deg and < 0.5 m; a guess outside it that passed the
test is a *false ok*. Seconds: matching + initial guess, from ``calib.json``.

Run:  python benchmarks/bench_real_auto.py [--protocols ab] [--bags/--no-bags] [--run-args "..."]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_real import DATA, KITTI, KITTI_CALIB, PJLAB, sets

from nbcalib.io.ground_truth import read_ground_truth

BAGS = (
    "kitti_2011_09_26_udacity_5frames.bag",
    "kitti_2011_09_26_udacity_5frames_db3",
    "kitti_2011_09_26_udacity_5frames_mcap",
)
GUESS_DEG, GUESS_M = 1.0, 0.5


def nbcalib(*args) -> subprocess.CompletedProcess:
    """``python -m nbcalib ARGS`` as a user types it."""
    return subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True
    )


def evaluate(work: Path, truth: Path, stage: str) -> dict | None:
    run = nbcalib("evaluate", work, "--ground-truth", truth, "--stage", stage)
    if run.returncode != 0:
        return None
    return json.loads(run.stdout.strip().splitlines()[-1])


def all_sets(data: Path, tmp: Path, args):
    yield from sets(data, tmp, args)
    if args.bags:
        for name in BAGS:
            yield (
                "bag",
                name.split("5frames")[-1].lstrip("_.") or "bag",
                [
                    data / "bags" / name,
                    None,
                ],
                data / KITTI / KITTI_CALIB,
            )


def run_set(protocol, name, pre, calib: Path, tmp: Path, args) -> dict:
    work = tmp / "work"
    if work.exists():
        shutil.rmtree(work)
    if None in pre:  # positional inputs, then the work directory, then options
        k = pre.index(None)
        command = [*pre[:k], work, *pre[k + 1 :]]
    else:
        command = [work, *pre]
    truth = tmp / "reference.json"
    truth.write_text(json.dumps({"T_camera_lidar": read_ground_truth(calib).tolist()}))
    t0 = time.perf_counter()
    run = nbcalib("run", *command, *shlex.split(args.run_args))
    wall = time.perf_counter() - t0
    calib_json = work / "calib.json"
    info = json.loads(calib_json.read_text()).get("nbcalib", {}) if calib_json.is_file() else {}
    record = (info.get("initial_guess") or {}).get("init_T_lidar_camera_auto") or {}
    flagged = bool(record.get("success", False))
    if not record and calib_json.is_file():
        nbcalib("initial-guess", work, "--force")
    guess = evaluate(work, truth, "init_T_lidar_camera_auto")
    final = evaluate(work, truth, "T_lidar_camera") if run.returncode == 0 else None
    seconds = info.get("seconds", {})
    attempts = []
    for path in sorted(work.glob("*_matches.json")):
        doc = json.loads(path.read_text())
        attempts.append((doc.get("nbcalib") or {}).get("kept_attempt"))
    row = {
        "protocol": protocol,
        "set": name,
        "exit": run.returncode,
        "error": "" if run.returncode == 0 else run.stderr.strip().splitlines()[-1][:300],
        "flagged_ok": flagged,
        "guess_cm": None if guess is None else 100 * guess["translation_error_m"],
        "guess_deg": None if guess is None else guess["rotation_error_deg"],
        "final_cm": None if final is None else 100 * final["translation_error_m"],
        "final_deg": None if final is None else final["rotation_error_deg"],
        "verdict": (info.get("quality") or {}).get("verdict"),
        "guess_s": round(seconds.get("find-matches", 0) + seconds.get("initial-guess", 0), 1),
        "run_s": round(wall, 1),
        "kept_attempts": attempts,
    }
    row["guess_within"] = guess is not None and (
        guess["rotation_error_deg"] < GUESS_DEG and guess["translation_error_m"] < GUESS_M
    )
    row["false_ok"] = flagged and not row["guess_within"]
    return row


def _f(value, digits):
    return "n/a" if value is None else f"{value:.{digits}f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--protocols", default="ab", help="any of a, b, c (default: ab)")
    ap.add_argument("--no-bags", dest="bags", action="store_false")
    ap.add_argument("--run-args", default="", help="options for every run")
    ap.add_argument("--neighbors", type=int, default=10)
    ap.add_argument("--image-offset", type=float, default=0.05)
    args = ap.parse_args(argv)
    if not (args.data / KITTI).is_dir():
        print(f"real data not found at {args.data}: nothing to measure", file=sys.stderr)
        return 0
    # the sets of bench_real.py, with a fourth single-shot image
    args.single_frames, args.pjlab, args.shot_images = [0, 5, 10, 15], list(PJLAB), [0, 5, 10, 15]
    args.multi = [list(range(5))]
    args.preprocess_args = ""
    print(f"nbcalib run, no --init; run options: {args.run_args or '(defaults)'}")
    print(
        "| set | guess cm / deg | within 1 deg / 0.5 m | flagged | final cm / deg | verdict | "
        "guess s | run s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_real_auto_") as tmp:
        for protocol, name, pre, calib in all_sets(args.data, Path(tmp), args):
            row = run_set(protocol, name, pre, calib, Path(tmp), args)
            rows.append(row)
            print(
                f"| ({protocol}) {name} | {_f(row['guess_cm'], 1)} / {_f(row['guess_deg'], 2)} | "
                f"{'yes' if row['guess_within'] else 'NO'} | "
                f"{'ok' if row['flagged_ok'] else 'failed'} | {_f(row['final_cm'], 1)} / "
                f"{_f(row['final_deg'], 2)} | {row['verdict'] or '-'} | {row['guess_s']} | "
                f"{row['run_s']} |",
                flush=True,
            )
    summary = {
        "sets": len(rows),
        "guess_within": sum(r["guess_within"] for r in rows),
        "flagged_ok": sum(r["flagged_ok"] for r in rows),
        "false_ok": sum(r["false_ok"] for r in rows),
        "refused_good": sum(r["guess_within"] and not r["flagged_ok"] for r in rows),
        "guess_s_max": max(r["guess_s"] for r in rows),
    }
    print(
        f"\nguess within 1 deg / 0.5 m: {summary['guess_within']}/{len(rows)}; flagged ok "
        f"{summary['flagged_ok']} ({summary['false_ok']} false ok, {summary['refused_good']} good "
        f"ones refused); slowest guess {summary['guess_s_max']} s"
    )
    load = Path("/proc/loadavg").read_text().split()[:3] if os.path.exists("/proc/loadavg") else []
    print(
        json.dumps(
            {
                "benchmark": "real_auto",
                "run_args": args.run_args,
                "machine": platform.processor() or platform.machine(),
                "load": load,
                "summary": summary,
                "runs": rows,
            }
        )
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
