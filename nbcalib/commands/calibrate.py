"""``nbcalib calibrate``: fine registration of a work directory by NID minimisation."""

from __future__ import annotations

import argparse
import sys
import time

DESCRIPTION = """\
Refine the LiDAR-camera extrinsic of a work directory (paper section III-E): hidden-point
removal, then minimisation of the normalised information distance (NID) between LiDAR
intensities and image intensities, summed over every pair, repeated until the pose stops
moving. Starts from --init, else from the latest initial guess in calib.json (manual or
automatic). Writes results.T_lidar_camera to calib.json, and the run's figures under
nbcalib.calibration.
"""

EPILOG = """\
examples:
  nbcalib calibrate work/
  nbcalib calibrate work/ --init 0.1,-0.05,0.02,0.5,-0.5,0.5,0.5
  nbcalib calibrate work/ --init=-0.1,0.05,0.02,0.5,-0.5,0.5,0.5
  nbcalib calibrate work/ --optimizer nelder_mead          # the paper's optimiser alone
  nbcalib calibrate work/ --optimizer lbfgs                # L-BFGS alone, over the pyramid
  nbcalib calibrate work/ --pairs 1 --window 1              # first pair only, 3x3 visibility test
  nbcalib calibrate work/ --pyramid-levels 0                # full resolution only (reference)

--init takes T_lidar_camera as x,y,z,qx,qy,qz,qw (metres, quaternion xyzw), the calib.json layout;
write --init=-0.1,... when the first value is negative.
"""


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``calibrate``."""
    from nbcalib.registration.config import OPTIMIZERS, RefineConfig

    d = RefineConfig()
    p = subparsers.add_parser(
        "calibrate",
        help="fine registration (NID) -> T_lidar_camera",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("workdir", metavar="WORKDIR", help="work directory made by nbcalib preprocess")
    p.add_argument("--init", metavar="X,Y,Z,QX,QY,QZ,QW", help="start from this T_lidar_camera")
    p.add_argument(
        "--optimizer",
        choices=OPTIMIZERS,
        default=d.optimizer,
        help="hybrid: Nelder-Mead over the pyramid, then L-BFGS (default); or either alone",
    )
    p.add_argument("--bins", type=int, default=d.bins, help="NID histogram bins")
    p.add_argument("--max-outer", type=int, default=d.max_outer, help="outer iterations at most")
    p.add_argument("--depth-margin", type=float, default=d.depth_margin, help="visibility, metres")
    p.add_argument("--window", type=int, default=d.window, help="visibility window half-size, px")
    p.add_argument(
        "--no-hidden-point-removal", action="store_true", help="use every point in the image"
    )
    p.add_argument("--pairs", type=int, default=None, help="use only the first N pairs")
    p.add_argument(
        "--pyramid-levels",
        type=int,
        default=d.pyramid_levels,
        help="coarse image levels before the full resolution (0: full resolution only)",
    )
    return p


def _parse_init(text: str):
    from nbcalib.errors import InputError
    from nbcalib.io.calib_json import T_camera_lidar_from_values

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--init must be 7 numbers x,y,z,qx,qy,qz,qw, got {text!r}") from None
    if len(values) != 7:
        raise InputError(f"--init must be 7 numbers x,y,z,qx,qy,qz,qw, got {len(values)}")
    return T_camera_lidar_from_values(values, what="--init")


def run(args) -> int:
    """Load the pairs, refine, write the result."""
    import numpy as np

    from nbcalib.errors import InputError
    from nbcalib.io.calib_json import FINAL_STAGE
    from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
    from nbcalib.transforms import invert_T, pose_error, pose_to_xyz_quat
    from nbcalib.workdir import WorkDir

    work = WorkDir(args.workdir)
    if not work.calib_path.is_file():
        raise InputError("no calib.json here: run nbcalib preprocess first", path=args.workdir)
    calib = work.read_calib()
    if args.init:
        T_init, init_stage = _parse_init(args.init), "--init"
    else:
        init_stage = calib.latest_initial_stage()
        if init_stage is None:
            raise InputError(
                "no initial guess in calib.json: run nbcalib initial-guess first, or pass --init",
                path=work.calib_path,
            )
        T_init = calib.get_T_camera_lidar(init_stage)
    try:
        config = RefineConfig(
            optimizer=args.optimizer,
            bins=args.bins,
            hidden_point_removal=not args.no_hidden_point_removal,
            depth_margin=args.depth_margin,
            window=args.window,
            max_outer=args.max_outer,
            pyramid_levels=args.pyramid_levels,
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
    names = work.names()
    if args.pairs is not None:
        if args.pairs < 1:
            raise InputError("--pairs must be >= 1")
        names = names[: args.pairs]
    if not names:
        raise InputError("no LiDAR-camera pair in the work directory", path=args.workdir)
    camera = calib.camera_model()
    pairs = []
    for name in names:
        p = work.load_pair(name)
        pairs.append(RegistrationPair(camera, p.image, p.points_lidar, p.intensities, name))
    print(
        f"calibrating {len(pairs)} pair(s), {sum(len(p.points_lidar) for p in pairs)} points, "
        f"{config.optimizer}, start: {init_stage}",
        file=sys.stderr,
    )
    t0 = time.perf_counter()

    def progress(i, step):
        print(
            f"  outer {i + 1} (level {step.level}): NID {step.nid_start:.5f} -> {step.nid:.5f}  "
            f"{step.iterations} it, {step.evaluations} evals, "
            f"moved {100 * step.translation_change:.2f} cm {step.rotation_change_deg:.3f} deg, "
            f"{sum(step.visible_points)} visible points, {step.seconds:.1f} s",
            file=sys.stderr,
        )

    result = refine(pairs, T_init, config, progress=progress)
    seconds = time.perf_counter() - t0
    dt, dr = pose_error(invert_T(result.T_camera_lidar), invert_T(T_init))
    calib.set_T_camera_lidar(FINAL_STAGE, result.T_camera_lidar)
    calib.nbcalib["calibration"] = {
        "start": init_stage,
        # the start pose itself, so a report can compare (also when it came from --init)
        "start_T_lidar_camera": [float(v) for v in pose_to_xyz_quat(invert_T(T_init))],
        "optimizer": config.optimizer,
        "bins": config.bins,
        "pyramid_levels": config.pyramid_levels,
        "pairs": names,
        "nid": result.nid,
        "nid_start": result.history[0].nid_start,
        "outer_iterations": len(result.history),
        "iterations": result.iterations,
        "evaluations": result.evaluations,
        "converged": result.converged,
        "stopped": result.stopped,
        "seconds": round(seconds, 3),
        "change_from_start": {"translation_m": float(dt), "rotation_deg": float(dr)},
    }
    work.write_calib(calib)
    xyzq = pose_to_xyz_quat(invert_T(result.T_camera_lidar))
    print(
        f"T_lidar_camera = [{', '.join(f'{v:.6f}' for v in xyzq)}]  (x y z qx qy qz qw)\n"
        f"NID {result.history[0].nid_start:.5f} -> {result.nid:.5f}, moved "
        f"{100 * dt:.2f} cm {dr:.3f} deg from the start, {len(result.history)} outer iterations "
        f"({'converged' if result.converged else result.stopped or 'stopped at --max-outer'}), "
        f"{seconds:.1f} s; "
        f"written to {work.calib_path}"
    )
    return 0 if np.all(np.isfinite(result.T_camera_lidar)) else 1
