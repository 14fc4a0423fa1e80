"""Peak resident memory of ``nbcalib run`` against the number of pairs and the recording's length.

Issue 48. Each case runs ``nbcalib run`` as a user types it, under ``/usr/bin/time``: its peak
resident set (the run's own process, numba threads included), its wall time, and the result's
error (``nbcalib evaluate``), so that a change that bounds memory can be shown not to move the
result. With ``--base COMMIT`` every case also runs with the nbcalib of that commit (a git
worktree), one after the other on the same data: the two results must be equal to the digit.

- ``--pairs 1,15,50``: ``nbcalib synth OUT --lidar livox --camera pinhole --pairs N --format
  bag2`` (one ROS 2 bag per pair), then ``nbcalib run OUT/pair_* WORK --no-matching --init
  START`` (``START`` 1 deg / 5 cm from the truth, seeded).
- ``--recording 1,10``: a recording of that many minutes of a spinning LiDAR (spinning64 at
  10 Hz, an image a second, the rig at rest in a room: one second of ``nbcalib synth``'s
  simulation written again every second, so 10 minutes are 6000 scans and 600 images in one
  ROS 2 bag, 9 GB), then ``nbcalib run BAG WORK --pair-count 20 --no-matching --init START``.

Each version first runs one short job, not measured, so that numba has compiled its kernels.
Run one at a time on an idle machine (`--repeat N`: each case N times, the versions in turn):

    python benchmarks/bench_memory.py --pairs 1,15,50 --recording 1,10 --base a03eaf4 --keep DIR

Prints a Markdown table and one JSON line.
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

from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.transforms import invert_T, offset_pose, pose_to_xyz_quat

#: Seed of the start's direction.
START_SEED = 48

ROOT = Path(__file__).resolve().parents[1]


def nbcalib(*args, timed: bool = False, code: Path | None = None):
    """Run ``nbcalib ARGS`` (with the nbcalib of folder ``code``); with ``timed``, under
    ``/usr/bin/time``: returns the run and its peak RSS in MB."""
    cmd = [sys.executable, "-m", "nbcalib", *map(str, args)]
    if timed:
        cmd = ["/usr/bin/time", "-f", "MAXRSS_KB %M", *cmd]
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = str(code)
    # not from the checkout: `python -m` puts the working folder first on the import path
    run = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tempfile.gettempdir())
    if run.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}:\n{run.stderr[-2000:]}")
    peak = None
    if timed:
        line = [w for w in run.stderr.splitlines() if w.startswith("MAXRSS_KB ")][-1]
        peak = int(line.split()[1]) / 1024.0
    return run, peak


def start_of(gt: Path) -> str:
    """``--init``: the truth moved 1 deg / 5 cm (seeded)."""
    start = offset_pose(read_ground_truth(gt), 1.0, 0.05, START_SEED)
    return ",".join(f"{v:.12g}" for v in pose_to_xyz_quat(invert_T(start)))


def measure(
    label: str, inputs: list, extra: list, gt: Path, root: Path, codes: dict, repeat: int = 1
) -> list:
    """``nbcalib run INPUTS WORK EXTRA`` with each nbcalib of ``codes`` in turn, ``repeat``
    times over: one row each run."""
    rows = []
    for version, code in [item for _ in range(repeat) for item in codes.items()]:
        work = root / f"work_{label}_{version}"
        shutil.rmtree(work, ignore_errors=True)
        t0 = time.perf_counter()
        _, peak = nbcalib("run", *inputs, work, *extra, timed=True, code=code)
        wall = time.perf_counter() - t0
        ev, _ = nbcalib("evaluate", work, "--ground-truth", gt)
        errors = json.loads(ev.stdout.splitlines()[-1])
        record = json.loads((work / "calib.json").read_text())
        result = record["results"]["T_lidar_camera"]
        row = {
            "case": label,
            "version": version,
            "peak_mb": round(peak, 1),
            "wall_s": round(wall, 1),
            "cm": round(100 * errors["translation_error_m"], 4),
            "deg": round(errors["rotation_error_deg"], 5),
            "result": result,
            # each stage's wall time, as the job recorded it
            "stages": record.get("nbcalib", {}).get("seconds", {}),
        }
        print(f"{label} ({version}): {row}", file=sys.stderr, flush=True)
        rows.append(row)
        shutil.rmtree(work, ignore_errors=True)
    return rows


def warm_up(args, root: Path, codes: dict) -> None:
    """One short job per version, not measured: numba compiles each checkout's kernels once."""
    out = root / "synth_1"
    if not (out / "ground_truth.json").is_file():
        shutil.rmtree(out, ignore_errors=True)
        nbcalib("synth", out, "--lidar", args.lidar, "--camera", args.camera, "--pairs", 1,
                "--seed", args.seed, "--format", "bag2")  # fmt: skip
    init = f"--init={start_of(out / 'ground_truth.json')}"
    for version, code in codes.items():
        work = root / f"warm_{version}"
        shutil.rmtree(work, ignore_errors=True)
        nbcalib("run", out / "pair_000", work, "--no-matching", init, "--max-outer", 1, code=code)
        shutil.rmtree(work, ignore_errors=True)


