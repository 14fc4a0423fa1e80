"""Peak resident memory of ``nbcalib run`` against the number of pairs (issue 48).

Per pair count: ``nbcalib synth OUT --lidar livox --camera pinhole --pairs N --format bag2``
(one ROS 2 bag per pair), then ``nbcalib run OUT/pair_* WORK --no-matching --init START`` as a
user types it (``START`` 1 deg / 5 cm from the truth, seeded), under ``/usr/bin/time``: its peak
resident set (the run's own process; numba threads included), its wall time, and the result's
error (``nbcalib evaluate``), so that a change that bounds memory can be shown not to move the
result.

Run one at a time on an idle machine:

    python benchmarks/bench_memory.py --pairs 1,15          # BENCHMARKS (issue 48)
    python benchmarks/bench_memory.py --pairs 15,50 --keep DIR    # keep and reuse the data

Prints a Markdown table and one JSON line.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.transforms import invert_T, offset_pose, pose_to_xyz_quat

#: Seed of the start's direction.
START_SEED = 48


def nbcalib(*args, timed: bool = False) -> tuple[subprocess.CompletedProcess, float | None]:
    """Run ``nbcalib ARGS``; with ``timed``, under ``/usr/bin/time`` (peak RSS in MB)."""
    cmd = [sys.executable, "-m", "nbcalib", *map(str, args)]
    if timed:
        cmd = ["/usr/bin/time", "-f", "MAXRSS_KB %M", *cmd]
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}:\n{run.stderr[-2000:]}")
    peak = None
    if timed:
        line = [w for w in run.stderr.splitlines() if w.startswith("MAXRSS_KB ")][-1]
        peak = int(line.split()[1]) / 1024.0
    return run, peak


def case(pairs: int, args, root: Path) -> dict:
    out, work = root / f"synth_{pairs}", root / f"work_{pairs}"
    if not (out / "ground_truth.json").is_file():
        shutil.rmtree(out, ignore_errors=True)
        nbcalib("synth", out, "--lidar", args.lidar, "--camera", args.camera, "--pairs", pairs,
                "--seed", args.seed, "--format", "bag2")  # fmt: skip
    gt = out / "ground_truth.json"
    start = offset_pose(read_ground_truth(gt), 1.0, 0.05, START_SEED)
    init = ",".join(f"{v:.12g}" for v in pose_to_xyz_quat(invert_T(start)))
    shutil.rmtree(work, ignore_errors=True)
    bags = sorted(out.glob("pair_*"))
    t0 = time.perf_counter()
    _, peak = nbcalib("run", *bags, work, "--no-matching", f"--init={init}", timed=True)
    wall = time.perf_counter() - t0
    ev, _ = nbcalib("evaluate", work, "--ground-truth", gt)
    errors = json.loads(ev.stdout.splitlines()[-1])
    row = {
        "pairs": pairs,
        "peak_mb": round(peak, 1),
        "wall_s": round(wall, 1),
        "cm": round(100 * errors["translation_error_m"], 4),
        "deg": round(errors["rotation_error_deg"], 5),
    }
    print(f"{pairs} pairs: {row}", file=sys.stderr, flush=True)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--pairs", default="1,15", help="pair counts, comma-separated")
    ap.add_argument("--lidar", default="livox")
    ap.add_argument("--camera", default="pinhole")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", type=Path, help="keep the data here (and reuse it)")
    args = ap.parse_args(argv)
    root = args.keep or Path(tempfile.mkdtemp(prefix="nbcalib_memory_"))
    rows = [case(int(n), args, root) for n in args.pairs.split(",")]
    print("| pairs | peak RSS, MB | wall s | result cm / deg |")
    print("|---|---|---|---|")
    for r in rows:
        result = f"{r['cm']:.2f} / {r['deg']:.3f}"
        print(f"| {r['pairs']} | {r['peak_mb']:.0f} | {r['wall_s']} | {result} |")
    print(
        json.dumps({"bench": "memory", "args": vars(args) | {"keep": str(args.keep)}, "rows": rows})
    )
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
