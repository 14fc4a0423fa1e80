"""Does the cost see a focal length that is off? The lab and the real sets (issue 47).

**Synthetic** (the truth of both cameras exact): per camera model and focal offset,
``nbcalib synth OUT --camera M --pairs P --given-focal-scale S`` (the images rendered with the
true camera, ``camera.yaml`` the offset one; several pairs as one ROS 2 bag each, their
``camera_info`` the offset camera), ``nbcalib preprocess`` of the pairs with that camera,
then :func:`nbcalib.report.intrinsics.focal_scan` (the job's summed cost over focal scales of
the given camera) at the true pose; ``nbcalib calibrate --init <truth>`` + ``nbcalib evaluate``
and the scan again at the result; with ``--profile``, the profile: per focal scale 0.985-1.015
the pose re-registered (``nbcalib calibrate --force --init <truth>``), the cost at its end. At
the true pose the lowest cost should lie at ``1 / S`` (the scale that gives back the true focal
length); at the result, the pose has absorbed what it could; the profile lets the pose move.

**Real** (``--real SETS``, ``../shared/data/real``, the sets of ``bench_real_frames.py``): each
set's frames through ``nbcalib preprocess --frames DIR --camera FILE`` as a user types it, then
the same scan at the set's reference pose: ACFR's fisheye is thought ~1 % off (BENCHMARKS 5.7),
KITTI's intrinsics exact.

Run:  python benchmarks/bench_intrinsics.py [--models pinhole,fisheye] [--offsets 1,1.015,0.985]
      python benchmarks/bench_intrinsics.py --models "" --real acfr,kitti-odometry,kitti-raw
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

import numpy as np

from nbcalib.config import CalibrationConfig
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.registration.pair import RegistrationPair
from nbcalib.report.intrinsics import focal_scan
from nbcalib.transforms import invert_T, pose_to_xyz_quat
from nbcalib.workdir import WorkDir

#: Focal scales of the profile (each one a calibration).
PROFILE_SCALES = (0.985, 0.99, 0.995, 1.0, 1.005, 1.01, 1.015)


def nbcalib(*args) -> subprocess.CompletedProcess:
    run = subprocess.run(
        [sys.executable, "-m", "nbcalib", *map(str, args)], capture_output=True, text=True
    )
    if run.returncode != 0:
        raise RuntimeError(f"nbcalib {' '.join(map(str, args))}:\n{run.stderr[-2000:]}")
    return run


def registration_pairs(work: Path) -> list:
    wd = WorkDir(work)
    camera = wd.require_preprocessed().camera_model()
    return [
        RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name)
        for p in wd.load_pairs()
    ]


def scan(work: Path, T, config) -> dict:
    t0 = time.perf_counter()
    found = focal_scan(registration_pairs(work), T, config).to_dict()
    found["seconds"] = round(time.perf_counter() - t0, 1)
    return found


def profile(work: Path, T_start, config, scales) -> dict:
    """The cost over focal scales with the pose re-registered at each (``--profile``).

    Per scale: a copy of ``work`` whose camera has ``fx, fy`` times the scale, through
    ``nbcalib calibrate --force --init <T_start>``; then the summed cost of that camera at the
    pose it ended at. The scale of the lowest cost: what the data say, the pose free.
    """
    from nbcalib.io.calib_json import read_calib_json, write_calib_json
    from nbcalib.registration.costs import build_cost
    from nbcalib.report.intrinsics import _vertex, scaled_focal

    init = "--init=" + ",".join(f"{v:.12g}" for v in pose_to_xyz_quat(invert_T(T_start)))
    t0 = time.perf_counter()
    values = []
    for scale in scales:
        copy = work.parent / f"{work.name}_focal_{scale:g}"
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(work, copy)
        calib = read_calib_json(copy / "calib.json")
        calib.set_camera(scaled_focal(calib.camera_model(), scale))
        write_calib_json(copy / "calib.json", calib)
        nbcalib("calibrate", copy, init, "--force")
        T = read_calib_json(copy / "calib.json").get_T_camera_lidar("T_lidar_camera")
        cost, _ = build_cost(registration_pairs(copy), T, config)
        values.append(float(cost.value(T)))
        shutil.rmtree(copy, ignore_errors=True)
    scales = np.asarray(scales, dtype=np.float64)
    return {
        "scales": scales.tolist(),
        "nid": values,
        "best": _vertex(scales, np.asarray(values)),
        "seconds": round(time.perf_counter() - t0, 1),
    }


def synthetic_case(model, offset, args, root: Path, config) -> dict:
    out, work = root / f"{model}_{offset:g}" / "synth", root / f"{model}_{offset:g}" / "work"
    if not (work / "calib.json").is_file():
        shutil.rmtree(out.parent, ignore_errors=True)
        several = ["--format", "bag2"] if args.pairs > 1 else []
        nbcalib("synth", out, "--lidar", args.lidar, "--camera", model, "--scene", args.scene,
                "--pairs", args.pairs, "--seed", args.seed, *several,
                "--given-focal-scale", f"{offset:g}")  # fmt: skip
        if args.pairs > 1:  # one bag per pair (its camera_info the given camera), as users have
            nbcalib("preprocess", *[out / f"pair_{k:03d}" for k in range(args.pairs)], work)
        else:
            scans = sorted((out / "pair_000_scans").glob("*.pcd")) or [out / "pair_000.pcd"]
            nbcalib("preprocess", "--points", *scans, "--image", out / "pair_000.png",
                    "--camera", out / "camera.yaml", work)  # fmt: skip
    gt = out / "ground_truth.json"
    T_true = read_ground_truth(gt)
    row = {"model": model, "offset": offset, "expected": 1.0 / offset}
    row["at_truth"] = scan(work, T_true, config)
    init = ",".join(f"{v:.12g}" for v in pose_to_xyz_quat(invert_T(T_true)))
    scratch = work.parent / "calibrated"
    shutil.rmtree(scratch, ignore_errors=True)
    shutil.copytree(work, scratch)
    nbcalib("calibrate", scratch, f"--init={init}")
    ev = json.loads(nbcalib("evaluate", scratch, "--ground-truth", gt).stdout.splitlines()[-1])
    row["walk_cm"] = 100 * ev["translation_error_m"]
    row["walk_deg"] = ev["rotation_error_deg"]
    from nbcalib.io.calib_json import read_calib_json

    T_result = read_calib_json(scratch / "calib.json").get_T_camera_lidar("T_lidar_camera")
    row["at_result"] = scan(scratch, T_result, config)
    if args.profile:
        row["profile"] = profile(work, T_true, config, PROFILE_SCALES)
        print(f"{model} x{offset:g}: profile best {row['profile']['best']:.4f}", file=sys.stderr)
    print(
        f"{model} x{offset:g}: best at truth {row['at_truth']['best']:.4f} (expected "
        f"{row['expected']:.4f}), at result {row['at_result']['best']:.4f}; walk "
        f"{row['walk_cm']:.2f} cm / {row['walk_deg']:.3f} deg",
        file=sys.stderr,
        flush=True,
    )
    return row


def real_case(name: str, spec: dict, root: Path, config, profile_too: bool = False) -> dict:
    from bench_real_frames import reference_pose

    work = root / f"real_{name}"
    if not (work / "calib.json").is_file():
        shutil.rmtree(work, ignore_errors=True)
        nbcalib("preprocess", "--frames", spec["folder"], "--camera", spec["camera"],
                *spec.get("options", []), work)  # fmt: skip
    T_ref = reference_pose(spec.get("reference", spec["camera"]))
    row = {"set": name, "at_reference": scan(work, T_ref, config)}
    if profile_too:
        row["profile"] = profile(work, T_ref, config, PROFILE_SCALES)
        print(f"{name}: profile best {row['profile']['best']:.4f}", file=sys.stderr)
    print(f"{name}: best at the reference {row['at_reference']['best']:.4f}", file=sys.stderr)
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--models", default="pinhole,fisheye")
    ap.add_argument("--offsets", default="1,1.015,0.985", help="given focal scales")
    ap.add_argument("--lidar", default="spinning64")
    ap.add_argument("--scene", default="room")
    ap.add_argument("--pairs", type=int, default=1)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--keep", type=Path, default=None, help="keep and reuse the data here")
    ap.add_argument("--real", default="", help="real sets of bench_real_frames.py, comma-separated")
    ap.add_argument("--profile", action="store_true",
                    help="also: the pose re-registered at each focal scale")  # fmt: skip
    args = ap.parse_args(argv)
    root = args.keep or Path(tempfile.mkdtemp(prefix="nbcalib_intrinsics_"))
    config = CalibrationConfig().refine
    rows = [
        synthetic_case(model, float(offset), args, root, config)
        for model in filter(None, args.models.split(","))
        for offset in args.offsets.split(",")
    ]
    real = []
    if args.real:
        from bench_real_frames import DATA, sets

        available = sets(DATA) if DATA.is_dir() else {}
        for name in args.real.split(","):
            if name not in available:
                print(f"{name}: no data, skipped", file=sys.stderr)
                continue
            real.append(real_case(name, available[name], root, config, args.profile))
    print("| model | given focal x | lowest cost at the truth (expected) | at the result | "
          "profile (pose free) | walk from the truth |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for r in rows:
        prof = f"{r['profile']['best']:.4f}" if "profile" in r else ""
        print(
            f"| {r['model']} | {r['offset']:g} | {r['at_truth']['best']:.4f} "
            f"({r['expected']:.4f}) | {r['at_result']['best']:.4f} | {prof} | "
            f"{r['walk_cm']:.2f} cm / {r['walk_deg']:.3f} deg |"
        )
    if real:
        print("\n| real set | lowest cost at the reference pose | profile (pose free) | scan s |")
        print("|---|---|---|---|")
        for r in real:
            scan_row = r["at_reference"]
            edge = " (at the scan's edge)" if scan_row["at_edge"] else ""
            prof = f"{r['profile']['best']:.4f}" if "profile" in r else ""
            print(f"| {r['set']} | {scan_row['best']:.4f}{edge} | {prof} | {scan_row['seconds']} |")
    print(json.dumps({"args": vars(args) | {"keep": str(args.keep)}, "rows": rows, "real": real}))
    if args.keep is None:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