def pairs_case(pairs: int, args, root: Path, codes: dict) -> list:
    out = root / f"synth_{pairs}"
    if not (out / "ground_truth.json").is_file():
        shutil.rmtree(out, ignore_errors=True)
        nbcalib("synth", out, "--lidar", args.lidar, "--camera", args.camera, "--pairs", pairs,
                "--seed", args.seed, "--format", "bag2")  # fmt: skip
    gt = out / "ground_truth.json"
    extra = ["--no-matching", f"--init={start_of(gt)}"]
    inputs = sorted(out.glob("pair_*"))
    return measure(f"{pairs} pairs", inputs, extra, gt, root, codes, args.repeat)


def write_recording(out: Path, minutes: float, seed: int) -> Path:
    """A recording of a spinning LiDAR at rest: one simulated second written again and again."""
    from nbcalib.io.bag_writer import BagWriter
    from nbcalib.io.ground_truth import write_ground_truth
    from nbcalib.synthetic import RigConfig
    from nbcalib.synthetic.rig import generate_sequence
    from nbcalib.synthetic.writer import BASE_STAMP_NS, FRAMES, TOPICS, scan_fields

    config = RigConfig(lidar="spinning64", camera="pinhole", scene="room", seed=seed,
                       duration=1.0, motion="static")  # fmt: skip
    sequence = generate_sequence(config, pair=0)
    scans = sequence.output_scans()
    period = 1.0 / len(scans)  # 10 scans a second
    out.mkdir(parents=True, exist_ok=True)
    bag = out / "recording"
    shutil.rmtree(bag, ignore_errors=True)
    with BagWriter(bag, "bag2") as writer:
        writer.write_tf_static(BASE_STAMP_NS, FRAMES["lidar"], FRAMES["camera"],
                               sequence.T_lidar_camera)  # fmt: skip
        writer.write_camera_info(TOPICS["camera_info"], BASE_STAMP_NS, sequence.camera,
                                 FRAMES["camera"])  # fmt: skip
        for second in range(round(60 * minutes)):
            stamp = BASE_STAMP_NS + second * 1_000_000_000
            writer.write_image(TOPICS["image"], stamp, sequence.image, FRAMES["camera"])
            for k, scan in enumerate(scans):
                at = stamp + round(k * period * 1e9)
                writer.write_pointcloud(TOPICS["points"], at, scan_fields(scan), FRAMES["lidar"])
    write_ground_truth(out / "ground_truth.json", sequence.T_camera_lidar)
    return bag


def recording_case(minutes: float, args, root: Path, codes: dict) -> list:
    out = root / f"recording_{minutes:g}min"
    if not (out / "ground_truth.json").is_file():
        shutil.rmtree(out, ignore_errors=True)
        write_recording(out, minutes, args.seed)
    gt = out / "ground_truth.json"
    extra = ["--pair-count", "20", "--no-matching", f"--init={start_of(gt)}"]
    return measure(f"{minutes:g} min", [out / "recording"], extra, gt, root, codes, args.repeat)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--pairs", default="1,15", help="pair counts, comma-separated ('': none)")
    ap.add_argument("--recording", default="", help="recording lengths, minutes, comma-separated")
    ap.add_argument("--base", help="also run each case with the nbcalib of this commit")
    ap.add_argument("--lidar", default="livox")
    ap.add_argument("--camera", default="pinhole")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1,
                    help="run each case this many times (the versions in turn)")  # fmt: skip
    ap.add_argument("--keep", type=Path, help="keep the data here (and reuse it)")
    args = ap.parse_args(argv)
    root = (args.keep or Path(tempfile.mkdtemp(prefix="nbcalib_memory_"))).resolve()
    codes: dict = {"head": ROOT}
    base_code = root / "base_code"
    if args.base:
        if not base_code.exists():
            add = ["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(base_code)]
            subprocess.run([*add, args.base], check=True, capture_output=True)
        codes = {"base": base_code, **codes}
    for version, code in codes.items():  # each version runs its own nbcalib
        probe = [sys.executable, "-c", "import nbcalib; print(nbcalib.__file__)"]
        env = {**os.environ, "PYTHONPATH": str(code)}
        where = subprocess.run(probe, capture_output=True, text=True, env=env,
                               cwd=tempfile.gettempdir()).stdout.strip()  # fmt: skip
        if not Path(where).resolve().is_relative_to(Path(code).resolve()):
            raise SystemExit(f"{version}: nbcalib imported from {where}, not {code}")
    rows = []
    try:
        warm_up(args, root, codes)
        for n in filter(None, args.pairs.split(",")):
            rows += pairs_case(int(n), args, root, codes)
        for m in filter(None, args.recording.split(",")):
            rows += recording_case(float(m), args, root, codes)
    finally:
        if args.base:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force",
                            str(base_code)], capture_output=True)  # fmt: skip
    print("| case | version | peak RSS, MB | wall s | preprocess / calibrate / report s | result "
          "cm / deg |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for r in rows:
        result = f"{r['cm']:.2f} / {r['deg']:.3f}"
        stages = " / ".join(f"{r['stages'].get(k, float('nan')):.1f}"
                            for k in ("preprocess", "calibrate", "report"))  # fmt: skip
        print(f"| {r['case']} | {r['version']} | {r['peak_mb']:.0f} | {r['wall_s']} | {stages} | "
              f"{result} |")  # fmt: skip
    same = {}
    for r in rows:
        same.setdefault(r["case"], set()).add(tuple(r["result"]))
    for case, results in same.items():
        if len(results) > 1:
            print(f"{case}: the versions' results differ", file=sys.stderr)
    print(
        json.dumps({"bench": "memory", "args": vars(args) | {"keep": str(args.keep)}, "rows": rows})
    )
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
