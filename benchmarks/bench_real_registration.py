"""Fine registration on the real KITTI and PJLab frames (issue 5 item 6).

Every run starts from the reference calibration perturbed by exactly 1 degree and 5 cm (the
camera centre moved in the LiDAR frame, the rotation turned about an axis; seeded random
directions, the same perturbations for every set) and runs :func:`nbcalib.registration.refine.
refine` with the given :class:`RefineConfig`. Sets:

- ``kitti single``: one KITTI scan and its image (static, as ``nbcalib preprocess`` makes it);
- ``kitti 5 pairs``: five consecutive single-scan pairs sharing the extrinsic (0-4, 5-9, ...);
- ``kitti 20 pairs``: the twenty single-scan pairs;
- ``kitti acc5 start`` / ``kitti acc5 image``: one pair whose cloud accumulates five scans with
  continuous-time ICP (dynamic integration), expressed as ``nbcalib preprocess`` writes it (LiDAR
  frame at the *start* of the first scan) or re-expressed in the LiDAR frame at the image time
  (KITTI triggers the camera when the LiDAR faces forward: the middle of the scan);
- ``pjlab``: each PJLab frame (two rigs, one scan each).

Static clouds go through :func:`nbcalib.preprocess.prepare.prepare_pair` (the readers and
preprocessing of ``nbcalib preprocess``, the values its work directory holds); accumulated
clouds are integrated in-process with the same settings, since re-expressing them needs the
scan poses. Per set: final error against the reference (median / max over runs), success rate
(both errors under the threshold printed), CPU and wall time per run, visible points, and how
often the optimiser ends where the NID over the points visible at the reference is lower than at
the reference (then the cost's minimum, not the optimiser, is off).

``--landscape`` adds the cost along single axes around the reference (left perturbation in the
camera frame: ``tx ty tz`` = right, down, forward; ``rx ry rz`` about those axes), for the smooth
(B-spline) and hard-binned NID: where the minimum lands, per single frame and per 5-pair set.

Numba threads default to 1 (``--threads``): on this shared 2-core machine under load the
OpenMP-parallel NID kernel spends 20-90 x more CPU than the serial one on ~16 k points.

Run:  python benchmarks/bench_real_registration.py [--quick] [--perturbations 5] [--landscape]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.metrics import pose_errors
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.inputs import gather_files
from nbcalib.preprocess.prepare import prepare_pair
from nbcalib.registration.refine import RefineConfig, RegistrationPair, build_cost, refine
from nbcalib.transforms import interpolate_pose, invert_T, make_T, se3_exp, so3_exp

#: ../shared/data/real relative to the project root (as tests/conftest.py)
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
KITTI = "kitti_raw_2011_09_26"
KITTI_CALIB = "calib/calib_normalized_cam2rect.json"
PJLAB = ("auto_calib", "manual_calib_0")

#: a run succeeds when it ends within both (the reference is trusted to a few tenths of a degree
#: and a few centimetres; the start is 5 cm / 1 degree away)
SUCCESS_TRANSLATION_M = 0.03
SUCCESS_ROTATION_DEG = 0.3

#: KITTI's sweeps start behind the sensor; the camera fires when the head faces forward
KITTI_IMAGE_SCAN_FRACTION = 0.5


@dataclass
class FrameSet:
    """Pairs sharing one extrinsic, with the reference ``T_camera_lidar`` to score against."""

    name: str
    group: str
    pairs: list[RegistrationPair]
    T_camera_lidar_ref: np.ndarray


# ---------------------------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------------------------


def kitti_paths(data: Path, k: int) -> tuple[Path, Path]:
    """(velodyne.bin, image_02.png) of KITTI frame ``k``."""
    folder = data / KITTI / f"{k:010d}"
    return folder / "velodyne.bin", folder / "image_02.png"


def static_pairs(inputs, camera: CameraModel, config: PreprocessConfig) -> list[RegistrationPair]:
    """Preprocess ``inputs`` as ``nbcalib preprocess`` does (the values its files hold)."""
    pairs = []
    for pair in inputs:
        p = prepare_pair(pair, config)
        pairs.append(RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name))
    return pairs


def accumulated_pair(
    data: Path, first: int, scans: int, camera: CameraModel, config: PreprocessConfig
) -> tuple[RegistrationPair, RegistrationPair, float]:
    """KITTI scans ``first .. first + scans - 1`` integrated dynamically, image ``first``.

    Returns the pair as ``nbcalib preprocess`` writes it (LiDAR frame at the start of the first
    scan), the same cloud in the LiDAR frame at the image time, and the distance between the two
    frames (metres).
    """
    from nbcalib.odometry import integrate_dynamic
    from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities

    inputs = gather_files(
        [kitti_paths(data, k)[0] for k in range(first, first + scans)],
        kitti_paths(data, first)[1],
        config,
        name=f"{first:010d}",
    )
    cloud = integrate_dynamic(
        inputs.scans,
        voxel_size=config.voxel_size,
        min_distance=config.min_distance,
        frame_rate=config.frame_rate,
    )
    intensities = equalize_point_intensities(cloud.intensity)
    image = equalize_image(inputs.image)
    T_first_image = interpolate_pose(
        cloud.T_first_scanbegin[0], cloud.T_first_scanend[0], KITTI_IMAGE_SCAN_FRACTION
    )
    T_image_first = invert_T(T_first_image)
    points_image = cloud.points @ T_image_first[:3, :3].T + T_image_first[:3, 3]
    start = RegistrationPair(camera, image, cloud.points, intensities, inputs.name)
    at_image = RegistrationPair(camera, image, points_image, intensities, inputs.name)
    return start, at_image, float(np.linalg.norm(T_first_image[:3, 3]))


def kitti_sets(data: Path, args) -> tuple[list[FrameSet], dict]:
    """The KITTI sets named in the module docstring."""
    calib = data / KITTI / KITTI_CALIB
    camera, T_ref = load_camera(calib), read_ground_truth(calib)
    config = PreprocessConfig(mode="static")
    frames = range(20)
    inputs = [
        gather_files([kitti_paths(data, k)[0]], kitti_paths(data, k)[1], config, name=f"{k:010d}")
        for k in frames
    ]
    singles = static_pairs(inputs, camera, config)
    sets = [
        FrameSet(f"kitti single {k:02d}", "kitti single", [singles[k]], T_ref)
        for k in args.single_frames
    ]
    sets += [
        FrameSet(f"kitti 5 pairs {k:02d}-{k + 4:02d}", "kitti 5 pairs", singles[k : k + 5], T_ref)
        for k in args.five_sets
    ]
    if args.twenty:
        sets.append(FrameSet("kitti 20 pairs", "kitti 20 pairs", singles, T_ref))
    info: dict = {"frame_offset_m": {}}
    for first in args.accumulate:
        start, at_image, offset = accumulated_pair(data, first, args.acc_scans, camera, config)
        info["frame_offset_m"][f"{first:02d}"] = round(offset, 4)
        tag = f"{first:02d}-{first + args.acc_scans - 1:02d}"
        sets.append(
            FrameSet(f"kitti acc{args.acc_scans} start {tag}", "kitti acc start", [start], T_ref)
        )
        sets.append(
            FrameSet(f"kitti acc{args.acc_scans} image {tag}", "kitti acc image", [at_image], T_ref)
        )
    return sets, info


def pjlab_sets(data: Path, names) -> list[FrameSet]:
    """One set per PJLab frame (two rigs, one scan each)."""
    config = PreprocessConfig(mode="static")
    sets = []
    for name in names:
        folder = data / "pjlab" / name
        calib = folder / "calib_normalized.json"
        camera, T_ref = load_camera(calib), read_ground_truth(calib)
        inputs = [gather_files([folder / "lidar.pcd"], folder / "image.png", config, name=name)]
        sets.append(FrameSet(f"pjlab {name}", "pjlab", static_pairs(inputs, camera, config), T_ref))
    return sets


# ---------------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------------


def perturbations(count: int, seed: int, *, angle_deg: float = 1.0, distance: float = 0.05):
    """``count`` (rotation, translation) offsets of exactly ``angle_deg`` and ``distance``."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        axis, direction = rng.standard_normal(3), rng.standard_normal(3)
        axis /= np.linalg.norm(axis)
        direction /= np.linalg.norm(direction)
        out.append((so3_exp(math.radians(angle_deg) * axis), distance * direction))
    return out


