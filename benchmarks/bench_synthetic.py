"""Speed of the synthetic rig (issue 3 item 8): a 64-beam sequence of ~1 M points and a
1280 x 960 image, serial and parallel kernels, in the room and the street.

Measured after warming the JIT, best of ``--repeat`` runs, wall clock and CPU time of the process
(all threads; on a shared machine the serial CPU time is the better estimate of idle wall time):

- ``rays``: plain nearest-hit ray casting of the 64-beam pattern (rays per second);
- ``lidar``: ``--scans`` scans of the nodding 64-beam LiDAR (1024 columns, ~65 k beams each),
  with textures, noise and motion distortion (points per second);
- ``image``: a 1280 x 960 colour pinhole image with shadows, blur and noise;
- ``sequence``: :func:`generate_sequence` end to end (the image plus every scan).

Run:  python benchmarks/bench_synthetic.py [--scans 16] [--repeat 3]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numba
import numpy as np

from nbcalib.camera import example_camera
from nbcalib.synthetic import (
    RenderConfig,
    RigConfig,
    generate_sequence,
    lidar_preset,
    make_scene,
    make_trajectory,
    render_image,
    simulate_scan,
)
from nbcalib.synthetic.motion import MotionConfig
from nbcalib.synthetic.rig import R_OPTICAL_BODY
from nbcalib.transforms import make_T


def best_time(fn, repeat):
    """Best wall-clock and best CPU (process, all threads) seconds of ``repeat`` runs."""
    fn()  # warm up (compilation, caches)
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--scans", type=int, default=16, help="scans of the 64-beam LiDAR")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    lidar = lidar_preset("spinning64")
    duration = args.scans * lidar.scan_period
    trajectory = make_trajectory(MotionConfig(kind="nod", seed=1), duration)
    camera = example_camera("pinhole", 1280, 960)
    T_world_camera = make_T(R_OPTICAL_BODY.T, np.zeros(3))
    directions, _, _ = lidar.pattern(0.0)
    directions = np.ascontiguousarray(np.tile(directions, (args.scans, 1)))

    results = {}
    print(f"{'scene':<7} {'what':<9} {'mode':<9} {'wall s':>8} {'cpu s':>8} {'per wall s':>12}")
    for kind in ("room", "street"):
        scene = make_scene(kind=kind, seed=1)
        for parallel in (False, True):
            mode = "parallel" if parallel else "serial"

            def cast(scene=scene, parallel=parallel):
                scene.cast(np.zeros(3), directions, parallel=parallel)

            def scans(scene=scene, parallel=parallel):
                rng = np.random.default_rng(0)
                return [
                    simulate_scan(
                        scene, lidar, trajectory, k * lidar.scan_period, rng, parallel=parallel
                    )
                    for k in range(args.scans)
                ]

            def image(scene=scene, parallel=parallel):
                config = RenderConfig(color=True, parallel=parallel)
                render_image(scene, camera, T_world_camera, config)

            config = RigConfig(scene=kind, duration=duration, color=True, parallel=parallel)

            def sequence(config=config):
                generate_sequence(config)

            n_points = sum(len(s) for s in scans())
            figures = {
                "rays": (best_time(cast, args.repeat), len(directions)),
                "lidar": (best_time(scans, args.repeat), n_points),
                "image": (best_time(image, args.repeat), camera.width * camera.height),
                "sequence": (best_time(sequence, args.repeat), None),
            }
            for what, ((seconds, cpu), count) in figures.items():
                rate = f"{count / seconds:12.3g}" if count else f"{'':>12}"
                print(f"{kind:<7} {what:<9} {mode:<9} {seconds:8.3f} {cpu:8.3f} {rate}")
                results[f"{kind}_{what}_{mode}_s"] = round(seconds, 4)
                results[f"{kind}_{what}_{mode}_cpu_s"] = round(cpu, 4)
            results[f"{kind}_points"] = n_points

    results.update(
        scans=args.scans,
        image="1280x960 rgb pinhole",
        cpus=os.cpu_count(),
        numba_threads=numba.config.NUMBA_NUM_THREADS,
        machine=platform.processor() or platform.machine(),
        load_average=round(os.getloadavg()[0], 2),  # other jobs on the machine
    )
    print(json.dumps(results))


if __name__ == "__main__":
    main()
