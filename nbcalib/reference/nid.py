"""Slow, readable NID: joint histograms built point by point, entropies, and a NumPy version.

:func:`joint_histogram_hard` and :func:`joint_histogram_smooth` say in plain Python what the
kernels in :mod:`nbcalib.kernels.nid` compute; :func:`nid_hard_numpy` is the same hard-binned cost
vectorised with NumPy only (projection included), the baseline of ``benchmarks/bench_nid.py``.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.reference import camera as ref_camera


def entropy(p: np.ndarray) -> float:
    """Shannon entropy (natural log) of a normalised histogram; empty cells contribute 0."""
    p = p[p > 0]
    return float(-(p * np.log(p)).sum())


def nid_from_histogram(hist: np.ndarray) -> float:
    """NID = (H(L, I) - MI(L; I)) / H(L, I) of a joint histogram (rows: LiDAR, columns: image)."""
    total = hist.sum()
    if total <= 0:
        return 1.0
    p = hist / total
    h_joint = entropy(p.ravel())
    if h_joint <= 0:
        return 1.0
    mi = entropy(p.sum(axis=1)) + entropy(p.sum(axis=0)) - h_joint
    return (h_joint - mi) / h_joint


def _camera_points(T, points):
    return points @ T[:3, :3].T + T[:3, 3]


def joint_histogram_hard(camera, T, points, point_bins, image_bins, bins):
    """Integer joint histogram: each point on its nearest pixel (``floor(u + 0.5)``)."""
    hist = np.zeros((bins, bins), dtype=np.int64)
    height, width = image_bins.shape
    uv, valid = camera.project(_camera_points(T, points))
    for (u, v), ok, a in zip(uv, valid, point_bins):
        if not ok:
            continue
        iu, iv = math.floor(u + 0.5), math.floor(v + 0.5)
        if 0 <= iu < width and 0 <= iv < height:
            hist[a, image_bins[iv, iu]] += 1
    return hist


def bspline_weights(s: float) -> np.ndarray:
    """Uniform cubic B-spline weights of knots -1, 0, +1, +2 around a position with fraction s."""
    return (
        np.array([(1 - s) ** 3, 3 * s**3 - 6 * s**2 + 4, -3 * s**3 + 3 * s**2 + 3 * s + 1, s**3])
        / 6
    )


def joint_histogram_smooth(camera, T, points, point_bins, image_bins, bins):
    """Weighted joint histogram: each in-image point spreads over 4 x 4 pixels (B-spline)."""
    hist = np.zeros((bins, bins))
    height, width = image_bins.shape
    uv, valid = camera.project(_camera_points(T, points))
    inside = camera.in_image(uv) & valid
    for (u, v), ok, a in zip(uv, inside, point_bins):
        if not ok:
            continue
        ku, kv = math.floor(u), math.floor(v)
        wu, wv = bspline_weights(u - ku), bspline_weights(v - kv)
        for jv in range(4):
            py = min(max(kv - 1 + jv, 0), height - 1)
            for ju in range(4):
                px = min(max(ku - 1 + ju, 0), width - 1)
                hist[a, image_bins[py, px]] += wu[ju] * wv[jv]
    return hist


def bspline_derivatives(s: float) -> np.ndarray:
    """Derivatives with respect to ``s`` of :func:`bspline_weights` (they sum to 0)."""
    return np.array([-3 * (1 - s) ** 2, 9 * s**2 - 12 * s, -9 * s**2 + 6 * s + 3, 3 * s**2]) / 6


def joint_histogram_smooth_derivative(
    camera, T, points, point_bins, image_bins, bins, n_intr=0, center_step=1.0
):
    """Derivative (bins, bins, 6 + n_intr) of :func:`joint_histogram_smooth`.

    Each in-image point moves its pixel by ``d(u, v)/d delta = J_proj [I, -[p_c]x]`` (left
    perturbation ``T <- exp(delta) T``, ``delta = [v, omega]``), and each of its 16 weights
    ``wu[i] wv[j]`` changes by ``du[i] wv[j] du/d delta + wu[i] dv[j] dv/d delta``.

    ``n_intr`` (0, 1 or 3) more columns with respect to the intrinsics, from the camera's own
    :meth:`~nbcalib.camera.CameraModel.intrinsics_jacobian` ``K = d(u, v)/d(fx, fy, cx, cy)``:
    ``lambda`` scaling both focal lengths by ``exp(lambda)`` moves the pixel by ``fx K[:, 0] +
    fy K[:, 1]``; ``cx`` and ``cy``, in pixels of a resolution ``1 / center_step`` times
    ``camera``'s, by ``center_step K[:, 2]`` and ``center_step K[:, 3]``.
    """
    dhist = np.zeros((bins, bins, 6 + n_intr))
    height, width = image_bins.shape
    p_camera = _camera_points(T, points)
    uv, jac, valid = camera.project_jacobian(p_camera)
    inside = camera.in_image(uv) & valid
    if n_intr:
        _, kjac, _ = camera.intrinsics_jacobian(p_camera)
        fx, fy = camera.intrinsics[:2]
        columns = [fx * kjac[:, :, 0] + fy * kjac[:, :, 1]]
        if n_intr == 3:
            columns += [center_step * kjac[:, :, 2], center_step * kjac[:, :, 3]]
        dintr = np.stack(columns, axis=2)  # (N, 2, n_intr)
    else:
        dintr = np.zeros((len(p_camera), 2, 0))
    for (u, v), J, p, ok, a, K in zip(uv, jac, p_camera, inside, point_bins, dintr):
        if not ok:
            continue
        hat = np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
        duv = np.hstack([J @ np.hstack([np.eye(3), -hat]), K])  # (2, 6 + n_intr)
        ku, kv = math.floor(u), math.floor(v)
        wu, wv = bspline_weights(u - ku), bspline_weights(v - kv)
        du, dv = bspline_derivatives(u - ku), bspline_derivatives(v - kv)
        for jv in range(4):
            py = min(max(kv - 1 + jv, 0), height - 1)
            for ju in range(4):
                px = min(max(ku - 1 + ju, 0), width - 1)
                dw = du[ju] * wv[jv] * duv[0] + wu[ju] * dv[jv] * duv[1]
                dhist[a, image_bins[py, px]] += dw
    return dhist


def nid_hard_numpy(model, intrinsics, distortion, T, points, point_bins, image_bins, bins):
    """The hard-binned NID with NumPy only: transform, project, round, ``np.bincount``.

    Pinhole-family models only (validity ``z > 0``); the baseline the kernels are measured against.
    """
    height, width = image_bins.shape
    pc = _camera_points(T, points)
    front = pc[:, 2] > 0
    uv = ref_camera.project(model, intrinsics, distortion, width, height, pc[front])
    iu = np.floor(uv[:, 0] + 0.5)
    iv = np.floor(uv[:, 1] + 0.5)
    inside = (iu >= 0) & (iu < width) & (iv >= 0) & (iv < height)
    pixel = iv[inside].astype(np.int64) * width + iu[inside].astype(np.int64)
    cell = point_bins[front][inside].astype(np.int64) * bins + image_bins.ravel()[pixel]
    hist = np.bincount(cell, minlength=bins * bins).reshape(bins, bins)
    return nid_from_histogram(hist)