def perturb(T_camera_lidar: np.ndarray, offset) -> np.ndarray:
    """Turn ``T_lidar_camera`` by ``R`` and move the camera centre by ``t`` (LiDAR frame)."""
    R, t = offset
    T_lidar_camera = invert_T(T_camera_lidar)
    return invert_T(make_T(R @ T_lidar_camera[:3, :3], T_lidar_camera[:3, 3] + t))


def run_set(frame_set: FrameSet, offsets, config: RefineConfig) -> dict:
    """Refine from every perturbed start; per-run figures and the set's summary."""
    T_ref = frame_set.T_camera_lidar_ref
    # the cost over the points visible at the reference: comparable between poses
    fixed, visible_ref = build_cost(frame_set.pairs, T_ref, config)
    nid_ref = fixed.value(T_ref)
    runs = []
    for offset in offsets:
        T0 = perturb(T_ref, offset)
        c0, w0 = time.process_time(), time.perf_counter()
        result = refine(frame_set.pairs, T0, config)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        err = pose_errors(result.T_camera_lidar, T_ref)
        nid_fixed = fixed.value(result.T_camera_lidar)
        runs.append(
            {
                "translation_cm": 100.0 * err["translation_error_m"],
                "rotation_deg": err["rotation_error_deg"],
                "cpu_s": cpu,
                "wall_s": wall,
                "outer": len(result.history),
                "evaluations": result.evaluations,
                "visible": int(sum(result.history[-1].visible_points)),
                "nid": result.nid,
                "nid_fixed_final": nid_fixed,
                "below_reference": bool(nid_fixed < nid_ref),
            }
        )
    return summarise(frame_set, runs, nid_ref, int(sum(visible_ref)))


