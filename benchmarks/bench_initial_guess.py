"""Initial guess from 2D-3D correspondences: speed of the RANSAC kernel and LM, and success rate
against the outlier fraction for every camera model (synthetic correspondences, known answer).

Run:  python benchmarks/bench_initial_guess.py [--trials 10] [--skip-speed] [--skip-accuracy]
      python benchmarks/bench_initial_guess.py --end-to-end [--quick] [--matcher M] [--real]

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

End to end (``--end-to-end``): every synthetic LiDAR (spinning16/32/64/128, livox) x camera
model (7) pair, made by :func:`nbcalib.synthetic.generate_sequence` (dense cloud of the true
trajectory, equalised intensities and image as ``nbcalib preprocess`` stores them), matched by
:func:`nbcalib.initial_guess.match_views` (camera-shaped LiDAR views at 12 headings, no prior),
then :func:`nbcalib.initial_guess.estimate_initial_guess` with the matches' confidences as
weights (as ``nbcalib initial-guess``). ``--quick``: one seed per combination, street and room
alternating (35 pairs); otherwise seeds 0..``--seeds``-1 and both scenes. ``--real`` adds the
KITTI (single scan, 20 scans accumulated) and PJLab frames of ../shared/data/real, without and
with a prior (the reference extrinsic turned by 10 degrees of yaw and moved by 0.2 m).
A correspondence is *correct* when its 3-D point projects within 8 px of the camera keypoint
under the true pose. Side-by-side pictures of the best view go to ``--pictures``.

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
from nbcalib.initial_guess.estimate import _MEMO
from nbcalib.kernels import ransac as K
from nbcalib.metrics import pose_errors
from nbcalib.reference import ransac as ref
from nbcalib.synthetic import default_T_camera_lidar
from nbcalib.transforms import make_T

PROCEDURES = {
    "reference": dict(
        candidates=1, local_optimization=False, initial_translation="zero", polish=False
    ),
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

        def estimate(c=c):  # the same inputs each time: not the estimate memo's answer
            _MEMO.clear()
            return estimate_initial_guess(camera, c.uv_camera, c.points_lidar)

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


LIDARS = ("spinning16", "spinning32", "spinning64", "spinning128", "livox")


def _correct(camera, T_camera_lidar, corr, tol_px=8.0) -> int:
    from nbcalib.transforms import transform_points

    if len(corr) == 0:
        return 0
    uv, ok = camera.project(transform_points(T_camera_lidar, corr.points_lidar))
    error = np.where(ok, np.linalg.norm(uv - corr.uv_camera, axis=1), np.inf)
    return int(np.count_nonzero(error < tol_px))


def end_to_end_pair(
    name,
    camera,
    image,
    points,
    intensities,
    truth,
    matcher,
    *,
    prior=None,
    pictures=None,
    **view_options,
) -> dict:
    """Match views, estimate, score against ``truth``; one row of the table."""
    from nbcalib.errors import InputError
    from nbcalib.matching import match_views

    load = os.getloadavg()[0]
    wall, cpu = time.perf_counter(), time.process_time()
    mv = match_views(
        camera, image, points, intensities, matcher=matcher, T_camera_lidar_prior=prior
    )
    t_match = (time.perf_counter() - wall, time.process_time() - cpu)
    corr = mv.correspondences
    row = {
        "pair": name,
        "matcher": matcher,
        "prior": prior is not None,
        "views": len(mv.views),
        "best_heading_deg": None if mv.best < 0 else round(mv.views[mv.best].view.heading_deg, 1),
        "per_view": [
            [
                round(v.view.heading_deg),
                v.matches.num_matches,
                len(v.correspondences),
                _correct(camera, truth, v.correspondences),
                v.ransac_inliers,
            ]
            for v in mv.views
        ],
        "correspondences": len(corr),
        "correct": _correct(camera, truth, corr),
    }
    row["inlier_ratio"] = round(row["correct"] / max(len(corr), 1), 3)
    try:
        g = estimate_initial_guess(camera, corr.uv_camera, corr.points_lidar, weights=corr.weights)
        e = pose_errors(g.T_camera_lidar, truth)
        row.update(
            flagged_ok=bool(g.success),
            inliers=g.n_inliers,
            rot_err_deg=round(e["rotation_error_deg"], 3),
            trans_err_m=round(e["translation_error_m"], 3),
        )
        row["success"] = e["rotation_error_deg"] < 1.0 and e["translation_error_m"] < 0.5
    except InputError as exc:
        row.update(flagged_ok=False, inliers=0, rot_err_deg=None, trans_err_m=None, success=False)
        row["error"] = str(exc)
    row.update(
        match_wall_s=round(t_match[0], 1),
        match_cpu_s=round(t_match[1], 1),
        total_wall_s=round(time.perf_counter() - wall, 1),
        total_cpu_s=round(time.process_time() - cpu, 1),
        load=round(load, 1),
    )
    if pictures and mv.best >= 0:
        from pathlib import Path

        from nbcalib.io.image import write_png
        from nbcalib.matching.draw import draw_matches

        best = mv.views[mv.best]
        folder = Path(pictures)
        folder.mkdir(parents=True, exist_ok=True)
        stem = name.replace(" ", "_") + ("_prior" if prior is not None else "")
        # the camera image at the view's scale, so that both sides have the same resolution
        import cv2

        small = cv2.resize(image, best.view.intensity.shape[::-1], interpolation=cv2.INTER_AREA)
        m = best.matches
        from nbcalib.matching.matches import Matches

        s = best.view.scale
        shown = Matches((m.kpts_camera + 0.5) * s - 0.5, m.kpts_lidar, m.matches, m.confidence)
        write_png(folder / f"{stem}.png", draw_matches(small, best.view.intensity, shown))
    return row


def synthetic_end_to_end(quick: bool, seeds: int, matcher: str, cameras, lidars, pictures):
    from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
    from nbcalib.synthetic import RigConfig, generate_sequence

    rows = []
    k = 0
    for lidar in lidars:
        for camera_name in cameras:
            if quick:
                plan = [(("street", "room")[k % 2], k % 3)]
            else:
                plan = [(scene, seed) for seed in range(seeds) for scene in ("street", "room")]
            k += 1
            for scene, seed in plan:
                config = RigConfig(lidar=lidar, camera=camera_name, scene=scene, seed=seed)
                seq = generate_sequence(config)
                points, intensities = seq.dense_cloud()
                name = f"{lidar} {camera_name} {scene} {seed}"
                row = end_to_end_pair(
                    name,
                    seq.camera,
                    equalize_image(seq.image),
                    points,
                    equalize_point_intensities(intensities),
                    seq.T_camera_lidar,
                    matcher,
                    pictures=pictures,
                )
                row.update(lidar=lidar, camera=camera_name, scene=scene, seed=seed)
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def real_end_to_end(matcher: str, pictures, accumulate: int = 20, frames=None, **view_options):
    """KITTI and PJLab frames, without and with a rough prior."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_matching as bm

    from nbcalib.preprocess.intensity import equalize_point_intensities
    from nbcalib.transforms import so3_exp

    if not bm.REAL.is_dir():
        return []
    makers = {
        "kitti0": lambda: bm.kitti_pair(0),
        "kitti10": lambda: bm.kitti_pair(10),
        "kitti_acc": lambda: bm.kitti_accumulated_pair(accumulate),
        "pjlab_auto": lambda: bm.pjlab_pair("auto_calib"),
        "pjlab_manual": lambda: bm.pjlab_pair("manual_calib_0"),
    }
    makers = [make for key, make in makers.items() if frames is None or key in frames]
    rows = []
    for make in makers:
        pair = make()
        truth = pair["T_camera_lidar"]
        # a rough prior: 10 degrees of yaw about LiDAR z and 0.2 m off
        turn = np.eye(4)
        turn[:3, :3] = so3_exp(np.array([0.0, 0.0, np.radians(10.0)]))
        prior = truth @ turn
        prior[:3, 3] += np.array([0.2, 0.0, 0.0])
        intensities = equalize_point_intensities(pair.get("intensities", None))
        for p in (None, prior):
            row = end_to_end_pair(
                pair["name"],
                pair["camera"],
                pair["camera_image"],
                pair["points"],
                intensities,
                truth,
                matcher,
                prior=p,
                pictures=pictures,
                **view_options,
            )
            row["view_options"] = view_options
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def print_end_to_end_table(rows) -> None:
    print(
        "| pair | views | correspondences | correct | inlier ratio | final inliers | "
        "rot err deg | trans err m | success | CPU s | load |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|")
    for r in rows:
        prior = " (prior)" if r.get("prior") else ""
        print(
            f"| {r['pair']}{prior} | {r['views']} | {r['correspondences']} | {r['correct']} | "
            f"{r['inlier_ratio']:.2f} | {r['inliers']} | {r['rot_err_deg']} | "
            f"{r['trans_err_m']} | {'yes' if r['success'] else 'NO'}"
            f"{'' if r['flagged_ok'] or not r['success'] else ' (flagged)'} | "
            f"{r['total_cpu_s']} | {r['load']} |"
        )


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
    ap.add_argument("--end-to-end", action="store_true", help="synthetic pairs -> matches -> guess")
    ap.add_argument("--quick", action="store_true", help="end to end: one seed per combination")
    ap.add_argument("--seeds", type=int, default=2, help="end to end: seeds per combination")
    ap.add_argument("--matcher", default="auto", help="end to end: matcher")
    ap.add_argument("--lidars", default=",".join(LIDARS))
    ap.add_argument("--real", action="store_true", help="end to end on ../shared/data/real")
    ap.add_argument("--no-synthetic", action="store_true", help="end to end: real frames only")
    ap.add_argument("--pictures", default=None, help="end to end: folder for match pictures")
    ap.add_argument(
        "--frames",
        default=None,
        help="real frames (kitti0,kitti10,kitti_acc,pjlab_auto,pjlab_manual; default all)",
    )
    ap.add_argument("--pixels-per-degree", type=float, default=None, help="views' resolution")
    ap.add_argument("--median", type=int, default=0, help="median filter of the views")
    ap.add_argument("--out", default=None, help="end to end: write the rows as JSON")
    args = ap.parse_args()
    if args.end_to_end:
        from nbcalib.matching import resolve_matcher

        matcher = resolve_matcher(args.matcher)
        rows = []
        load0 = os.getloadavg()
        if not args.no_synthetic:
            rows += synthetic_end_to_end(
                args.quick,
                args.seeds,
                matcher,
                args.models.split(","),
                args.lidars.split(","),
                args.pictures,
            )
        if args.real:
            view_options = {"median": args.median}
            if args.pixels_per_degree:
                view_options["pixels_per_degree"] = args.pixels_per_degree
            frames = args.frames.split(",") if args.frames else None
            rows += real_end_to_end(matcher, args.pictures, frames=frames, **view_options)
        print_end_to_end_table(rows)
        synthetic = [r for r in rows if "lidar" in r]
        summary = {
            "matcher": matcher,
            "load_average_start": load0,
            "load_average_end": os.getloadavg(),
            "synthetic_success": sum(r["success"] for r in synthetic),
            "synthetic_pairs": len(synthetic),
            "mean_cpu_s": float(np.mean([r["total_cpu_s"] for r in rows])) if rows else None,
        }
        if args.out:
            with open(args.out, "w") as f:
                json.dump(rows, f, indent=1)
        print(json.dumps(summary))
        return
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
