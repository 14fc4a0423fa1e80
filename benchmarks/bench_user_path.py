"""The whole job on the user's path: ``nbcalib run`` on synthetic bags, every stage timed.

For each LiDAR x camera combination: ``nbcalib synth OUT --lidar L --camera C --pairs N
--format bag1 --seed S`` (every other option at its default), then ``nbcalib run
OUT/pair_000.bag ... WORK`` exactly as a user types it (no ``--init``: the automatic guess),
then ``nbcalib evaluate`` of the result against ``OUT/ground_truth.json``. The seconds of each
stage are the ones ``run`` writes to ``calib.json`` (``nbcalib.seconds``); wall is the whole
command, interpreter start-up included.

warm: the numba cache already holds every kernel (a first run of the same combination fills
it and is not counted; ``--no-warmup`` skips that run when an earlier one has filled it).
cold: an empty cache (``NUMBA_CACHE_DIR`` set to a new folder), as on a fresh install, the
background warm-up of ``nbcalib run`` included.

Run one job at a time on an idle machine:

    python benchmarks/bench_user_path.py                        # 1 pair, the 5 combinations
    python benchmarks/bench_user_path.py --pairs 15 --combos livox:pinhole --no-warmup
    python benchmarks/bench_user_path.py --cold --combos spinning64:fisheye

The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The paper's four combinations (spinning / non-repetitive x pinhole / omnidirectional) and a
#: fisheye camera.
DEFAULT_COMBOS = (
    "spinning64:pinhole",
    "spinning64:omnidir",
    "livox:pinhole",
    "livox:omnidir",
    "livox:fisheye",
)
STAGES = ("preprocess", "find-matches", "initial-guess", "calibrate", "report")


def nbcalib(*args, env=None) -> subprocess.CompletedProcess:
    """``python -m nbcalib ARGS`` as a user types it."""
    return subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True, env=env
    )


def synthesise(out: Path, lidar: str, camera: str, pairs: int, seed: int) -> list[Path]:
    made = nbcalib(
        "synth", out, "--lidar", lidar, "--camera", camera, "--pairs", pairs, "--seed", seed,
        "--format", "bag1", "-q",
    )  # fmt: skip
    if made.returncode != 0:
        raise RuntimeError(f"synth failed: {made.stderr.strip()[-600:]}")
    return sorted(out.glob("pair_*.bag"))


def run_job(bags: list[Path], work: Path, truth: Path, env, extra=()) -> dict:
    shutil.rmtree(work, ignore_errors=True)  # a failed run must not report the last one's figures
    t0 = time.perf_counter()
    run = nbcalib("run", *bags, work, "--force", *extra, env=env)
    wall = time.perf_counter() - t0
    row = {"exit": run.returncode, "wall_s": round(wall, 1)}
    row.update(seconds=dict.fromkeys(STAGES), verdict=None)
    if run.returncode != 0:
        row["error"] = (run.stderr.strip().splitlines() or [""])[-1][:300]
        return row
    calib_path = work / "calib.json"
    info = json.loads(calib_path.read_text()).get("nbcalib", {}) if calib_path.is_file() else {}
    row["seconds"] = {s: info.get("seconds", {}).get(s) for s in STAGES}
    row["verdict"] = (info.get("quality") or {}).get("verdict")
    ev = nbcalib("evaluate", work, "--ground-truth", truth, "--stage", "T_lidar_camera", env=env)
    if ev.returncode == 0:
        errors = json.loads(ev.stdout.strip().splitlines()[-1])
        row["t_cm"] = round(100 * errors["translation_error_m"], 3)
        row["r_deg"] = round(errors["rotation_error_deg"], 4)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--pairs", type=int, default=1, help="pairs per job (default 1)")
    ap.add_argument("--combos", default=",".join(DEFAULT_COMBOS), help="lidar:camera,...")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cold", action="store_true", help="time the run on an empty numba cache")
    ap.add_argument(
        "--no-warmup",
        dest="warmup",
        action="store_false",
        help="no first run to fill the numba cache (it is warm from an earlier run)",
    )
    ap.add_argument(
        "--with",
        dest="variants",
        action="append",
        default=[],
        metavar="OPTIONS",
        help="also time `nbcalib run ... OPTIONS` on the same data, side by side (repeatable)",
    )
    args = ap.parse_args(argv)
    combos = [c.split(":") for c in args.combos.split(",")]
    mode = "cold" if args.cold else "warm"
    print(f"`nbcalib run` on {args.pairs} synthetic pair(s), {mode}, seed {args.seed}")
    header = " | ".join(STAGES)
    print(f"| lidar x camera | {header} | wall | error cm / deg | verdict |")
    print("|---" * (len(STAGES) + 4) + "|")
    rows = []
    with tempfile.TemporaryDirectory(prefix="nbcalib_user_path_") as tmp:
        for lidar, camera in combos:
            root = Path(tmp) / f"{lidar}_{camera}"
            bags = synthesise(root / "synth", lidar, camera, args.pairs, args.seed)
            truth = root / "synth" / "ground_truth.json"
            env = dict(os.environ)
            if args.cold:
                env["NUMBA_CACHE_DIR"] = str(root / "numba_cache")  # empty: every kernel compiles
            elif args.warmup:
                run_job(bags, root / "warmup_work", truth, env)  # fills the cache, not counted
            for variant in ["", *args.variants]:
                extra = variant.split()
                if args.cold and variant:  # each variant from an empty cache of its own
                    env["NUMBA_CACHE_DIR"] = str(root / f"numba_cache_{len(rows)}")
                row = run_job(bags, root / "work", truth, env, extra)
                row.update(lidar=lidar, camera=camera, pairs=args.pairs, mode=mode, options=variant)
                rows.append(row)
                cells = " | ".join(
                    "-" if row["seconds"][s] is None else f"{row['seconds'][s]:.1f} s"
                    for s in STAGES
                )
                error = f"{row['t_cm']:.2f} / {row['r_deg']:.3f}" if "t_cm" in row else "n/a"
                name = f"{lidar} x {camera}" + (f" `{variant}`" if variant else "")
                print(
                    f"| {name} | {cells} | {row['wall_s']:.1f} s | {error} | "
                    f"{row['verdict'] or row.get('error', '-')} |",
                    flush=True,
                )
    print(json.dumps({"mode": mode, "pairs": args.pairs, "runs": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
