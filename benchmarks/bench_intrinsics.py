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

**Refinement** (``--refine focal,center``; issue 47's done-when): per camera model, a lab of
``--pairs`` pairs rendered with the true camera and given one off by ``--refine-offset`` (focal
scale and principal point shift; the sign alternates from model to model), preprocessed twice
as a user would: with the bags' (wrong) ``camera_info``, and with the true camera typed
(``--camera-model --intrinsics --distortion``). Each is calibrated through
``nbcalib calibrate WORK --init START --refine-intrinsics MODE``, ``START`` 1 deg / 5 cm from the
truth (seeded), and judged by ``nbcalib evaluate``: the refined intrinsics' error, the pose's
error with them, and the pose's error found with the given camera alone (recorded beside the
refinement in ``calib.json``). With the true camera given, the refinement should hardly move.

Run:  python benchmarks/bench_intrinsics.py [--models pinhole,fisheye] [--offsets 1,1.015,0.985]
      python benchmarks/bench_intrinsics.py --models "" --real acfr,kitti-odometry,kitti-raw
      python benchmarks/bench_intrinsics.py --refine focal,center --pairs 10 \
          --models pinhole,plumb_bob,rational_polynomial,fisheye,atan,omnidir
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


#: Seed of the refinement's starts (1 deg / 5 cm from the truth).
START_SEED = 47


def _calibrated(work: Path, gt: Path, init: str, mode: str) -> dict:
    """``nbcalib calibrate --refine-intrinsics MODE`` from ``init``; evaluate's line + record."""
    from nbcalib.io.calib_json import T_camera_lidar_from_values, read_calib_json
    from nbcalib.transforms import pose_error

    t0 = time.perf_counter()
    nbcalib("calibrate", work, f"--init={init}", "--refine-intrinsics", mode, "--force")
    seconds = time.perf_counter() - t0
    ev = json.loads(nbcalib("evaluate", work, "--ground-truth", gt).stdout.splitlines()[-1])
    record = read_calib_json(work / "calib.json").record.calibration.figures["intrinsics"]
    T_true = read_ground_truth(gt)
    T_pose = T_camera_lidar_from_values(record["pose_only_T_lidar_camera"])
    dt, dr = pose_error(invert_T(T_pose), invert_T(T_true))
    return {
        "focal_error_percent": ev.get("focal_error_percent"),
        "center_error_px": ev.get("center_error_px"),
        "cm": 100 * ev["translation_error_m"],
        "deg": ev["rotation_error_deg"],
        "pose_only_cm": 100 * dt,
        "pose_only_deg": dr,
        "refined": record["refined"],
        "reason": record["reason"],
        "focal_scale": record["focal_scale"],
        "center_shift_px": record["center_shift_px"],
        "focal_bound_percent": record["focal_bound_percent"],
        "center_bound_px": record["center_bound_px"],
        "correlation": record["correlation_focal_forward"],
        "seconds": round(seconds, 1),
    }


def refine_case(model: str, sign: int, args, root: Path) -> dict:
    """One model's lab: calibrated with the given (wrong) camera and with the true one."""
    from nbcalib.transforms import offset_pose

    scale, dx, dy = (float(v) for v in args.refine_offset.split(","))
    scale = scale if sign > 0 else 2.0 - scale
    shift = (sign * dx, sign * dy)
    base = root / f"refine_{model}_{scale:g}"
    out = base / "synth"
    if not (out / "ground_truth.json").is_file():
        shutil.rmtree(base, ignore_errors=True)
        nbcalib("synth", out, "--lidar", args.lidar, "--camera", model, "--scene", args.scene,
                "--pairs", args.pairs, "--seed", args.seed, "--format", "bag2",
                "--given-focal-scale", f"{scale:g}",
                "--given-center-shift", f"{shift[0]:g},{shift[1]:g}")  # fmt: skip
    gt = out / "ground_truth.json"
    bags = [out / f"pair_{k:03d}" for k in range(args.pairs)]
    true = json.loads(gt.read_text())["intrinsics"]["rendered"]
    typed = ["--camera-model", true["camera_model"],
             "--intrinsics", ",".join(f"{v:.12g}" for v in true["intrinsics"])]  # fmt: skip
    if true["distortion_coeffs"]:
        typed += ["--distortion", ",".join(f"{v:.12g}" for v in true["distortion_coeffs"])]
    T_true = read_ground_truth(gt)
    start = offset_pose(T_true, 1.0, 0.05, START_SEED)
    init = ",".join(f"{v:.12g}" for v in pose_to_xyz_quat(invert_T(start)))
    row = {"model": model, "focal_scale": scale, "center_shift": shift}
    for name, camera in (("given", []), ("true", typed)):
        work = base / f"work_{name}"
        if not (work / "calib.json").is_file():
            nbcalib("preprocess", *bags, *camera, work)
        row[name] = _calibrated(work, gt, init, args.refine)
        r = row[name]
        print(
            f"{model} {name}: focal {r['focal_error_percent']:+.3f} %, centre "
            f"{r['center_error_px']:.2f} px, pose {r['cm']:.2f} cm / {r['deg']:.3f} deg "
            f"(pose only {r['pose_only_cm']:.2f} / {r['pose_only_deg']:.3f}), "
            f"{'refined' if r['refined'] else 'kept: ' + r['reason']}, {r['seconds']} s",
            file=sys.stderr,
            flush=True,
        )
    return row


def print_refine_table(rows) -> None:
    """The refinement's table: errors with the wrong camera given, then with the true one."""
    print("| model | given | focal error | centre error | pose error | pose alone | kept | "
          "+-focal / centre (95 %) | corr f/tz | s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        for name in ("given", "true"):
            r = row[name]
            given = (
                f"x{row['focal_scale']:g}, {row['center_shift'][0]:+g},{row['center_shift'][1]:+g}"
                if name == "given"
                else "true"
            )
            print(
                f"| {row['model']} | {given} | {r['focal_error_percent']:+.3f} % | "
                f"{r['center_error_px']:.2f} px | {r['cm']:.2f} cm / {r['deg']:.3f} deg | "
                f"{r['pose_only_cm']:.2f} cm / {r['pose_only_deg']:.3f} deg | "
                f"{'refined' if r['refined'] else 'kept'} | {r['focal_bound_percent']:.3f} % / "
                f"{r['center_bound_px'] or float('nan'):.2f} px | {r['correlation']:+.2f} | "
                f"{r['seconds']} |"
            )


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
    ap.add_argument("--refine", default="", help="focal or focal,center: the refinement's cases")
    ap.add_argument("--refine-offset", default="1.015,4,-3",
                    help="focal scale, DX, DY given (the sign alternates by model)")  # fmt: skip
    args = ap.parse_args(argv)
    root = args.keep or Path(tempfile.mkdtemp(prefix="nbcalib_intrinsics_"))
    if args.refine:
        models = [m for m in args.models.split(",") if m]
        rows = [refine_case(m, 1 if k % 2 == 0 else -1, args, root) for k, m in enumerate(models)]
        print_refine_table(rows)
        print(json.dumps({"args": vars(args) | {"keep": str(args.keep)}, "refine": rows}))
        if args.keep is None:
            shutil.rmtree(root, ignore_errors=True)
        return 0
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
