"""Speed of a whole fine registration: one synthetic pair, ~1 M LiDAR points, a 2 MP image.

Makes the pair with :mod:`nbcalib.synthetic` (64-beam spinning LiDAR nodding in a room, a
1920 x 1080 plumb_bob camera; the dense cloud is every scan deskewed with the true trajectory,
intensities rank-equalised, the image histogram-equalised), starts
:func:`nbcalib.registration.refine.refine` from the ground truth perturbed by ``--init-deg``
degrees and ``--init-cm`` centimetres in random directions, and breaks its time down into

- ``hidden_point_removal``: :func:`nbcalib.preprocess.lidar_image.visible_mask`, itself split
  into the z-buffer kernels of :mod:`nbcalib.kernels.zbuffer` (``project``, ``scatter``,
  ``min_filter``, ``visible``) and the rest (input checks, buffers);
- ``cost_construction``: :class:`nbcalib.registration.nid.NIDCost` construction (subset copy,
  quantisation of intensities and image);
- ``evaluations``: cost evaluations with and without gradient;
- ``other``: everything else (optimiser, se(3) charts, Python overhead).

Wall clock and CPU time of the process (all threads) are printed side by side with the load
average: on a shared machine the CPU time is the better estimate of the idle figure.

Run:  python benchmarks/bench_registration_speed.py [--points 1000000] [--optimizer lbfgs]
The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections import defaultdict
from contextlib import contextmanager

import numba
import numpy as np

from nbcalib.kernels import zbuffer as zbuffer_kernels
from nbcalib.preprocess import lidar_image
from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
from nbcalib.registration import nid as nid_module
from nbcalib.registration import refine as refine_module
from nbcalib.registration.config import OPTIMIZERS
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import invert_T, pose_error, se3_exp

#: Accumulated (wall, cpu, calls) per timed part.
TIMES: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0, 0])


@contextmanager
def timed(name):
    """Add the wall and process CPU seconds of the block to ``TIMES[name]``."""
    w0, c0 = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        entry = TIMES[name]
        entry[0] += time.perf_counter() - w0
        entry[1] += time.process_time() - c0
        entry[2] += 1


def wrap(owner, attr, name):
    """Replace ``owner.attr`` with a timed version of itself; returns the function to undo it."""
    original = getattr(owner, attr)

    def timed_call(*args, **kwargs):
        with timed(name):
            return original(*args, **kwargs)

    setattr(owner, attr, timed_call)
    return lambda: setattr(owner, attr, original)


def instrument():
    """Time the parts of refine; returns a function that undoes the instrumentation."""
    undo = [
        wrap(lidar_image, "visible_mask", "hidden_point_removal"),
        wrap(lidar_image, "visible_indices", "hidden_point_removal"),
        wrap(zbuffer_kernels, "_project_to_pixels", "hpr.project"),
        wrap(zbuffer_kernels, "_scatter_nearest", "hpr.scatter"),
        wrap(zbuffer_kernels, "_min_filter", "hpr.min_filter"),
        wrap(zbuffer_kernels, "_visible", "hpr.visible"),
    ]
    cost_class = nid_module.NIDCost
    init, evaluate = cost_class.__init__, cost_class.evaluate

    def timed_init(self, *args, **kwargs):
        with timed("cost_construction"):
            init(self, *args, **kwargs)

    def timed_evaluate(self, T, *, grad=False):
        with timed("evaluations.grad" if grad else "evaluations.value"):
            return evaluate(self, T, grad=grad)

    cost_class.__init__, cost_class.evaluate = timed_init, timed_evaluate

    def restore():
        for u in undo:
            u()
        cost_class.__init__, cost_class.evaluate = init, evaluate

    return restore


def use_pixel_order():
    """Make refine take its visible points from ``visible_indices`` (sorted by pixel)."""
    original = refine_module.visible_subset

    def visible_subset(pair, T_camera_lidar, config):
        if not config.hidden_point_removal:
            return original(pair, T_camera_lidar, config)
        return lidar_image.visible_indices(
            pair.camera,
            T_camera_lidar,
            pair.points_lidar,
            margin=config.depth_margin,
            window=config.window,
        )

    refine_module.visible_subset = visible_subset


def make_pair(n_points, width, height, seed):
    """A synthetic pair with about ``n_points`` points (whole scans) and its ground truth."""
    config = RigConfig(
        lidar="spinning64",
        camera="plumb_bob",
        scene="room",
        seed=seed,
        image_size=(width, height),
        duration=0.1 * max(1, round(n_points / 65536)),
        parallel=True,
    )
    seq = generate_sequence(config)
    points, raw = seq.dense_cloud()
    keep = np.isfinite(points).all(axis=1)
    points, raw = points[keep][:n_points], raw[keep][:n_points]
    pair = RegistrationPair(
        seq.camera, equalize_image(seq.image), points, equalize_point_intensities(raw)
    )
    return pair, seq.T_camera_lidar


def perturb(T_camera_lidar, degrees, metres, rng):
    """``T_camera_lidar`` moved by ``degrees`` and the camera centre by ``metres``."""
    axis = rng.normal(size=3)
    direction = rng.normal(size=3)
    delta = np.concatenate([np.zeros(3), np.radians(degrees) * axis / np.linalg.norm(axis)])
    T = se3_exp(delta) @ T_camera_lidar
    T_lidar_camera = invert_T(T)
    T_lidar_camera[:3, 3] += metres * direction / np.linalg.norm(direction)
    return invert_T(T_lidar_camera)


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--points", type=int, default=1_000_000)
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--optimizer", default=RefineConfig().optimizer, choices=OPTIMIZERS)
    ap.add_argument("--init-deg", type=float, default=1.5)
    ap.add_argument("--init-cm", type=float, default=7.0)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument(
        "--pixel-order",
        action="store_true",
        help="visible points sorted by pixel (lidar_image.visible_indices) instead of cloud order",
    )
    ap.add_argument(
        "--serial",
        action="store_true",
        help="serial NID kernels (RefineConfig.parallel=False): CPU time = one idle core's time",
    )
    ap.add_argument("--cache", help="npz file to keep the pair in between runs (outside the repo)")
    args = ap.parse_args()
    if args.pixel_order:
        use_pixel_order()

    t0 = time.perf_counter()
    if args.cache and os.path.exists(args.cache):
        saved = np.load(args.cache)
        camera = RigConfig(camera="plumb_bob", image_size=(args.width, args.height)).camera_object()
        pair = RegistrationPair(camera, saved["image"], saved["points"], saved["intensities"])
        T_true = saved["T_camera_lidar"]
    else:
        pair, T_true = make_pair(args.points, args.width, args.height, args.seed)
        if args.cache:
            np.savez(
                args.cache,
                image=pair.image,
                points=pair.points_lidar,
                intensities=pair.intensities,
                T_camera_lidar=T_true,
            )
    make_s = time.perf_counter() - t0
    T_init = perturb(T_true, args.init_deg, args.init_cm / 100, np.random.default_rng(args.seed))
    options = {"parallel": False} if args.serial else {}
    config = RefineConfig(optimizer=args.optimizer, **options)

    # warm-up on a small subset: JIT compilation (or cache loading) is not part of the figure
    small = RegistrationPair(
        pair.camera, pair.image, pair.points_lidar[::50], pair.intensities[::50]
    )
    refine(
        [small], T_init, RefineConfig(optimizer=args.optimizer, max_outer=1, max_inner=2, **options)
    )

    restore = instrument()
    load_before = os.getloadavg()[0]
    w0, c0 = time.perf_counter(), time.process_time()
    result = refine([pair], T_init, config)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    load_after = os.getloadavg()[0]
    restore()

    dt0, dr0 = pose_error(invert_T(T_init), invert_T(T_true))
    dt, dr = pose_error(invert_T(result.T_camera_lidar), invert_T(T_true))
    parts = {k: TIMES[k] for k in sorted(TIMES)}
    top = ["hidden_point_removal", "cost_construction", "evaluations.value", "evaluations.grad"]
    other_wall = wall - sum(TIMES[k][0] for k in top)
    other_cpu = cpu - sum(TIMES[k][1] for k in top)

    print(f"pair: {len(pair.points_lidar)} points, {args.width} x {args.height} image")
    print(f"made in {make_s:.1f} s; load average {load_before:.2f} before, {load_after:.2f} after")
    print(f"init error {dt0 * 100:.1f} cm / {dr0:.2f} deg -> {dt * 100:.2f} cm / {dr:.3f} deg")
    print(
        f"{len(result.history)} outer iterations, {result.iterations} inner iterations, "
        f"{result.evaluations} optimiser evaluations, visible points "
        f"{[h.visible_points[0] for h in result.history]}"
    )
    for k, h in enumerate(result.history):
        print(
            f"  outer {k}: level {getattr(h, 'level', 0)}, {h.iterations} iterations, "
            f"{h.evaluations} evaluations, {h.seconds:.2f} s, "
            f"NID {h.nid_start:.4f} -> {h.nid:.4f}, {h.message}"
        )
    print(f"{'part':<24} {'calls':>6} {'wall s':>8} {'cpu s':>8}")
    for name, (w, c, calls) in parts.items():
        print(f"{name:<24} {calls:6d} {w:8.3f} {c:8.3f}")
    print(f"{'other':<24} {'':>6} {other_wall:8.3f} {other_cpu:8.3f}")
    print(f"{'total refine':<24} {'':>6} {wall:8.3f} {cpu:8.3f}")
    summary = {
        "points": len(pair.points_lidar),
        "image": f"{args.width}x{args.height}",
        "optimizer": args.optimizer,
        "pixel_order": args.pixel_order,
        "serial": args.serial,
        "per_outer": [
            [getattr(h, "level", 0), h.iterations, h.evaluations, round(h.seconds, 3)]
            for h in result.history
        ],
        "threads": numba.get_num_threads(),
        "cpu_count": os.cpu_count(),
        "load_average": [round(load_before, 2), round(load_after, 2)],
        "refine_wall_s": round(wall, 3),
        "refine_cpu_s": round(cpu, 3),
        "outer_iterations": len(result.history),
        "inner_iterations": result.iterations,
        "evaluations": result.evaluations,
        "visible_points": [h.visible_points[0] for h in result.history],
        "error_cm": round(dt * 100, 3),
        "error_deg": round(dr, 4),
        **{f"{k}_wall_s": round(v[0], 3) for k, v in parts.items()},
        **{f"{k}_cpu_s": round(v[1], 3) for k, v in parts.items()},
        **{f"{k}_calls": v[2] for k, v in parts.items()},
        "other_wall_s": round(other_wall, 3),
        "other_cpu_s": round(other_cpu, 3),
    }
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
