"""Speed of ``sha256_file`` (``nbcalib data verify``) and the URDF ``rpy`` round trip.

BENCHMARKS section 8: ``max |matrix_from_rpy(rpy_from_matrix(R)) - R|`` on random rotations and
near gimbal lock (the usual case for a camera in a LiDAR frame), via calib.json's quaternion.

Run:  python benchmarks/bench_exports.py      (writes and removes a 200 MB blob.bin here)
"""

from __future__ import annotations

import math
import os
import time

import numpy as np

from nbcalib.data import sha256_file
from nbcalib.io.extrinsic_formats import matrix_from_rpy, rpy_from_matrix
from nbcalib.transforms import matrix_to_quat_xyzw, quat_xyzw_to_matrix, random_pose

#: How far from gimbal lock (radians of pitch) the near-lock rotations are.
GAPS = (0, 1e-14, 1e-12, 1e-11, 1e-10, 3e-10, 1e-9, 3e-9, 1e-8, 3e-8, 1e-7, 1e-6, 1e-4)


def round_trip_error(R: np.ndarray) -> float:
    """``max |matrix_from_rpy(rpy_from_matrix(R)) - R|``."""
    return float(np.abs(matrix_from_rpy(rpy_from_matrix(R)) - R).max())


def main() -> None:
    rng = np.random.default_rng(2)
    with open("blob.bin", "wb") as f:
        f.write(rng.bytes(200_000_000))
    try:
        c = time.process_time()
        sha256_file("blob.bin")
        print("sha256 cpu", time.process_time() - c)
    finally:
        os.remove("blob.bin")
    print("random", max(round_trip_error(T[:3, :3]) for T in random_pose(rng, size=10000)))
    near = [
        round_trip_error(
            quat_xyzw_to_matrix(matrix_to_quat_xyzw(matrix_from_rpy([a, s * (math.pi / 2 - g), b])))
        )
        for g in GAPS
        for s in (1, -1)
        for a, b in rng.uniform(-math.pi, math.pi, (300, 2))
    ]
    print("near lock", max(near))


if __name__ == "__main__":
    main()