def summarise(
    frame_set: FrameSet, runs: list[dict], nid_ref: float | None, visible_ref: int
) -> dict:
    """Median / max errors, success rate and costs of a set's runs."""
    t = np.array([r["translation_cm"] for r in runs])
    r = np.array([r["rotation_deg"] for r in runs])
    ok = (t < 100.0 * SUCCESS_TRANSLATION_M) & (r < SUCCESS_ROTATION_DEG)
    return {
        "name": frame_set.name,
        "group": frame_set.group,
        "pairs": len(frame_set.pairs),
        "points": int(sum(len(p.points_lidar) for p in frame_set.pairs)),
        "visible_at_reference": visible_ref,
        "nid_reference": nid_ref,
        "runs": runs,
        "median_translation_cm": float(np.median(t)),
        "max_translation_cm": float(np.max(t)),
        "median_rotation_deg": float(np.median(r)),
        "max_rotation_deg": float(np.max(r)),
        "success": float(ok.mean()),
        "below_reference": float(np.mean([x["below_reference"] for x in runs])),
        "median_cpu_s": float(np.median([x["cpu_s"] for x in runs])),
        "median_wall_s": float(np.median([x["wall_s"] for x in runs])),
        "median_visible": float(np.median([x["visible"] for x in runs])),
        "median_evaluations": float(np.median([x["evaluations"] for x in runs])),
    }


def group_rows(results: list[dict]) -> list[dict]:
    """Pool the runs of every set of a group (e.g. all single frames) into one row."""
    rows = []
    for group in dict.fromkeys(s["group"] for s in results):
        members = [s for s in results if s["group"] == group]
        pooled = FrameSet(f"{group} (all {len(members)} sets)", group, [], np.eye(4))
        runs = [run for s in members for run in s["runs"]]
        row = summarise(pooled, runs, None, 0)
        row["pairs"] = members[0]["pairs"]
        row["points"] = int(np.median([s["points"] for s in members]))
        row["visible_at_reference"] = int(np.median([s["visible_at_reference"] for s in members]))
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# Cost along single axes
# ---------------------------------------------------------------------------------------------

AXES = ("tx", "ty", "tz", "rx", "ry", "rz")


def landscape(frame_set: FrameSet, config: RefineConfig) -> dict:
    """Offset of the NID minimum along each axis from the reference, smooth and hard form.

    The visible points are fixed at the reference; translations span +-20 cm (1 cm steps),
    rotations +-2 degrees (0.1 degree steps); the chart is ``se3_exp(delta) @ T_ref``.
    """
    T_ref = frame_set.T_camera_lidar_ref
    out = {}
    for optimizer, form in (("lbfgs", "smooth"), ("nelder_mead", "hard")):
        cost, _ = build_cost(
            frame_set.pairs, T_ref, RefineConfig(optimizer=optimizer, bins=config.bins)
        )
        minima, depth = {}, {}
        for k, axis in enumerate(AXES):
            steps = np.linspace(-0.2, 0.2, 41) if k < 3 else np.radians(np.linspace(-2, 2, 41))
            values = []
            for s in steps:
                delta = np.zeros(6)
                delta[k] = s
                values.append(cost.value(se3_exp(delta) @ T_ref))
            values = np.array(values)
            best = int(np.argmin(values))
            minima[axis] = float(100 * steps[best] if k < 3 else math.degrees(steps[best]))
            depth[axis] = float(values.max() - values.min())
        out[form] = {"argmin": minima, "range": depth, "nid_reference": cost.value(T_ref)}
    return out


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------


def print_table(rows: list[dict]) -> None:
    """Markdown table of set summaries."""
    print(
        "| set | pairs | points | visible | median / max t (cm) | median / max r (deg) "
        "| success | NID below ref | evals | CPU s | wall s |"
    )
    print("|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|")
    for s in rows:
        print(
            f"| {s['name']} | {s['pairs']} | {s['points']} | {s['median_visible']:.0f} "
            f"| {s['median_translation_cm']:.1f} / {s['max_translation_cm']:.1f} "
            f"| {s['median_rotation_deg']:.2f} / {s['max_rotation_deg']:.2f} "
            f"| {100 * s['success']:.0f} % | {100 * s['below_reference']:.0f} % "
            f"| {s['median_evaluations']:.0f} | {s['median_cpu_s']:.2f} "
            f"| {s['median_wall_s']:.2f} |"
        )


