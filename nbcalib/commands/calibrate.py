"""``nbcalib calibrate``: fine registration of a work directory by NID minimisation."""

from __future__ import annotations

import argparse
import time

DESCRIPTION = """\
Refine the LiDAR-camera extrinsic of a work directory (paper section III-E): hidden-point
removal, then minimisation of the normalised information distance (NID) between LiDAR
intensities and image intensities, summed over every pair, repeated until the pose stops
moving. Starts from --init, else from the latest initial guess in calib.json (manual or
automatic). Writes results.T_lidar_camera to calib.json, and the run's figures under
nbcalib.calibration. The cost is the regional NID (--cost regional: one joint histogram per
image region, whose minimum stays at the truth where the paper's single histogram walks away)
or the paper's (--cost nid).
"""

EPILOG = """\
examples:
  nbcalib calibrate work/
  nbcalib calibrate work/ --init 0.1,-0.05,0.02,0.5,-0.5,0.5,0.5
  nbcalib calibrate work/ --init -0.1,0.05,0.02,0.5,-0.5,0.5,0.5
  nbcalib calibrate work/ --optimizer nelder_mead          # the paper's optimiser alone
  nbcalib calibrate work/ --optimizer lbfgs                # L-BFGS alone, over the pyramid
  nbcalib calibrate work/ --pairs 1 --window 1              # first pair only, 3x3 visibility test
  nbcalib calibrate work/ --pyramid-levels 0                # full resolution only (reference)
  nbcalib calibrate work/ --trust-translation 0.1 --trust-rotation 2   # stay within 10 cm / 2 deg
  nbcalib calibrate work/ --init 0.1,-0.05,0.02,0.5,-0.5,0.5,0.5 --init-uncertainty 0.05 1
  nbcalib calibrate work/ --force --bins 8                  # replace a finished result
  nbcalib calibrate work/ --force --points-per-pixel none   # every visible point, no subset

--init takes T_lidar_camera as x,y,z,qx,qy,qz,qw (metres, quaternion xyzw), the calib.json layout;
settings not given take their defaults. The run never leaves the trust region around its start
(--trust-translation metres of camera centre, --trust-rotation degrees). A run that ends on its
edge has no result: its optimum lies beyond. It writes none (calib.json keeps the attempt under
nbcalib.calibration.failed) and exits with status 3; start closer or widen the region.
"""


def add_parser(subparsers, formatter_class) -> argparse.ArgumentParser:
    """Register ``calibrate``."""
    from nbcalib.commands._args import add_force_argument
    from nbcalib.commands._options import INIT_UNCERTAINTY_HELP, REFINE, add_options

    p = subparsers.add_parser(
        "calibrate",
        help="fine registration (NID) -> T_lidar_camera",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    p.add_argument("workdir", metavar="WORKDIR", help="work directory made by nbcalib preprocess")
    p.add_argument("--init", metavar="X,Y,Z,QX,QY,QZ,QW", help="start from this T_lidar_camera")
    p.add_argument("--init-uncertainty", nargs=2, metavar=("M", "DEG"), help=INIT_UNCERTAINTY_HELP)
    add_options(p.add_argument_group("fine registration"), REFINE)
    add_force_argument(p)
    return p


def run(args) -> int:
    """Refine from the start pose, write the result, print it."""
    import numpy as np

    from nbcalib.commands._args import parse_start, stage_calibrator
    from nbcalib.transforms import invert_T, pose_error

    init = parse_start(args.init, args.init_uncertainty)
    calibrator = stage_calibrator(args, ("refine",))
    t0 = time.perf_counter()
    calibrator.run(init=init, only="calibrate", overwrite=args.force)
    result = calibrator.refinement
    start = calibrator.start
    dt, dr = pose_error(invert_T(result.T_camera_lidar), invert_T(start.T_camera_lidar))
    values = calibrator.work.read_calib().results["T_lidar_camera"]
    # NID values of other pyramid levels and visibility sets are not comparable with the last
    last = result.history[-1]
    stopped = "converged" if result.converged else result.stopped or "stopped at --max-outer"
    print(
        f"T_lidar_camera = [{', '.join(f'{v:.6f}' for v in values)}]  (x y z qx qy qz qw)\n"
        f"NID {last.nid_start:.5f} -> {last.nid:.5f} (last outer iteration), moved "
        f"{100 * dt:.2f} cm {dr:.3f} deg from the start, {len(result.history)} outer iterations "
        f"({stopped}), {time.perf_counter() - t0:.1f} s; written to "
        f"{calibrator.work.calib_path}"
    )
    return 0 if np.all(np.isfinite(result.T_camera_lidar)) else 1
