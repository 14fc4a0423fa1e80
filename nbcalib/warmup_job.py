"""The warm-up's tiny job: a small in-memory calibration through the pipeline's stages.

:func:`nbcalib.warmup.start` runs it in a low-priority background process on a first run, so
that numba compiles (and caches) the later stages' kernels beside the job's first stages.
``python -m nbcalib.warmup_job`` runs it in the foreground. It sits above the pipeline (it
runs it), :mod:`nbcalib.warmup` below it (the stages ask it whether the warm-up runs).
"""

from __future__ import annotations

import numpy as np

__all__ = ["tiny_job"]


def _scene(rng: np.random.Generator, camera):
    """A textured corner (back wall, floor, side wall) seen by a pinhole ``camera``.

    Points are in the camera frame; their intensity is the texture at their position, the
    image the texture at each pixel's first hit.
    """

    def texture(p):
        return 0.5 + 0.25 * np.sin(3.1 * p[..., 0] + 1.3 * p[..., 2]) * np.cos(2.7 * p[..., 1])

    planes = [  # (normal axis, offset): z = 6 back wall, y = 1.5 floor, x = -3 side wall
        (2, 6.0),
        (1, 1.5),
        (0, -3.0),
    ]
    h, w = camera.height, camera.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    # a pinhole's rays by its intrinsics: the job compiles the unprojection kernels itself
    # at once (synth, reading), so the warm-up does not race it for them
    fx, fy, cx, cy = camera.intrinsics[:4]
    rays = np.column_stack([(u.ravel() - cx) / fx, (v.ravel() - cy) / fy, np.ones(u.size)])
    depth = np.full(len(rays), np.inf)
    for axis, offset in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = offset / rays[:, axis]
        depth = np.where((s > 0.5) & (s < depth), s, depth)
    hit = rays * np.where(np.isfinite(depth), depth, 0.0)[:, None]
    image = np.where(np.isfinite(depth), texture(hit), 0.0).reshape(h, w)
    points = []
    for axis, offset in planes:
        p = rng.uniform((-3.0, -2.0, 1.0), (3.0, 1.5, 6.0), (15000, 3))
        p[:, axis] = offset
        points.append(p)
    points = np.concatenate(points)
    return (255 * image).astype(np.uint8), points, texture(points)


def tiny_job() -> None:
    """Calibrate a small synthetic scene in memory, through the stages a job runs.

    In the order a job needs its kernels: preprocessing and rendering, the initial guess's
    RANSAC, matching's views, then fine registration and the report.
    """
    from nbcalib.api import ArrayInputs
    from nbcalib.camera import example_camera
    from nbcalib.config import CalibrationConfig, set_values
    from nbcalib.initial_guess.estimate import estimate_initial_guess
    from nbcalib.matching.multiview import match_views
    from nbcalib.pipeline import Calibrator
    from nbcalib.products import Start
    from nbcalib.transforms import se3_exp

    rng = np.random.default_rng(0)
    camera = example_camera("pinhole", 320, 240)
    image, points_camera, intensities = _scene(rng, camera)
    # a LiDAR with REP 103 axes (x forward) at the camera
    T_camera_lidar = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    points = points_camera @ T_camera_lidar[:3, :3]
    inputs = ArrayInputs([points], [intensities], [image], camera)
    calibrator = Calibrator(set_values(CalibrationConfig(), {"refine.max_outer": 2}))
    calibrator.run(inputs, until="preprocess")
    uv, valid = camera.project(points_camera[:400])
    estimate_initial_guess(camera, uv[valid], points[:400][valid], seed=0)
    match_views(camera, image, points, intensities, matcher="sift", views=2)
    near = se3_exp(np.array([0.02, -0.01, 0.01, 0.004, -0.003, 0.002])) @ T_camera_lidar
    calibrator.run(inputs, init=Start.from_matrix(near, "warm-up"))


if __name__ == "__main__":  # pragma: no cover - run by start() in its own process
    tiny_job()
