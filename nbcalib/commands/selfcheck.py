"""``nbcalib selfcheck``: check every camera model on this machine (compiles the kernels)."""

from __future__ import annotations

import argparse
import time

DESCRIPTION = """\
Check every camera model on this machine: for a realistic camera of each model, unproject a grid
of pixels and project the bearings back (round trip, px), compare the projection with the slow
reference formulas (px), and the analytic Jacobian with finite differences (relative). The first
run compiles the numba kernels (cached for later runs).
"""

EPILOG = """\
examples:
  nbcalib selfcheck
  nbcalib selfcheck --width 1920 --height 1080 --step 4
"""


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``selfcheck``."""
    p = subparsers.add_parser(
        "selfcheck",
        help="check every camera model (projection, unprojection, Jacobians)",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("--width", type=int, default=1280, help="image width of the test cameras")
    p.add_argument("--height", type=int, default=960, help="image height of the test cameras")
    p.add_argument("--step", type=int, default=8, help="pixel grid step for the round trip")
    return p


def run(args) -> int:
    """Run the checks; returns 0 when every model passes, 1 otherwise."""
    import numpy as np

    from nbcalib.camera import CAMERA_MODELS, example_camera
    from nbcalib.errors import InputError
    from nbcalib.reference import camera as ref

    if args.width < 16 or args.height < 16 or args.step < 1:
        raise InputError("--width and --height must be >= 16 and --step >= 1")
    t0 = time.perf_counter()
    print(
        f"{'model':<20} {'fov deg':>8} {'roundtrip px':>13} {'vs reference px':>16} "
        f"{'jacobian rel':>13}  result"
    )
    failures = 0
    for name in CAMERA_MODELS:
        cam = example_camera(name, args.width, args.height)
        uv = cam.pixel_grid(args.step)
        bearings = cam.unproject(uv)
        ok = np.isfinite(bearings[:, 0])
        uv2, valid = cam.project(bearings[ok])
        roundtrip = float(np.max(np.abs(uv2 - uv[ok]))) if ok.any() else np.inf
        rng = np.random.default_rng(0)
        sample = bearings[ok][rng.choice(ok.sum(), size=min(500, ok.sum()), replace=False)]
        points = sample * rng.uniform(0.5, 30.0, (len(sample), 1))
        uv_k, _ = cam.project(points)
        args_ref = (cam.model, cam.intrinsics, cam.distortion_coeffs, cam.width, cam.height)
        vs_ref = float(np.max(np.abs(uv_k - ref.project(*args_ref, points))))
        _, J, _ = cam.project_jacobian(points)
        Jn = ref.project_jacobian_numeric(*args_ref, points)
        scale = np.maximum(1.0, np.abs(Jn).max(axis=(1, 2), keepdims=True))
        jac = float(np.max(np.abs(J - Jn) / scale))
        passed = ok.all() and valid.all() and roundtrip < 1e-6 and vs_ref < 1e-6 and jac < 1e-5
        failures += not passed
        print(
            f"{name:<20} {cam.fov_deg:8.1f} {roundtrip:13.1e} {vs_ref:16.1e} {jac:13.1e}  "
            f"{'ok' if passed else 'FAILED'}"
        )
    print(
        f"{len(CAMERA_MODELS) - failures}/{len(CAMERA_MODELS)} camera models ok "
        f"({time.perf_counter() - t0:.1f} s, including numba compilation on a first run)"
    )
    return 1 if failures else 0
