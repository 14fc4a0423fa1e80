"""Initial guess from 2D-3D correspondences: speed of the RANSAC kernel and LM, and success rate
against the outlier fraction for every camera model (synthetic correspondences, known answer).

Run:  python benchmarks/bench_initial_guess.py [--trials 10] [--skip-speed] [--skip-accuracy]

Speed: the rotation-only RANSAC kernel (8192 hypotheses) serial and parallel for M
correspondences, the slow reference per hypothesis, one LM refinement and one full estimate.

Accuracy: per camera model (the example lens of each kind, 1280 x 960, equirectangular 1280 x 640),
per outlier fraction, ``--trials`` rigs from ``nbcalib.synthetic.default_T_camera_lidar("spinning",
seed)`` (camera yaw anywhere in +-180 degrees: forwards, sideways, backwards; 5-30 cm from the
LiDAR) with ``--inliers`` true correspondences (1 px noise) plus outliers
(:func:`nbcalib.initial_guess.synthetic_correspondences`). Two range regimes: "street" (points 2-40
m from the camera) and "room" (1-10 m, where the translation is a large fraction of the range and
rotation-only RANSAC's far-field assumption is strained). Success is the paper's criterion:
rotation error < 1 degree and translation error < 0.5 m. Two procedures: "reference" (the
reference toolbox's: best RANSAC rotation, zero translation, one LM over all correspondences) and
"nbcalib" (the defaults of :func:`nbcalib.initial_guess.estimate_initial_guess`).

The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import time

import numba
import numpy as np

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.initial_guess import (
    estimate_initial_guess,
    refine_pose_lm,
    synthetic_correspondences,
    usable_correspondences,
)
from nbcalib.kernels import ransac as K
from nbcalib.metrics import pose_errors
from nbcalib.reference import ransac as ref
from nbcalib.synthetic import default_T_camera_lidar
from nbcalib.transforms import make_T

PROCEDURES = {
    "reference": dict(candidates=1, local_optimization=False, initial_translation="zero"),
    "nbcalib": {},
}
RANGES = {"street": (2.0, 40.0), "room": (1.0, 10.0)}


def best_time(fn, repeat):
    """Best wall time of ``repeat`` runs after a warm-up; also the process CPU time of that run."""
    fn()  # warm up (compilation, caches)
    best = (np.inf, np.inf)
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t0, time.process_time() - c0))
    return best


def speed(repeat: int) -> dict:
    rows = {}
    camera = example_camera("plumb_bob")
    truth = default_T_camera_lidar("spinning", 0)
    for m in (500, 2000):
        c = synthetic_correspondences(camera, truth, 0, n_inliers=m // 5, outlier_fraction=0.8)
        bc, bl, usable = usable_correspondences(camera, c.uv_camera, c.points_lidar)
        bc, bl, uv = (np.ascontiguousarray(a[usable]) for a in (bc, bl, c.uv_camera))
        counts = np.empty(8192, dtype=np.int64)
        for name, kernel in (
            ("serial", K._hypothesis_counts),
            ("parallel", K._hypothesis_counts_parallel),
        ):
            run = functools.partial(
                kernel, camera.model_id, camera.params, bc, bl, uv, 25.0, np.uint64(0), counts
            )
            wall, cpu = best_time(run, repeat)
            rows[f"ransac_8192_M{m}_{name}_s"] = wall
            rows[f"ransac_8192_M{m}_{name}_cpu_s"] = cpu
        n_ref = 20
        ref.hypothesis_counts(camera.model_id, camera.params, bc, bl, uv, 5.0, 1, 0)  # warm up
        t0 = time.perf_counter()
        ref.hypothesis_counts(camera.model_id, camera.params, bc, bl, uv, 5.0, n_ref, 0)
        rows[f"reference_per_hypothesis_M{m}_s"] = (time.perf_counter() - t0) / n_ref
        start = make_T(truth[:3, :3], np.zeros(3))
        lm = functools.partial(refine_pose_lm, camera, c.uv_camera, c.points_lidar, start)
        rows[f"lm_M{m}_s"] = best_time(lm, repeat)[0]
        estimate = functools.partial(estimate_initial_guess, camera, c.uv_camera, c.points_lidar)
        rows[f"estimate_M{m}_s"] = best_time(estimate, repeat)[0]
    return rows


def accuracy(trials: int, inliers: int, fractions, models) -> dict:
    table = {}
    for regime, range_m in RANGES.items():
        for model in models:
            camera = example_camera(model)
            for fraction in fractions:
                tally = {p: [] for p in PROCEDURES}
                for trial in range(trials):
                    truth = default_T_camera_lidar("spinning", trial)
                    c = synthetic_correspondences(
                        camera,
                        truth,
                        [trial, int(fraction * 100)],
                        n_inliers=inliers,
                        outlier_fraction=fraction,
                        range_m=range_m,
                    )
                    for name, options in PROCEDURES.items():
                        t0 = time.perf_counter()
                        g = estimate_initial_guess(
                            camera, c.uv_camera, c.points_lidar, seed=trial, **options
                        )
                        dt = time.perf_counter() - t0
                        e = pose_errors(g.T_camera_lidar, truth)
                        ok = e["rotation_error_deg"] < 1.0 and e["translation_error_m"] < 0.5
                        tally[name].append(
                            (ok, g.success, e["rotation_error_deg"], e["translation_error_m"], dt)
                        )
                for name, rows in tally.items():
                    a = np.array(rows, dtype=float)
                    key = f"{regime}/{model}/{fraction:.2f}/{name}"
                    table[key] = {
                        "success": float(a[:, 0].mean()),
                        "flagged_ok": float(a[:, 1].mean()),
                        "false_ok": int(np.sum((a[:, 1] == 1) & (a[:, 0] == 0))),
                        "rot_median_deg": float(np.median(a[:, 2])),
                        "trans_median_m": float(np.median(a[:, 3])),
                        "time_s": float(a[:, 4].mean()),
                    }
                    print(key, json.dumps(table[key]), flush=True)
    return table


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--inliers", type=int, default=50)
    ap.add_argument("--fractions", default="0.5,0.7,0.8,0.9")
    ap.add_argument("--models", default=",".join(CAMERA_MODELS))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--skip-speed", action="store_true")
    ap.add_argument("--skip-accuracy", action="store_true")
    args = ap.parse_args()
    out = {
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"numba {numba.__version__}, {numba.get_num_threads()} threads",
        "load_average": os.getloadavg()[0],
    }
    if not args.skip_speed:
        out["speed"] = speed(args.repeat)
        print(json.dumps(out["speed"]), flush=True)
    if not args.skip_accuracy:
        fractions = [float(f) for f in args.fractions.split(",")]
        out["accuracy"] = accuracy(args.trials, args.inliers, fractions, args.models.split(","))
    out["load_average_end"] = os.getloadavg()[0]
    print(json.dumps(out))


if __name__ == "__main__":
    main()
