"""``ground_truth.json``: the true extrinsic of a synthetic rig (or a reference calibration).

``nbcalib synth`` writes it (:func:`write_ground_truth`); ``nbcalib evaluate``, the benchmarks
and the notebooks read it (:func:`read_ground_truth`, one camera;
:func:`read_ground_truth_cameras`, a camera ring). A ``calib.json`` whose result is the truth
reads as one too.
"""

from __future__ import annotations

import os

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io.calib_json import (
    FINAL_STAGE,
    T_camera_lidar_from_values,
    _kind,
    _matrix_pose,
    read_json,
    values_from_T_camera_lidar,
    write_json,
)

__all__ = [
    "read_ground_truth",
    "read_ground_truth_camera",
    "read_ground_truth_cameras",
    "write_ground_truth",
]


def read_ground_truth_cameras(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Each camera's true ``T_camera_lidar`` of a camera ring's ``ground_truth.json``.

    ``{"cameras": [{"name": ..., "T_lidar_camera": [x, y, z, qx, qy, qz, qw]}, ...]}`` as
    ``nbcalib synth --cameras`` writes; empty when the file has no camera list.
    """
    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(f"expected a JSON object at the top level, got {_kind(data)}", path)
    entries = data.get("cameras")
    if entries is None:
        return {}
    if not isinstance(entries, list):
        raise InputError(f"cameras: expected a list, got {_kind(entries)}", path)
    out = {}
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise InputError(f"cameras[{k}]: expected an object with a name", path)
        what = f"cameras[{k}].T_lidar_camera"
        if "T_lidar_camera" not in entry:
            raise InputError(f"{what} missing", path)
        out[entry["name"]] = T_camera_lidar_from_values(
            entry["T_lidar_camera"], what=what, path=path
        )
    return out


def read_ground_truth_camera(path: str | os.PathLike):
    """The camera that rendered the images of a lab ``ground_truth.json``, or None.

    ``nbcalib synth --given-*`` keeps it under ``intrinsics.rendered`` (a camera's
    ``to_dict``); other ground truths, and calib.json files, have none.
    """
    from nbcalib.camera import CameraModel

    data = read_json(path)
    entry = data.get("intrinsics") if isinstance(data, dict) else None
    if entry is None:
        return None
    rendered = entry.get("rendered") if isinstance(entry, dict) else None
    if not isinstance(rendered, dict):
        raise InputError("intrinsics.rendered: expected the rendering camera", path)
    try:
        return CameraModel.from_dict(rendered)
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"intrinsics.rendered: {exc}", path) from None


def read_ground_truth(path: str | os.PathLike) -> np.ndarray:
    """Read the true ``T_camera_lidar`` from a ``ground_truth.json`` or a ``calib.json``.

    Parameters
    ----------
    path : str or PathLike
        Either ``{"T_lidar_camera": [x, y, z, qx, qy, qz, qw], "T_camera_lidar": 4x4 nested
        list}`` as ``nbcalib synth`` writes (either key suffices; when both are present they
        must agree to 1e-6; ``T_cam_lidar`` is accepted for ``T_camera_lidar``), or a
        ``calib.json`` whose ``results.T_lidar_camera`` is the truth.

    Returns
    -------
    T_camera_lidar : ndarray of shape (4, 4), float64
        ``p_camera = T_camera_lidar @ p_lidar``.

    Notes
    -----
    A 4 x 4 rotation part that is orthonormal only to rounding (within 1e-3) is projected onto
    SO(3); anything further off is an :class:`InputError`.
    """
    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError(f"expected a JSON object at the top level, got {_kind(data)}", path)
    if "T_camera_lidar" not in data and "T_cam_lidar" in data:
        data["T_camera_lidar"] = data["T_cam_lidar"]  # the name used by some dataset tools
    if "results" in data and "T_lidar_camera" not in data and "T_camera_lidar" not in data:
        results = data["results"]
        if not isinstance(results, dict) or FINAL_STAGE not in results:
            raise InputError("calib.json without results.T_lidar_camera", path)
        return T_camera_lidar_from_values(
            results[FINAL_STAGE], what="results.T_lidar_camera", path=path
        )
    candidates = []
    if "T_lidar_camera" in data:
        candidates.append(
            T_camera_lidar_from_values(data["T_lidar_camera"], what="T_lidar_camera", path=path)
        )
    if "T_camera_lidar" in data:
        candidates.append(_matrix_pose(data["T_camera_lidar"], "T_camera_lidar", path))
    if not candidates:
        raise InputError(
            "no ground truth: expected 'T_lidar_camera' [x,y,z,qx,qy,qz,qw], 'T_camera_lidar' "
            "4x4, or a calib.json with results.T_lidar_camera",
            path,
        )
    if len(candidates) == 2 and not np.allclose(candidates[0], candidates[1], rtol=0, atol=1e-6):
        worst = float(np.max(np.abs(candidates[0] - candidates[1])))
        raise InputError(
            f"T_lidar_camera and T_camera_lidar disagree (largest difference {worst:.3g}; "
            "T_camera_lidar must be the inverse of T_lidar_camera)",
            path,
        )
    return candidates[-1]


def write_ground_truth(path: str | os.PathLike, T_camera_lidar: np.ndarray) -> None:
    """Write a ``ground_truth.json`` with both forms of the true pose (atomically).

    Parameters
    ----------
    path : str or PathLike
        Output file.
    T_camera_lidar : ndarray of shape (4, 4), float64
        The true ``p_camera = T_camera_lidar @ p_lidar``; written as ``T_camera_lidar`` (4 x 4
        nested list) and ``T_lidar_camera`` ``[x, y, z, qx, qy, qz, qw]``.
    """
    values = values_from_T_camera_lidar(T_camera_lidar)
    # the 4x4 written is the one the quaternion encodes, so the two keys agree to rounding
    T_camera_lidar = T_camera_lidar_from_values(values)
    write_json(path, {"T_camera_lidar": T_camera_lidar.tolist(), "T_lidar_camera": values})
