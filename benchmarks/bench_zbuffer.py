"""Benchmark: z-buffer rendering of LiDAR images (nbcalib.preprocess.lidar_image).

Renders 1 M and 4 M points into the 1024 x 1024 pinhole virtual camera (70-degree cone of points,
as a Livox) and the 1920 x 960 equirectangular one (a spinning LiDAR's band, -25..+3 degrees),
after warming the JIT. Variants:

- ``render``: ``render_lidar_image`` as shipped (index map, depth and intensity images).
- ``serial``: the index map alone: projection kernel, then the serial scatter (what ``render``
  does before filling the depth and intensity images).
- ``parallel``: the same with a ``prange`` twin of the projection kernel, compiled here from the
  same Python function (each point writes only its own slots; checked equal to ``serial``).
- ``fused``: projection and scatter in one serial loop (defined here; nbcalib does not use it).

Reports the best of ``--repeat`` runs (wall clock), points per second and the best CPU time of
the process (all threads: for the parallel variant, CPU time close to the serial one means it
would halve the wall time on two idle cores); the last line printed is one JSON object with every
figure and the 1-minute load average (other work on the machine inflates wall times).

Run: ``python benchmarks/bench_zbuffer.py [--repeat 7] [--sizes 1000000,4000000]``
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

from nbcalib.kernels import zbuffer as kz
from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.zbuffer import _pixel_of_point
from nbcalib.preprocess.intensity import equalize_point_intensities
from nbcalib.preprocess.lidar_image import make_virtual_camera, render_lidar_image


@jit
def _render_fused(model_id, params, T, points, width, height, best_range2, index):
    """Projection and scatter in one loop: same result as the two kernels nbcalib uses."""
    for i in range(points.shape[0]):
        p, r2 = _pixel_of_point(
            model_id, params, T, points[i, 0], points[i, 1], points[i, 2], width, height
        )
        if p >= 0 and r2 <= best_range2[p]:
            best_range2[p] = r2
            index[p] = i


_project_to_pixels_parallel = jit_parallel(kz._project_to_pixels_impl)


def _index_map(camera, T, points, *, parallel):
    """Index map from the projection kernel (or its parallel twin) and the serial scatter."""
    n = points.shape[0]
    pixel = np.empty(n, dtype=np.int64)
    range2 = np.empty(n)
    project = _project_to_pixels_parallel if parallel else kz._project_to_pixels
    project(camera.model_id, camera.params, T, points, camera.width, camera.height, pixel, range2)
    best = np.full(camera.width * camera.height, np.inf)
    index = np.full(camera.width * camera.height, -1, dtype=np.int32)
    kz._scatter_nearest(pixel, range2, best, index)
    return index


def _points(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    if kind == "pinhole":  # a 70-degree cone around LiDAR +x
        cos_t = rng.uniform(math.cos(math.radians(35.0)), 1.0, n)
        phi = rng.uniform(0.0, 2.0 * math.pi, n)
        sin_t = np.sqrt(1.0 - cos_t**2)
        d = np.column_stack([cos_t, sin_t * np.cos(phi), sin_t * np.sin(phi)])
    else:  # a spinning LiDAR's band
        az = rng.uniform(-math.pi, math.pi, n)
        el = rng.uniform(math.radians(-25.0), math.radians(3.0), n)
        d = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return d * rng.uniform(2.0, 60.0, (n, 1))


def _best(fn, repeat: int) -> tuple[float, float]:
    """Best wall-clock and best CPU (all threads of the process) seconds over ``repeat`` runs."""
    wall, cpu = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=7)
    parser.add_argument("--sizes", default="1000000,4000000")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    rng = np.random.default_rng(0)
    cameras = {
        "pinhole": make_virtual_camera(math.radians(70.0)),
        "equirectangular": make_virtual_camera(math.pi),
    }
    results = []
    for kind, (camera, T) in cameras.items():
        # warm the JIT (all variants) on a small cloud
        small = _points(kind, 1000, rng)
        render_lidar_image(camera, T, small, np.zeros(1000))
        _index_map(camera, T, small, parallel=True)
        for n in sizes:
            points = _points(kind, n, rng)
            values = equalize_point_intensities(rng.random(n))

            def fused(points=points, camera=camera, T=T):
                best = np.full(camera.width * camera.height, np.inf)
                index = np.full(camera.width * camera.height, -1, dtype=np.int32)
                _render_fused(
                    camera.model_id, camera.params, T, points, camera.width, camera.height,
                    best, index,
                )  # fmt: skip
                return index

            reference = render_lidar_image(camera, T, points, values).index.ravel()
            assert np.array_equal(fused(), reference)
            assert np.array_equal(_index_map(camera, T, points, parallel=True), reference)
            variants = {
                "render": lambda p=points, v=values, c=camera, T=T: render_lidar_image(c, T, p, v),
                "serial": lambda p=points, c=camera, T=T: _index_map(c, T, p, parallel=False),
                "parallel": lambda p=points, c=camera, T=T: _index_map(c, T, p, parallel=True),
                "fused": fused,
            }
            for name, fn in variants.items():
                seconds, cpu_seconds = _best(fn, args.repeat)
                row = {
                    "camera": kind,
                    "size": f"{camera.width}x{camera.height}",
                    "points": n,
                    "variant": name,
                    "ms": round(seconds * 1e3, 1),
                    "cpu_ms": round(cpu_seconds * 1e3, 1),
                    "Mpoints_per_s": round(n / seconds / 1e6, 2),
                }
                results.append(row)
                print(
                    f"{kind:16s} {row['size']:>9s} {n:>8d} points  {name:8s} "
                    f"{row['ms']:8.1f} ms  {row['Mpoints_per_s']:6.2f} M points/s  "
                    f"(CPU {row['cpu_ms']:7.1f} ms)"
                )
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    print(json.dumps({"benchmark": "zbuffer", "cores": os.cpu_count(), "load1": load,
                      "results": results}))  # fmt: skip


if __name__ == "__main__":
    main()
