"""Fine-registration accuracy and basin of convergence on synthetic pairs (issue #5, item 5).

Every pair is simulated in-process with :mod:`nbcalib.synthetic.rig` and registered with its
ground-truth dense cloud (deskewed by the true trajectory); intensities and image are equalised as
``nbcalib preprocess`` does. Errors follow docs/conventions.md section 10 (camera centre in the
LiDAR frame, rotation angle).

1. Accuracy: for each combination LiDAR x camera (spinning64 / livox x plumb_bob / omnidir, plus
   spinning64 x fisheye), ``--seeds`` rigs; each run starts 5-10 cm and 1-2 degrees off in random
   directions and uses one pair, then the same rig's three pairs. Median and max errors; the
   optimiser is ``--optimizer`` (default: RefineConfig's).
2. Basin: on one pair of spinning64 x omnidir (``--basin-combo``), ``--trials`` random starts
   per initial error (1 deg / 5 cm, 2 / 10, 3 / 20, 5 / 30) for each optimiser (hybrid, lbfgs,
   nelder_mead; ``--nm-step`` sets Nelder-Mead's initial simplex); success = final
   error < 2 cm and < 0.2 degrees.

Timings are process CPU seconds (serial kernels) beside wall seconds; the load average is
printed. The last line of the output is one JSON object.

Usage::

    python benchmarks/bench_registration.py            # about 15-20 CPU minutes
    python benchmarks/bench_registration.py --seeds 3 --max-points 200000 --trials 5   # ~6 min
    python benchmarks/bench_registration.py --quick    # smoke run, about a minute
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
from nbcalib.registration.config import OPTIMIZERS
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
from nbcalib.synthetic.rig import RigConfig, generate_sequence
from nbcalib.transforms import invert_T, pose_error, so3_exp

COMBOS = [
    ("spinning64", "plumb_bob"),
    ("spinning64", "omnidir"),
    ("livox", "plumb_bob"),
    ("livox", "omnidir"),
    ("spinning64", "fisheye"),
]
BASIN_LEVELS = [(1.0, 0.05), (2.0, 0.10), (3.0, 0.20), (5.0, 0.30)]  # (degrees, metres)
SUCCESS_CM, SUCCESS_DEG = 2.0, 0.2


def perturbed(T_camera_lidar, rng, translation_m, rotation_deg):
    """``T_camera_lidar`` with the camera ``translation_m``, ``rotation_deg`` off (random axes)."""
    T_lidar_camera = invert_T(T_camera_lidar)
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    T = T_lidar_camera.copy()
    T[:3, :3] = T[:3, :3] @ so3_exp(axis / np.linalg.norm(axis) * math.radians(rotation_deg))
    T[:3, 3] += shift / np.linalg.norm(shift) * translation_m
    return invert_T(T)


def errors(T_est, T_true):
    """(centimetres, degrees) between two ``T_camera_lidar``."""
    dt, dr = pose_error(invert_T(T_est), invert_T(T_true))
    return 100.0 * float(dt), float(dr)


def make_pair(lidar, camera, seed, pair, *, max_points, image_size):
    """One synthetic pair as a RegistrationPair (ground-truth dense cloud) and the truth."""
    rig = RigConfig(lidar=lidar, camera=camera, seed=seed, image_size=image_size)
    seq = generate_sequence(rig, pair=pair)
    points, raw = seq.dense_cloud()
    if max_points and len(points) > max_points:
        keep = np.random.default_rng([seed, pair]).choice(len(points), max_points, replace=False)
        points, raw = points[keep], raw[keep]
    image = equalize_image(seq.image)
    name = f"{lidar}-{camera}-{seed}-{pair}"
    rp = RegistrationPair(seq.camera, image, points, equalize_point_intensities(raw), name)
    return rp, seq.T_camera_lidar


def fresh(pair: RegistrationPair) -> RegistrationPair:
    """The same pair without what an earlier run cached (KD-tree, orientation classes)."""
    return RegistrationPair(pair.camera, pair.image, pair.points_lidar, pair.intensities, pair.name)


def run_one(pairs, T_true, T_init, config):
    """Refine; return errors, CPU and wall seconds, evaluations."""
    cpu, wall = time.process_time(), time.perf_counter()
    result = refine(pairs, T_init, config)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    cm, deg = errors(result.T_camera_lidar, T_true)
    return {"cm": cm, "deg": deg, "cpu": cpu, "wall": wall, "evals": result.evaluations}


def summary(rows):
    """Median / max of errors and mean CPU seconds of a list of run_one rows."""
    cm = [r["cm"] for r in rows]
    deg = [r["deg"] for r in rows]
    return {
        "median_cm": statistics.median(cm),
        "max_cm": max(cm),
        "median_deg": statistics.median(deg),
        "max_deg": max(deg),
        "cpu_s": statistics.mean(r["cpu"] for r in rows),
        "wall_s": statistics.mean(r["wall"] for r in rows),
        "n": len(rows),
    }


def main(argv=None) -> int:
    """Run the benchmark; print markdown tables, then one JSON line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="one combination, one seed, small")
    parser.add_argument("--seeds", type=int, default=3, help="rigs per combination")
    parser.add_argument("--trials", type=int, default=4, help="starts per basin level")
    parser.add_argument("--max-points", type=int, default=600_000, help="dense points per pair")
    parser.add_argument("--pyramid-levels", type=int, default=RefineConfig().pyramid_levels)
    parser.add_argument("--no-basin", action="store_true")
    parser.add_argument(
        "--combos", default=None, help="comma-separated LIDAR:CAMERA (default: all five)"
    )
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--basin-combo", default="spinning64:omnidir", help="LIDAR:CAMERA")
    parser.add_argument(
        "--plain-nid",
        action="store_true",
        help="one histogram per pair (orientation_classes=False), for side-by-side runs",
    )
    parser.add_argument(
        "--optimizer",
        choices=OPTIMIZERS,
        default=RefineConfig().optimizer,
        help="optimiser of the accuracy table (the basin runs both)",
    )
    parser.add_argument(
        "--nm-step",
        type=float,
        default=RefineConfig().nelder_mead_init_step,
        help="RefineConfig.nelder_mead_init_step (accuracy table and basin)",
    )
    parser.add_argument(
        "--points-per-pixel",
        default=None,
        help="comma-separated RefineConfig.points_per_pixel values ('none': every visible point)"
        " run side by side on the same pairs and starts (default: RefineConfig's)",
    )
    parser.add_argument(
        "--cost",
        default=None,
        help="comma-separated RefineConfig.cost values (nbcalib calibrate --cost) run side by "
        "side on the same pairs and starts (default: RefineConfig's)",
    )
    parser.add_argument(
        "--nm-tolerances",
        default=None,
        help="comma-separated XATOL:FATOL of Nelder-Mead (RefineConfig.nelder_mead_xatol, "
        "nelder_mead_fatol) run side by side on the same pairs and starts, e.g. "
        "'1e-6:1e-8,1e-4:1e-5' (SciPy's own, then the default)",
    )
    args = parser.parse_args(argv)
    if args.points_per_pixel is None:
        ppps = [RefineConfig().points_per_pixel]
    else:
        ppps = [
            None if v.strip().lower() == "none" else float(v)
            for v in args.points_per_pixel.split(",")
        ]
    costs = args.cost.split(",") if args.cost else [RefineConfig().cost]
    default_tol = (RefineConfig().nelder_mead_xatol, RefineConfig().nelder_mead_fatol)
    tolerances = [
        tuple(float(x) for x in v.split(":")) for v in (args.nm_tolerances or "").split(",") if v
    ] or [default_tol]
    # (label, RefineConfig overrides) of every variant run side by side
    variants = [
        (
            (f"-ppp{v}" if len(ppps) > 1 else "")
            + (f"-cost{c}" if len(costs) > 1 else "")
            + (f"-nm{xa:g}:{fa:g}" if len(tolerances) > 1 else ""),
            {"points_per_pixel": v, "cost": c, "nelder_mead_xatol": xa, "nelder_mead_fatol": fa},
        )
        for v in ppps
        for c in costs
        for xa, fa in tolerances
    ]
    combos, seeds, trials, max_points = COMBOS, range(args.seeds), args.trials, args.max_points
    if args.combos:
        combos = [tuple(c.split(":")) for c in args.combos.split(",")]
    if args.no_accuracy:
        combos = []
    image_size = None
    if args.quick:
        combos, seeds, trials, max_points = COMBOS[:1], range(1), 1, 150_000
        image_size = (640, 480)
    load = open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else []
    print(f"load average at start: {' '.join(load)}", file=sys.stderr)
    classes = not args.plain_nid
    config = RefineConfig(
        optimizer=args.optimizer,
        parallel=False,
        pyramid_levels=args.pyramid_levels,
        orientation_classes=classes,
        nelder_mead_init_step=args.nm_step,
    )
    out = {"load_start": load, "max_points": max_points, "config": vars(args), "accuracy": {}}

    # 1. accuracy per combination, one pair and three pairs
    side_by_side = len(variants) > 1
    ppp_head = "variant | " if side_by_side else ""
    print(f"| LiDAR x camera | {ppp_head}pairs | runs | median cm | max cm | median deg | max deg |"
          " CPU s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|" + ("---|" if side_by_side else ""))
    all_one = {label: [] for label, _ in variants}
    for lidar, camera in combos:
        rows = {(label, n): [] for label, _ in variants for n in (1, 3)}
        for seed in seeds:
            made = [
                make_pair(lidar, camera, seed, k, max_points=max_points, image_size=image_size)
                for k in range(3)
            ]
            T_true = made[0][1]
            rng = np.random.default_rng([seed, 5])
            T_init = perturbed(T_true, rng, rng.uniform(0.05, 0.10), rng.uniform(1.0, 2.0))
            for label, overrides in variants:
                for n in (1, 3):
                    pairs = [fresh(m[0]) for m in made[:n]]  # no normals from a run before
                    cfg = replace(config, **overrides)
                    rows[label, n].append(run_one(pairs, T_true, T_init, cfg))
        for label, _ in variants:
            for n in (1, 3):
                s = summary(rows[label, n])
                out["accuracy"][f"{lidar}-{camera}-{n}{label}"] = s
                cell = f"{label.lstrip('-')} | " if side_by_side else ""
                print(
                    f"| {lidar} x {camera} | {cell}{n} | {s['n']} | {s['median_cm']:.2f} "
                    f"| {s['max_cm']:.2f} | {s['median_deg']:.3f} | {s['max_deg']:.3f} "
                    f"| {s['cpu_s']:.1f} |",
                    flush=True,
                )
            all_one[label] += rows[label, 1]
    for label, _ in variants:
        if all_one[label]:
            one = summary(all_one[label])
            out["one_pair_all" + label] = one
            if side_by_side:
                print(
                    f"all one-pair runs, {label.lstrip('-')}: {one['median_cm']:.2f} cm / "
                    f"{one['median_deg']:.3f} deg median, {one['cpu_s']:.1f} CPU s mean"
                )
            else:
                out["target_met"] = one["median_cm"] <= 1.0 and one["median_deg"] <= 0.1

    # 2. basin of convergence, each optimiser
    if not args.no_basin:
        lidar, camera = args.basin_combo.split(":")
        pair, T_true = make_pair(lidar, camera, 0, 0, max_points=max_points, image_size=image_size)
        print(
            f"\nbasin ({lidar} x {camera}, seed 0, "
            f"success < {SUCCESS_CM} cm and < {SUCCESS_DEG} deg)"
        )
        print("| optimiser | initial error | success | median cm | median deg | CPU s |")
        print("|---|---|---|---|---|---|")
        out["basin"] = {}
        for optimizer in OPTIMIZERS:
            cfg = RefineConfig(
                optimizer=optimizer,
                parallel=False,
                pyramid_levels=args.pyramid_levels,
                orientation_classes=classes,
                nelder_mead_init_step=args.nm_step,
            )
            for deg, metres in BASIN_LEVELS[: 1 if args.quick else None]:
                rng = np.random.default_rng([int(deg * 10), 17])
                rows = [
                    run_one([pair], T_true, perturbed(T_true, rng, metres, deg), cfg)
                    for _ in range(trials)
                ]
                ok = sum(r["cm"] < SUCCESS_CM and r["deg"] < SUCCESS_DEG for r in rows)
                s = summary(rows)
                out["basin"][f"{optimizer}-{deg:g}deg-{100 * metres:g}cm"] = {
                    "success": ok / len(rows),
                    **s,
                }
                print(
                    f"| {optimizer} | {deg:g} deg, {100 * metres:g} cm | {ok}/{len(rows)} "
                    f"| {s['median_cm']:.2f} | {s['median_deg']:.3f} | {s['cpu_s']:.1f} |",
                    flush=True,
                )
    out["load_end"] = open("/proc/loadavg").read().split()[:3] if load else []
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
