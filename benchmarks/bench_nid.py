"""Speed of the NID cost: 1 M LiDAR points against a 2 MP image, serial and parallel kernels,
and the same hard-binned cost in NumPy in the same process for the ratio.

Run:  python benchmarks/bench_nid.py [--points 1000000] [--width 1920 --height 1080] [--repeat 5]
The last line printed is one JSON object with points_per_s (hard-binned value, best kernel),
grad_points_per_s (smooth value + gradient, best kernel) and numpy_ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numba
import numpy as np
from scipy.ndimage import gaussian_filter

from nbcalib.camera import example_camera
from nbcalib.reference import nid as ref
from nbcalib.registration.nid import NIDCost
from nbcalib.transforms import se3_exp


def best_time(fn, repeat):
    fn()  # warm up (compilation, caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    cam = example_camera("plumb_bob", args.width, args.height)
    image = gaussian_filter(rng.random((args.height, args.width)), 2.0)
    image = (image - image.min()) / np.ptp(image)
    uv = np.column_stack(
        [rng.uniform(0, args.width - 1, args.points), rng.uniform(0, args.height - 1, args.points)]
    )
    points = cam.unproject(uv) * rng.uniform(2, 40, (args.points, 1))
    intensities = rng.random(args.points)
    T = se3_exp(np.array([0.01, -0.02, 0.01, 0.002, 0.003, -0.001]))
    n = args.points

    rows = {}
    for parallel in (False, True):
        tag = "parallel" if parallel else "serial"
        hard = NIDCost(cam, image, points, intensities, form="hard", parallel=parallel)
        smooth = NIDCost(cam, image, points, intensities, form="smooth", parallel=parallel)
        rows[f"hard_value_{tag}"] = n / best_time(lambda c=hard: c.value(T), args.repeat)
        rows[f"smooth_value_{tag}"] = n / best_time(lambda c=smooth: c.value(T), args.repeat)
        rows[f"smooth_value_grad_{tag}"] = n / best_time(
            lambda c=smooth: c.value_and_grad(T), args.repeat
        )
    numpy_t = best_time(
        lambda: ref.nid_hard_numpy(
            cam.model,
            cam.intrinsics,
            cam.distortion_coeffs,
            T,
            hard.points,
            hard.point_bins,
            hard.image_bins,
            hard.bins,
        ),
        max(1, args.repeat // 2),
    )
    assert (
        abs(
            ref.nid_hard_numpy(
                cam.model,
                cam.intrinsics,
                cam.distortion_coeffs,
                T,
                hard.points,
                hard.point_bins,
                hard.image_bins,
                hard.bins,
            )
            - hard.value(T)
        )
        < 1e-12
    )
    rows["hard_value_numpy"] = n / numpy_t
    best_hard = max(rows["hard_value_serial"], rows["hard_value_parallel"])
    best_grad = max(rows["smooth_value_grad_serial"], rows["smooth_value_grad_parallel"])
    print(f"{'variant':<28} {'M points/s':>10}")
    for k, v in rows.items():
        print(f"{k:<28} {v / 1e6:10.1f}")
    result = {
        "points": n,
        "image": f"{args.width}x{args.height}",
        "camera": cam.model,
        "threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "points_per_s": round(best_hard),
        "grad_points_per_s": round(best_grad),
        "numpy_ratio": round(best_hard / rows["hard_value_numpy"], 1),
        **{k: round(v) for k, v in rows.items()},
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