def print_landscape(shapes: dict) -> None:
    """Markdown table of where the cost minimum lands along each axis."""
    print("| set | form | " + " | ".join(f"{a} min" for a in AXES) + " | NID at ref |")
    print("|---|---|" + "---:|" * 7)
    for name, by_form in shapes.items():
        for form, s in by_form.items():
            cells = " | ".join(
                f"{s['argmin'][a]:+.0f} cm" if a[0] == "t" else f"{s['argmin'][a]:+.1f} deg"
                for a in AXES
            )
            print(f"| {name} | {form} | {cells} | {s['nid_reference']:.4f} |")


def parse_args(argv=None):
    """Command line (module docstring)."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--data", type=Path, default=DATA, help="the real-data folder")
    ap.add_argument("--quick", action="store_true", help="small smoke run (~1 min CPU)")
    ap.add_argument("--perturbations", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--optimizer", choices=("lbfgs", "nelder_mead"), default=None)
    ap.add_argument("--threads", type=int, default=1, help="numba threads (module docstring)")
    ap.add_argument("--landscape", action="store_true", help="cost along single axes")
    ap.add_argument("--acc-scans", type=int, default=5, help="scans per accumulated cloud")
    ap.add_argument("--ftol", type=float, default=None, help="RefineConfig.lbfgs_ftol")
    args = ap.parse_args(argv)
    if args.quick:
        args.perturbations = min(args.perturbations, 2)
        args.single_frames, args.five_sets, args.twenty = [0], [0], False
        args.accumulate, args.pjlab = [0], PJLAB[:1]
    else:
        args.single_frames, args.five_sets, args.twenty = [0, 5, 10, 15], [0, 5, 10, 15], True
        args.accumulate, args.pjlab = [0, 10], PJLAB
    return args


def main(argv=None):
    args = parse_args(argv)
    if not (args.data / KITTI).is_dir():
        print(f"real data not found at {args.data}", file=sys.stderr)
        return 1
    import numba

    numba.set_num_threads(args.threads)
    config = RefineConfig()
    if args.optimizer is not None:
        config = replace(config, optimizer=args.optimizer)
    if args.ftol is not None:
        config = replace(config, lbfgs_ftol=args.ftol)
    offsets = perturbations(args.perturbations, args.seed)

    t0 = time.perf_counter()
    kitti, info = kitti_sets(args.data, args)
    sets = kitti + pjlab_sets(args.data, args.pjlab)
    print(f"loaded {len(sets)} sets in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    results = []
    for frame_set in sets:
        results.append(run_set(frame_set, offsets, config))
        s = results[-1]
        print(
            f"{s['name']}: t {s['median_translation_cm']:.1f} cm, r {s['median_rotation_deg']:.2f}"
            f" deg, success {s['success']:.2f}, {s['median_cpu_s']:.1f} s CPU",
            file=sys.stderr,
        )
    load = Path("/proc/loadavg").read_text().split()[:3] if os.path.exists("/proc/loadavg") else []
    print(f"\nRefineConfig: {asdict(config)}; numba threads {args.threads}; load {' '.join(load)}")
    print(
        f"success: translation < {100 * SUCCESS_TRANSLATION_M:.0f} cm and rotation < "
        f"{SUCCESS_ROTATION_DEG} deg; start 5 cm / 1 deg; {args.perturbations} perturbations "
        f"(seed {args.seed}); accumulated frames: image frame {info['frame_offset_m']} m from the "
        "scan-start frame\n"
    )
    print_table(results)
    print()
    print_table(group_rows(results))
    sys.stdout.flush()  # the tables survive an interrupted landscape
    shapes = {}
    if args.landscape:
        pick = [s for s in sets if s.group != "kitti 20 pairs"]
        shapes = {s.name: landscape(s, config) for s in pick}
        print()
        print_landscape(shapes)
    summary = {
        "benchmark": "real_registration",
        "quick": args.quick,
        "refine_config": asdict(config),
        "threads": args.threads,
        "perturbation": {"rotation_deg": 1.0, "translation_m": 0.05, "count": args.perturbations},
        "seed": args.seed,
        "success_threshold": {
            "translation_m": SUCCESS_TRANSLATION_M,
            "rotation_deg": SUCCESS_ROTATION_DEG,
        },
        "frame_offset_m": info["frame_offset_m"],
        "groups": {
            r["name"]: {k: v for k, v in r.items() if k != "runs"} for r in group_rows(results)
        },
        "sets": results,
        "landscape": shapes,
        "loadavg": load,
        "machine": platform.machine(),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
