"""Benchmark: dense clouds by continuous-time ICP (nbcalib.odometry.integrate_dynamic).

Two parts:

- ``synthetic``: a 64-beam LiDAR (``spinning64``, 65 k points a scan, 10 Hz) nodding in a room
  and driving in a street (``nbcalib.synthetic``, 3 s = 30 scans each, with ground truth).
  Per-scan pose errors of the begin and end poses (at the first and last point times) in the
  frame of the first scan, drift (end position error over the path length), the floor set by
  the motion model (how far the true trajectory strays, inside one scan, from slerp + lerp
  between its true begin and end poses), and the sharpness of the accumulated cloud: RMS
  distance of the points on planar primitives (rectangles, box faces) to their true surface, for
  the deskewed cloud, for the same scans placed rigidly at their estimated mid-scan pose (no
  deskewing), and for the ground-truth deskewing (the floor: range noise); plus the local-PCA
  thickness (:func:`nbcalib.odometry.local_thickness`) of the same clouds.
- ``kitti``: the 20 real KITTI frames (``../shared/data/real/kitti_raw_2011_09_26``, Velodyne
  HDL-64E, ~114 k points a scan, 0.1 s apart, no per-point times: synthesised from the azimuth).
  Speed (best of ``--repeat`` runs, wall and CPU time of the process, with the 1-minute load
  average): the default (plane lookups split over two threads, accumulation on a background
  thread), everything on one thread, and numba's ``prange`` kernels instead of threads;
  local-PCA thickness deskewed vs rigid; clockwise vs counter-clockwise times.

The last line printed is one JSON object with every figure.

Run: ``python benchmarks/bench_integrate.py [--parts synthetic,kitti] [--repeat 3]
[--lidars spinning16,spinning64,spinning128] [--seeds 0,1,2]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from nbcalib.odometry import (
    DynamicIntegrationConfig,
    deskew,
    integrate_dynamic,
    local_thickness,
    normalized_scan_times,
    synthesize_times_from_azimuth,
)
from nbcalib.transforms import interpolate_pose, invert_T, pose_error, transform_points

KITTI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
KITTI = KITTI / "kitti_raw_2011_09_26"


def _timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


# ---------------------------------------------------------------------------------------------
# Synthetic sequences with ground truth
# ---------------------------------------------------------------------------------------------


def _surface_distance(prims, prim_index, points_world):
    """Distance of each point to the surface of its primitive (rectangles and boxes only)."""
    from nbcalib.kernels.raycast import BOX, PRIM_AXES, PRIM_CENTER, PRIM_HALF, PRIM_TYPE, RECTANGLE

    out = np.full(len(points_world), np.nan)
    P = prims[prim_index]
    kind = P[:, PRIM_TYPE].astype(int)
    R = P[:, PRIM_AXES : PRIM_AXES + 9].reshape(-1, 3, 3)  # R_local_world
    local = np.einsum("nij,nj->ni", R, points_world - P[:, PRIM_CENTER : PRIM_CENTER + 3])
    half = P[:, PRIM_HALF : PRIM_HALF + 3]
    rect = kind == RECTANGLE
    out[rect] = np.abs(local[rect, 2])
    box = kind == BOX
    q = np.abs(local[box]) - half[box]
    out[box] = np.abs(np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0))
    return out


def _model_floor(trajectory, t0, t1):
    """Largest rotation (deg) / translation (m) gap between the true motion and slerp + lerp."""
    T0, T1 = trajectory.pose(t0), trajectory.pose(t1)
    s = np.linspace(0.0, 1.0, 21)
    t, r = pose_error(interpolate_pose(T0, T1, s), trajectory.poses(t0 + s * (t1 - t0)))
    return float(r.max()), float(t.max())


def synthetic_case(name, scene, motion, duration, seed, lidar="spinning64"):
    from nbcalib.synthetic import RigConfig, generate_sequence

    config = RigConfig(lidar=lidar, scene=scene, motion=motion, duration=duration, seed=seed)
    seq, gen_wall, _ = _timed(lambda: generate_sequence(config))
    scans = [np.column_stack([s.points, s.intensities]) for s in seq.scans]
    times = [s.times for s in seq.scans]
    integrate_dynamic(scans[:3], times[:3])  # warm the JIT
    cloud, wall, cpu = _timed(lambda: integrate_dynamic(scans, times))

    # ground truth at each scan's first and last point time, in the frame of the first scan
    T_first_world = invert_T(seq.trajectory.pose(seq.scans[0].stamp + times[0].min()))
    t_begin = np.array([s.stamp + t.min() for s, t in zip(seq.scans, times)])
    t_end = np.array([s.stamp + t.max() for s, t in zip(seq.scans, times)])
    T_b_true = T_first_world @ seq.trajectory.poses(t_begin)
    T_e_true = T_first_world @ seq.trajectory.poses(t_end)
    tb, rb = pose_error(cloud.T_first_scanbegin, T_b_true)
    te, re = pose_error(cloud.T_first_scanend, T_e_true)
    rot = np.concatenate([rb[1:], re])  # the first begin pose is the identity by definition
    trans = np.concatenate([tb[1:], te])
    # relative motion within each scan and between consecutive scan starts
    rel_scan = pose_error(
        invert_T(cloud.T_first_scanbegin) @ cloud.T_first_scanend, invert_T(T_b_true) @ T_e_true
    )
    rel_step = pose_error(
        invert_T(cloud.T_first_scanend[:-1]) @ cloud.T_first_scanend[1:],
        invert_T(T_e_true[:-1]) @ T_e_true[1:],
    )
    path = float(np.linalg.norm(np.diff(T_e_true[:, :3, 3], axis=0), axis=1).sum())
    path += float(np.linalg.norm(T_e_true[0, :3, 3] - T_b_true[0, :3, 3]))
    floor = np.array([_model_floor(seq.trajectory, a, b) for a, b in zip(t_begin, t_end)])

    # sharpness on planar primitives: deskewed / rigid at the mid-scan pose / true deskewing
    deskewed, rigid, truth, prims = [], [], [], []
    for k, (scan, t) in enumerate(zip(seq.scans, times)):
        s, _ = normalized_scan_times(t)
        T_b, T_e = cloud.T_first_scanbegin[k], cloud.T_first_scanend[k]
        deskewed.append(deskew(scan.points, s, T_b, T_e))
        rigid.append(transform_points(interpolate_pose(T_b, T_e, 0.5), scan.points))
        truth.append(deskew(scan.points, s, T_b_true[k], T_e_true[k]))
        prims.append(scan.prim)
    prims = np.concatenate(prims)
    T_world_first = invert_T(T_first_world)
    sharp = {}
    for label, clouds in (("deskewed", deskewed), ("rigid", rigid), ("true_deskew", truth)):
        pts = np.vstack(clouds)
        d = _surface_distance(seq.scene.prims, prims, transform_points(T_world_first, pts))
        d = d[np.isfinite(d) & (d < 0.5)]  # points on planar primitives (0.5 m: not a mismatch)
        sharp[label] = {
            "plane_rms_m": float(np.sqrt(np.mean(d**2))),
            "local_thickness_m": local_thickness(pts),
        }

    def summary(x):
        return {
            "median": float(np.median(x)),
            "p90": float(np.percentile(x, 90)),
            "max": float(x.max()),
        }

    return {
        "name": name,
        "lidar": lidar,
        "seed": seed,
        "scans": len(scans),
        "points_per_scan": int(np.mean([len(s) for s in scans])),
        "generation_s": gen_wall,
        "scans_per_s_wall": len(scans) / wall,
        "scans_per_s_cpu": len(scans) / cpu,
        "rotation_error_deg": summary(rot),
        "translation_error_m": summary(trans),
        "intra_scan_error_rot_deg": summary(rel_scan[1]),
        "intra_scan_error_trans_m": summary(rel_scan[0]),
        "scan_to_scan_error_rot_deg": summary(rel_step[1]),
        "scan_to_scan_error_trans_m": summary(rel_step[0]),
        "path_m": path,
        "end_error_m": float(te[-1]),
        "drift_percent": 100.0 * float(te[-1]) / path,
        "model_floor_rot_deg": summary(floor[:, 0]),
        "sharpness": sharp,
    }


# ---------------------------------------------------------------------------------------------
# KITTI
# ---------------------------------------------------------------------------------------------


def _kitti_scans():
    return [
        np.fromfile(KITTI / f"{k:010d}" / "velodyne.bin", np.float32).reshape(-1, 4)
        for k in range(20)
    ]


def _best_of(repeat, fn):
    runs = [_timed(fn) for _ in range(repeat)]
    out = runs[0][0]
    return out, min(r[1] for r in runs), min(r[2] for r in runs)


def _rigid_vs_deskewed(scans, cloud, clockwise):
    deskewed, rigid = [], []
    for k, scan in enumerate(scans):
        p = scan[:, :3].astype(np.float64)
        p = p[np.einsum("ij,ij->i", p, p) >= 1.0]
        s, _ = normalized_scan_times(synthesize_times_from_azimuth(p, 10.0, clockwise=clockwise))
        T_b, T_e = cloud.T_first_scanbegin[k], cloud.T_first_scanend[k]
        deskewed.append(deskew(p, s, T_b, T_e))
        rigid.append(transform_points(interpolate_pose(T_b, T_e, 0.5), p))
    out = {}
    for label, pts in (("deskewed", np.vstack(deskewed)), ("rigid", np.vstack(rigid))):
        out[label] = {
            "all_m": local_thickness(pts),
            "facing_travel_m": local_thickness(pts, direction=[1.0, 0.0, 0.0]),
        }
    return out


def kitti_case(repeat):
    scans = _kitti_scans()
    n = len(scans)
    integrate_dynamic(scans[:3])  # warm the JIT
    integrate_dynamic(scans[:3], config=DynamicIntegrationConfig(parallel=True, threads=1))
    speed = {}
    for label, config in (
        ("default", DynamicIntegrationConfig()),
        ("one_thread", DynamicIntegrationConfig(background_accumulation=False, threads=1)),
        ("prange_kernels", DynamicIntegrationConfig(parallel=True, threads=1)),
    ):
        cloud, wall, cpu = _best_of(repeat, lambda c=config: integrate_dynamic(scans, config=c))
        speed[label] = {
            "scans_per_s_wall": n / wall,
            "scans_per_s_cpu": n / cpu,
            "ms_per_scan_wall": 1e3 * wall / n,
        }
        if label == "default":
            default_cloud = cloud
    T_e = default_cloud.T_first_scanend
    T_b = default_cloud.T_first_scanbegin
    directions = {}
    for clockwise in (True, False):
        cloud = integrate_dynamic(scans, config=DynamicIntegrationConfig(clockwise=clockwise))
        directions["clockwise" if clockwise else "counter_clockwise"] = {
            "mean_residual_rms_m": float(np.nanmean(cloud.stats["residual_rms"][1:])),
            "thickness": _rigid_vs_deskewed(scans, cloud, clockwise),
        }
    return {
        "scans": n,
        "points_per_scan": int(np.mean([len(s) for s in scans])),
        "points_out": len(default_cloud),
        "speed": speed,
        "path_m": float(np.linalg.norm(np.diff(T_e[:, :3, 3], axis=0), axis=1).sum()),
        "intra_scan_motion_m_median": float(
            np.median(np.linalg.norm(T_e[:, :3, 3] - T_b[:, :3, 3], axis=1))
        ),
        "time_direction": directions,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--parts", default="synthetic,kitti")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--duration", type=float, default=3.0)
    parser.add_argument("--seeds", default="0", help="comma-separated seeds of the sequences")
    parser.add_argument(
        "--lidars", default="spinning64", help="comma-separated LiDAR presets (nbcalib.synthetic)"
    )
    args = parser.parse_args()
    parts = args.parts.split(",")
    result = {"load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count()}
    if "synthetic" in parts:
        for lidar in args.lidars.split(","):
            for seed in (int(x) for x in args.seeds.split(",")):
                for name, scene, motion in (
                    ("nod_room", "room", "nod"),
                    ("drive_street", "street", "drive"),
                ):
                    r = synthetic_case(name, scene, motion, args.duration, seed, lidar)
                    key = name if (lidar, seed) == ("spinning64", 0) else f"{name}_{lidar}_{seed}"
                    result[key] = r
                    print(
                        f"{name} {lidar} seed {seed}: {r['scans']} scans x "
                        f"{r['points_per_scan']} pts, {r['scans_per_s_wall']:.1f} scans/s (CPU "
                        f"{r['scans_per_s_cpu']:.1f}); rotation error median "
                        f"{r['rotation_error_deg']['median']:.3f} deg (p90 "
                        f"{r['rotation_error_deg']['p90']:.3f}, max "
                        f"{r['rotation_error_deg']['max']:.3f}; model floor median "
                        f"{r['model_floor_rot_deg']['median']:.3f}), translation median "
                        f"{1e3 * r['translation_error_m']['median']:.1f} mm (max "
                        f"{1e3 * r['translation_error_m']['max']:.1f}), end error "
                        f"{1e3 * r['end_error_m']:.2f} mm, drift {r['drift_percent']:.2f} % of "
                        f"{r['path_m']:.2f} m; plane RMS deskewed "
                        f"{1e3 * r['sharpness']['deskewed']['plane_rms_m']:.1f} mm / rigid "
                        f"{1e3 * r['sharpness']['rigid']['plane_rms_m']:.1f} mm / true "
                        f"{1e3 * r['sharpness']['true_deskew']['plane_rms_m']:.1f} mm; thickness "
                        f"{1e3 * r['sharpness']['deskewed']['local_thickness_m']:.1f} / "
                        f"{1e3 * r['sharpness']['rigid']['local_thickness_m']:.1f} mm",
                        flush=True,
                    )
    if "kitti" in parts:
        if not KITTI.is_dir():
            print(f"KITTI frames not found at {KITTI}; skipped")
        else:
            r = kitti_case(args.repeat)
            result["kitti"] = r
            d = r["speed"]["default"]
            print(
                f"kitti: {r['scans']} scans x {r['points_per_scan']} pts: "
                f"{d['scans_per_s_wall']:.1f} scans/s (CPU {d['scans_per_s_cpu']:.1f}), "
                f"path {r['path_m']:.2f} m",
                flush=True,
            )
    result["load_average_1min_end"] = os.getloadavg()[0]
    print(
        json.dumps(result, default=lambda x: None if isinstance(x, float) and math.isnan(x) else x)
    )


if __name__ == "__main__":
    main()
