"""Benchmark: nbcalib's continuous-time ICP side by side with kiss-icp on the 20 real KITTI frames.

kiss-icp (PRBonn, PyPI ``kiss-icp``) is a benchmark-only tool here, not a dependency of nbcalib:
``pip install kiss-icp``. Both run on the same scans (``../shared/data/real/kitti_raw_2011_09_26``,
float32 x, y, z, intensity; 0.1 s apart; no per-point times: both get the times nbcalib
synthesises from the azimuth, clockwise from behind) with a 1 m minimum range; kiss-icp with its
defaults otherwise (max range 100 m, voxel 1 m, deskewing on).

kiss-icp 1.x deskews each scan into the LiDAR frame at the *end* of the scan, so its pose ``k`` is
compared with nbcalib's ``T_first_scanend[k]``, both expressed relative to the end of scan 0.
Reported: for each pair of consecutive scans, the rotation (degrees) and translation (metres)
between the two estimates of the relative pose ``T_k^-1 T_k+1``; the same end to end (scan 0 to
scan 19); path lengths; and the speed of each (best of ``--repeat`` runs, wall and CPU time of the
process, the 1-minute load average of the machine alongside).

The last line printed is one JSON object with every figure.

Run: ``pip install kiss-icp && python benchmarks/bench_kiss_icp.py [--repeat 3]``
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from nbcalib.odometry import (
    integrate_dynamic,
    normalized_scan_times,
    synthesize_times_from_azimuth,
)
from nbcalib.transforms import invert_T, pose_error

KITTI = Path(__file__).resolve().parents[1].parent / "shared/data/real/kitti_raw_2011_09_26"
MIN_RANGE = 1.0


def _timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def _best_of(repeat, fn):
    runs = [_timed(fn) for _ in range(repeat)]
    return runs[-1][0], min(r[1] for r in runs), min(r[2] for r in runs)


def run_kiss_icp(scans_xyz, stamps):
    try:
        from kiss_icp.config import KISSConfig
        from kiss_icp.kiss_icp import KissICP
    except ImportError as exc:  # pragma: no cover - benchmark-only dependency
        raise SystemExit("this benchmark needs kiss-icp: pip install kiss-icp") from exc
    config = KISSConfig()
    config.data.deskew = True
    config.data.max_range = 100.0
    config.data.min_range = MIN_RANGE
    config.mapping.voxel_size = config.data.max_range / 100.0  # kiss-icp's own default rule
    odometry = KissICP(config)
    poses = []
    for points, t in zip(scans_xyz, stamps):
        odometry.register_frame(points, t)
        poses.append(odometry.last_pose.copy())
    return np.array(poses)


def relative_agreement(T_a, T_b):
    """Errors between consecutive relative poses of two trajectories (K, 4, 4)."""
    rel_a = invert_T(T_a[:-1]) @ T_a[1:]
    rel_b = invert_T(T_b[:-1]) @ T_b[1:]
    trans, rot = pose_error(rel_a, rel_b)
    end_trans, end_rot = pose_error(invert_T(T_a[0]) @ T_a[-1], invert_T(T_b[0]) @ T_b[-1])
    return {
        "consecutive_rotation_deg": {
            "median": float(np.median(rot)),
            "max": float(rot.max()),
        },
        "consecutive_translation_m": {
            "median": float(np.median(trans)),
            "max": float(trans.max()),
        },
        "end_to_end_rotation_deg": float(end_rot),
        "end_to_end_translation_m": float(end_trans),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    if not KITTI.is_dir():
        raise SystemExit(f"KITTI frames not found at {KITTI}")
    scans = [
        np.fromfile(KITTI / f"{k:010d}" / "velodyne.bin", np.float32).reshape(-1, 4)
        for k in range(20)
    ]
    n = len(scans)
    xyz = [s[:, :3].astype(np.float64) for s in scans]
    stamps = [normalized_scan_times(synthesize_times_from_azimuth(p, 10.0))[0] for p in xyz]

    integrate_dynamic(scans[:3], min_distance=MIN_RANGE)  # warm the JIT
    cloud, ours_wall, ours_cpu = _best_of(
        args.repeat, lambda: integrate_dynamic(scans, min_distance=MIN_RANGE)
    )
    run_kiss_icp(xyz[:3], stamps[:3])  # warm up
    kiss, kiss_wall, kiss_cpu = _best_of(args.repeat, lambda: run_kiss_icp(xyz, stamps))

    ours = invert_T(cloud.T_first_scanend[0]) @ cloud.T_first_scanend
    kiss = invert_T(kiss[0]) @ kiss

    def path(T):
        return float(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1).sum())

    result = {
        "load_average_1min": os.getloadavg()[0],
        "cpus": os.cpu_count(),
        "scans": n,
        "agreement": relative_agreement(ours, kiss),
        "path_m": {"nbcalib": path(ours), "kiss_icp": path(kiss)},
        "end_position_m": {
            "nbcalib": ours[-1, :3, 3].tolist(),
            "kiss_icp": kiss[-1, :3, 3].tolist(),
        },
        "speed": {
            "nbcalib_scans_per_s_wall": n / ours_wall,
            "nbcalib_scans_per_s_cpu": n / ours_cpu,
            "kiss_icp_scans_per_s_wall": n / kiss_wall,
            "kiss_icp_scans_per_s_cpu": n / kiss_cpu,
            "ratio_wall_nbcalib_over_kiss": kiss_wall / ours_wall,
        },
        "load_average_1min_end": os.getloadavg()[0],
    }
    a = result["agreement"]
    print(
        f"relative poses nbcalib vs kiss-icp: median {a['consecutive_rotation_deg']['median']:.3f}"
        f" deg / {100 * a['consecutive_translation_m']['median']:.1f} cm (max "
        f"{a['consecutive_rotation_deg']['max']:.3f} deg / "
        f"{100 * a['consecutive_translation_m']['max']:.1f} cm); end to end "
        f"{a['end_to_end_rotation_deg']:.3f} deg / {100 * a['end_to_end_translation_m']:.1f} cm; "
        f"path {result['path_m']['nbcalib']:.2f} m vs {result['path_m']['kiss_icp']:.2f} m; "
        f"speed {n / ours_wall:.1f} vs {n / kiss_wall:.1f} scans/s",
        flush=True,
    )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
