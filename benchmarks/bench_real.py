"""Fine registration on real data as a user runs it (issue 15): three protocols, two start sizes.

Every run is the command line as typed: ``nbcalib preprocess`` once per set (a work directory),
then per start a copy of it, ``nbcalib calibrate COPY --init X,Y,Z,QX,QY,QZ,QW``,
``nbcalib evaluate COPY --ground-truth GT`` and ``nbcalib report COPY`` (its verdict).

Protocols, on ``../shared/data/real`` (skips with a message when it is absent):

- **a** one scan + its image: KITTI frames 0, 5, 10, 15 and both PJLab frames (distorted camera);
- **b** the paper's single-shot: one KITTI image + the K scans around it (``--neighbors``,
  default 10), accumulated by continuous-time ICP and expressed in the LiDAR frame at the image
  time (``--images IMG --image-times T --neighbors K --dynamic``); images 5, 10, 15. KITTI's
  camera fires when the LiDAR faces forward, the middle of its sweep: ``T = 0.1 i + 0.05`` s
  (``--image-offset`` 0.05; 0 puts the cloud at the start of the image's scan instead);
- **c** several pairs jointly (``--frames``): KITTI frames 0-4, 5-9, 10-14, 15-19, and all 20.

Starts: the reference turned by exactly ``r`` about a seeded random axis and its camera centre
moved by exactly ``t`` in a seeded random direction, for ``(r, t)`` = (1 deg, 5 cm) and
(2 deg, 10 cm), ``--perturbations`` (5) directions each, the same for every set. A run "ends
better" when both its final errors are below its start's. Seconds: wall time of ``calibrate``
(fine registration alone, numba cache warm).

``--calibrate-args "..."`` passes options to every ``calibrate`` (the ablation levers:
``--structure-weight 1``, ``--bins 8``...), ``--preprocess-args "..."`` to every ``preprocess``.

Run:  python benchmarks/bench_real.py [--protocols abc] [--quick] [--calibrate-args "..."]
Prints one Markdown table (a row per protocol and start size), then one JSON line.
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

import numpy as np

# the starts of the in-process benchmark: the same seeded directions, exactly sized
from bench_real_registration import perturb, perturbations

from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.transforms import invert_T, pose_to_xyz_quat

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
KITTI = "kitti_raw_2011_09_26"
KITTI_CALIB = "calib/calib_normalized_cam2rect.json"
PJLAB = ("auto_calib", "manual_calib_0")
START_SIZES = ((1.0, 0.05), (2.0, 0.10))
#: "good" and "bad" results for the verdict figures (issue 15)
GOOD = (0.3, 0.05)
BAD = (1.0, 0.10)


def nbcalib(*args, check=True) -> subprocess.CompletedProcess:
    """``python -m nbcalib ARGS`` as a user types it."""
    run = subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True
    )
    if check and run.returncode != 0:
        raise RuntimeError(f"nbcalib {' '.join(map(str, args))} failed:\n{run.stderr[-2000:]}")
    return run


# ---------------------------------------------------------------------------------------------
# The sets: (protocol, name, preprocess arguments, reference calibration file)
# ---------------------------------------------------------------------------------------------


def frames_folder(tmp: Path, data: Path, frames) -> Path:
    """A folder of links to the KITTI frames ``frames`` (the ``--frames`` layout)."""
    folder = tmp / f"frames_{frames[0]:02d}_{frames[-1]:02d}"
    folder.mkdir(exist_ok=True)
    for k in frames:
        link = folder / f"{k:010d}"
        if not link.exists():
            link.symlink_to(data / KITTI / f"{k:010d}")
    return folder


def sets(data: Path, tmp: Path, args):
    kitti = data / KITTI
    camera = ["--camera", kitti / KITTI_CALIB]
    if "a" in args.protocols:
        for k in args.single_frames:
            f = kitti / f"{k:010d}"
            pre = ["--points", f / "velodyne.bin", "--image", f / "image_02.png", *camera]
            yield "a", f"kitti {k:02d}", pre, kitti / KITTI_CALIB
        for name in args.pjlab:
            f = data / "pjlab" / name
            calib = next(f.glob("calib_normalized*.json"))
            pre = ["--points", f / "lidar.pcd", "--image", f / "image.png", "--camera", calib]
            yield "a", f"pjlab {name}", pre, calib
    if "b" in args.protocols:
        scans = [kitti / f"{k:010d}" / "velodyne.bin" for k in range(20)]
        for i in args.shot_images:
            image = kitti / f"{i:010d}" / "image_02.png"
            pre = [
                f"--images={image}",
                f"--image-times={0.1 * i + args.image_offset:.3f}",
                "--neighbors",
                args.neighbors,
                "--dynamic",
                *camera,
            ]
            # the scans are positional, before the work directory
            pre = [*scans, None, *pre]
            yield "b", f"kitti image {i:02d} + {args.neighbors} scans", pre, kitti / KITTI_CALIB
    if "c" in args.protocols:
        for frames in args.multi:
            folder = frames_folder(tmp, data, frames)
            pre = ["--frames", folder, *camera]
            name = f"kitti {len(frames)} pairs {frames[0]:02d}-{frames[-1]:02d}"
            yield "c", name, pre, kitti / KITTI_CALIB


# ---------------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------------


def run_set(protocol, name, pre, calib: Path, tmp: Path, args) -> list[dict]:
    """Preprocess once, then calibrate + evaluate from every start."""
    base = tmp / "work" / name.replace(" ", "_").replace("+", "")
    if base.exists():
        shutil.rmtree(base)
    t0 = time.perf_counter()
    if None in pre:  # positional inputs, then the work directory, then options
        k = pre.index(None)
        command = [*pre[:k], base, *pre[k + 1 :]]
    else:
        command = [base, *pre]
    nbcalib("preprocess", *command, *shlex.split(args.preprocess_args))
    preprocess_s = time.perf_counter() - t0
    T_ref = read_ground_truth(calib)
    gt = tmp / "ground_truth.json"
    gt.write_text(json.dumps({"T_camera_lidar": T_ref.tolist()}))
    runs = []
    for angle, dist in args.sizes:
        for j, offset in enumerate(
            perturbations(args.perturbations, args.seed, angle_deg=angle, distance=dist)
        ):
            work = tmp / "run"
            if work.exists():
                shutil.rmtree(work)
            shutil.copytree(base, work)
            init = pose_to_xyz_quat(invert_T(perturb(T_ref, offset)))
            w0 = time.perf_counter()
            nbcalib(
                "calibrate",
                work,
                f"--init={','.join(f'{x:.12g}' for x in init)}",
                *shlex.split(args.calibrate_args),
            )
            seconds = time.perf_counter() - w0
            ev = json.loads(nbcalib("evaluate", work, "--ground-truth", gt).stdout.splitlines()[-1])
            # the verdict as a user reads it; exit 3 only with --strict
            rep = nbcalib("report", work, check=False) if args.verdict else None
            log = "" if rep is None else rep.stdout + rep.stderr
            verdict = next(
                (ln.split(":", 1)[1].strip() for ln in log.splitlines() if "verdict:" in ln), "?"
            )
            reasons = [
                ln.strip()[2:].split(":")[0] for ln in log.splitlines() if ln.startswith("  - ")
            ]
            row = {
                "protocol": protocol,
                "set": name,
                "start_deg": angle,
                "start_cm": 100 * dist,
                "direction": j,
                "translation_cm": 100 * ev["translation_error_m"],
                "rotation_deg": ev["rotation_error_deg"],
                "verdict": verdict,
                "reasons": reasons,
                "seconds": seconds,
                "preprocess_s": preprocess_s,
            }
            row["better"] = row["translation_cm"] < 100 * dist and row["rotation_deg"] < angle
            runs.append(row)
            print(
                f"{protocol} {name} start {angle:g} deg/{100 * dist:g} cm #{j}: "
                f"{row['translation_cm']:.1f} cm / {row['rotation_deg']:.2f} deg, {verdict}, "
                f"{seconds:.1f} s",
                file=sys.stderr,
                flush=True,
            )
    return runs


def summary(runs: list[dict]) -> dict:
    t = np.array([r["translation_cm"] for r in runs])
    r = np.array([r["rotation_deg"] for r in runs])
    return {
        "runs": len(runs),
        "median_translation_cm": float(np.median(t)),
        "max_translation_cm": float(np.max(t)),
        "median_rotation_deg": float(np.median(r)),
        "max_rotation_deg": float(np.max(r)),
        "better": float(np.mean([x["better"] for x in runs])),
        "ok": float(np.mean([x["verdict"] == "ok" for x in runs])),
        "median_seconds": float(np.median([x["seconds"] for x in runs])),
    }


def verdict_figures(runs: list[dict]) -> dict:
    """How often the verdict is right on good and on bad results (issue 15's targets)."""
    good = [
        x for x in runs if x["rotation_deg"] <= GOOD[0] and x["translation_cm"] <= 100 * GOOD[1]
    ]
    bad = [x for x in runs if x["rotation_deg"] > BAD[0] or x["translation_cm"] > 100 * BAD[1]]
    return {
        "good_runs": len(good),
        "good_called_ok": float(np.mean([x["verdict"] == "ok" for x in good])) if good else None,
        "bad_runs": len(bad),
        "bad_called_suspect": (
            float(np.mean([x["verdict"] == "suspect" for x in bad])) if bad else None
        ),
    }


ROW_GROUPS = {
    "a": ("a", lambda s: s.startswith("kitti")),
    "a-pjlab": ("a", lambda s: s.startswith("pjlab")),
    "b": ("b", lambda s: True),
    "c5": ("c", lambda s: " 5 pairs" in s),
    "c20": ("c", lambda s: " 20 pairs" in s),
}
LABELS = {
    "a": "(a) KITTI, one scan",
    "a-pjlab": "(a) PJLab, one scan",
    "b": "(b) KITTI, image + K scans",
    "c5": "(c) KITTI, 5 pairs",
    "c20": "(c) KITTI, 20 pairs",
}


def table(runs: list[dict]) -> list[dict]:
    rows = []
    for key, (protocol, pick) in ROW_GROUPS.items():
        for angle, cm in sorted({(x["start_deg"], x["start_cm"]) for x in runs}):
            sel = [
                x
                for x in runs
                if x["protocol"] == protocol
                and pick(x["set"])
                and (x["start_deg"], x["start_cm"]) == (angle, cm)
            ]
            if sel:
                rows.append({"group": key, "start": f"{angle:g} deg / {cm:g} cm", **summary(sel)})
    print(
        "| protocol | start | runs | median / max t (cm) | median / max r (deg) | ends better "
        "| verdict ok | s / run |"
    )
    print("|---|---|---:|---|---|---:|---:|---:|")
    for s in rows:
        print(
            f"| {LABELS[s['group']]} | {s['start']} | {s['runs']} "
            f"| {s['median_translation_cm']:.1f} / {s['max_translation_cm']:.1f} "
            f"| {s['median_rotation_deg']:.2f} / {s['max_rotation_deg']:.2f} "
            f"| {100 * s['better']:.0f} % | {100 * s['ok']:.0f} % | {s['median_seconds']:.1f} |"
        )
    return rows


def parse_args(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--data", type=Path, default=DATA, help="the real-data folder")
    ap.add_argument("--protocols", default="abc", help="any of a, b, c (default: abc)")
    ap.add_argument("--perturbations", type=int, default=5, help="start directions per size")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--neighbors", type=int, default=10, help="scans per single shot (b)")
    ap.add_argument(
        "--image-offset",
        type=float,
        default=0.05,
        help="(b) image time after its scan's start, s (0.05: KITTI's mid-sweep trigger)",
    )
    ap.add_argument("--sizes", default="1,0.05;2,0.10", help="start sizes 'deg,m;deg,m'")
    ap.add_argument("--calibrate-args", default="", help="options for every calibrate")
    ap.add_argument("--preprocess-args", default="", help="options for every preprocess")
    ap.add_argument("--quick", action="store_true", help="one set per protocol, 2 starts")
    ap.add_argument(
        "--no-verdict", dest="verdict", action="store_false", help="skip nbcalib report"
    )
    ap.add_argument("--threads", type=int, default=None, help="NUMBA_NUM_THREADS of the runs")
    args = ap.parse_args(argv)
    args.sizes = [tuple(float(v) for v in s.split(",")) for s in args.sizes.split(";")]
    args.single_frames, args.pjlab = [0, 5, 10, 15], list(PJLAB)
    args.shot_images = [5, 10, 15]
    args.multi = [list(range(k, k + 5)) for k in (0, 5, 10, 15)] + [list(range(20))]
    if args.quick:
        args.perturbations = min(args.perturbations, 2)
        args.single_frames, args.pjlab, args.shot_images = [0], list(PJLAB[:1]), [10]
        args.multi = [list(range(5))]
        args.sizes = args.sizes[:1]
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    if not (args.data / KITTI).is_dir():
        print(f"real data not found at {args.data}: nothing to measure", file=sys.stderr)
        return 0
    if args.threads is not None:
        os.environ["NUMBA_NUM_THREADS"] = str(args.threads)
    t0 = time.perf_counter()
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench_real_") as tmp:
        for protocol, name, pre, calib in sets(args.data, Path(tmp), args):
            runs += run_set(protocol, name, pre, calib, Path(tmp), args)
    print(
        f"\ncalibrate {args.calibrate_args or '(defaults)'}; preprocess "
        f"{args.preprocess_args or '(defaults)'}; {args.perturbations} directions per start size "
        f"(seed {args.seed}); K = {args.neighbors}\n"
    )
    rows = table(runs)
    verdicts = verdict_figures(runs)
    print(
        f"\nverdict: {verdicts['good_runs']} runs within {GOOD[0]} deg / {100 * GOOD[1]:g} cm, "
        f"ok for {verdicts['good_called_ok']}; {verdicts['bad_runs']} runs worse than "
        f"{BAD[0]} deg or {100 * BAD[1]:g} cm, suspect for {verdicts['bad_called_suspect']}"
    )
    load = Path("/proc/loadavg").read_text().split()[:3] if os.path.exists("/proc/loadavg") else []
    print(
        json.dumps(
            {
                "benchmark": "real",
                "calibrate_args": args.calibrate_args,
                "preprocess_args": args.preprocess_args,
                "quick": args.quick,
                "rows": rows,
                "verdicts": verdicts,
                "runs": runs,
                "seconds": round(time.perf_counter() - t0, 1),
                "loadavg": load,
                "machine": platform.processor() or platform.machine(),
            }
        )
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
