"""Speed of the NID cost: 1 M LiDAR points against a 2 MP image, serial and parallel kernels,
and the same hard-binned cost in NumPy in the same process for the ratio.

Each cost runs twice: with the points in random order (the headline figures) and sorted by their
pixel (``*_pixel_order``, the order :func:`nbcalib.preprocess.lidar_image.visible_indices` gives),
since the kernels' speed depends on how the image is read. Wall clock and process CPU time (all
threads) are printed side by side with the load average.

Run:  python benchmarks/bench_nid.py [--points 1000000] [--width 1920 --height 1080] [--repeat 5]
(best of at least --repeat runs, and of as many as fit in half a second)
The last line printed is one JSON object with points_per_s (hard-binned value, best kernel),
grad_points_per_s (smooth value + gradient, best kernel) and numpy_ratio, the same with suffix
_pixel_order, the load average and every row (points/s from wall time; ``*_cpu_s`` seconds).
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


def best_time(fn, repeat, min_seconds=0.5):
    """Best wall-clock and best CPU (process, all threads) seconds of at least ``repeat`` runs.

    Fast calls are repeated until ``min_seconds`` have passed (a 2 ms kernel gets ~250 runs), so
    that one slow wake-up of the second core does not decide its figure.
    """
    fn()  # warm up (compilation, caches)
    wall, cpu = [], []
    start = time.perf_counter()
    while len(wall) < repeat or time.perf_counter() - start < min_seconds:
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


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
    # the same points sorted by their pixel (what nbcalib.preprocess.lidar_image.visible_indices
    # returns): the image is then read in memory order
    pixel_order = np.lexsort((np.floor(uv[:, 0] + 0.5), np.floor(uv[:, 1] + 0.5)))

    rows = {}  # name -> (wall s, cpu s)
    load_before = os.getloadavg()[0]
    for order_name, order in (("", np.arange(n)), ("_pixel_order", pixel_order)):
        pts, inten = points[order], intensities[order]
        for parallel in (False, True):
            tag = ("parallel" if parallel else "serial") + order_name
            hard = NIDCost(cam, image, pts, inten, form="hard", parallel=parallel)
            smooth = NIDCost(cam, image, pts, inten, form="smooth", parallel=parallel)
            rows[f"hard_value_{tag}"] = best_time(lambda c=hard: c.value(T), args.repeat)
            rows[f"smooth_value_{tag}"] = best_time(lambda c=smooth: c.value(T), args.repeat)
            rows[f"smooth_value_grad_{tag}"] = best_time(
                lambda c=smooth: c.value_and_grad(T), args.repeat
            )

        # the NumPy baseline in its faster layout: the points as an (N, 3) C array, or as the
        # (3, N) rows the kernels read (the transposed view); best of the two
        def numpy_cost(c=hard, pts=None):
            return ref.nid_hard_numpy(
                cam.model,
                cam.intrinsics,
                cam.distortion_coeffs,
                T,
                pts,
                c.point_bins,
                c.image_bins,
                c.bins,
            )

        layouts = {"rows": np.ascontiguousarray(hard.points), "columns": hard.points}
        for pts in layouts.values():
            assert abs(numpy_cost(pts=pts) - hard.value(T)) < 1e-12
        timings = {
            name: best_time(lambda p=pts: numpy_cost(pts=p), max(1, args.repeat // 2))
            for name, pts in layouts.items()
        }
        rows[f"hard_value_numpy{order_name}"] = min(timings.values())
    load_after = os.getloadavg()[0]

    rate = {k: n / wall for k, (wall, _) in rows.items()}
    best_hard = max(rate["hard_value_serial"], rate["hard_value_parallel"])
    best_grad = max(rate["smooth_value_grad_serial"], rate["smooth_value_grad_parallel"])
    best_hard_sorted = max(
        rate["hard_value_serial_pixel_order"], rate["hard_value_parallel_pixel_order"]
    )
    best_grad_sorted = max(
        rate["smooth_value_grad_serial_pixel_order"],
        rate["smooth_value_grad_parallel_pixel_order"],
    )
    print(f"load average {load_before:.2f} before, {load_after:.2f} after")
    print(f"{'variant':<44} {'M points/s':>10} {'wall ms':>8} {'cpu ms':>8} {'M/cpu-s':>8}")
    for k, (wall, cpu) in rows.items():
        print(
            f"{k:<44} {n / wall / 1e6:10.1f} {wall * 1e3:8.1f} {cpu * 1e3:8.1f} "
            f"{n / cpu / 1e6:8.1f}"
        )
    result = {
        "points": n,
        "image": f"{args.width}x{args.height}",
        "camera": cam.model,
        "threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "machine": platform.machine(),
        "load_average": [round(load_before, 2), round(load_after, 2)],
        "points_per_s": round(best_hard),
        "grad_points_per_s": round(best_grad),
        "numpy_ratio": round(best_hard / rate["hard_value_numpy"], 1),
        "points_per_s_pixel_order": round(best_hard_sorted),
        "grad_points_per_s_pixel_order": round(best_grad_sorted),
        "numpy_ratio_pixel_order": round(
            best_hard_sorted / rate["hard_value_numpy_pixel_order"], 1
        ),
        **{k: round(v) for k, v in rate.items()},
        **{f"{k}_cpu_s": round(cpu, 4) for k, (_, cpu) in rows.items()},
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
