"""Slow, readable camera models: the formulas written out once more, independently of the kernels.

The tests compare :mod:`nbcalib.kernels.projection` and :mod:`nbcalib.kernels.unprojection` with
these functions; the notebooks teach from them. Everything is plain NumPy over arrays of points;
unprojection is a generic numerical inverse (:func:`unproject`) that knows nothing about the
models' closed forms.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares


def _brown(x, y, k1, k2, p1, p2, k3=0.0, k4=0.0, k5=0.0, k6=0.0):
    r2 = x * x + y * y
    radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / (1 + k4 * r2 + k5 * r2**2 + k6 * r2**3)
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return xd, yd


def project(model: str, intrinsics, distortion, width: int, height: int, points) -> np.ndarray:
    """Pixel positions of camera-frame ``points`` (N, 3); no validity logic, NaN where undefined.

    The pixel convention is nbcalib's (centres at integers); for every model with ``fx, fy, cx,
    cy`` this is exactly OpenCV's ``u = fx * x_d + cx``.
    """
    P = np.asarray(points, dtype=np.float64)
    X, Y, Z = P[:, 0], P[:, 1], P[:, 2]
    d = list(distortion)
    with np.errstate(all="ignore"):
        if model == "equirectangular":
            n = np.linalg.norm(P, axis=1)
            lat = -np.arcsin(Y / n)  # the reference toolbox's latitude (up positive)
            lon = np.arctan2(X, Z)
            u = (
                width * (0.5 + lon / (2 * np.pi)) - 0.5
            )  # reference: no -0.5 (truncation convention)
            v = height * (0.5 - lat / np.pi) - 0.5
            return np.stack([u, v], axis=1)
        fx, fy, cx, cy = intrinsics[:4]
        if model in ("pinhole", "plumb_bob", "rational_polynomial"):
            x, y = X / Z, Y / Z
            xd, yd = _brown(x, y, *(d + [0.0] * 8)[:8]) if d else (x, y)
        elif model == "fisheye":
            k1, k2, k3, k4 = d
            rho = np.hypot(X, Y)
            theta = np.arctan2(rho, Z)
            theta_d = theta * (1 + k1 * theta**2 + k2 * theta**4 + k3 * theta**6 + k4 * theta**8)
            xd, yd = theta_d * X / rho, theta_d * Y / rho
        elif model == "atan":
            (w,) = d
            x, y = X / Z, Y / Z
            r = np.hypot(x, y)
            factor = np.arctan(2 * r * np.tan(w / 2)) / (w * r) if w > 0 else np.ones_like(r)
            xd, yd = x * factor, y * factor
        elif model == "omnidir":
            xi = intrinsics[4]
            s = P / np.linalg.norm(P, axis=1, keepdims=True)
            x, y = s[:, 0] / (s[:, 2] + xi), s[:, 1] / (s[:, 2] + xi)
            xd, yd = _brown(x, y, *d)
        else:
            raise ValueError(f"unknown model {model!r}")
        return np.stack([fx * xd + cx, fy * yd + cy], axis=1)


def unproject(model: str, intrinsics, distortion, width: int, height: int, uv) -> np.ndarray:
    """Bearings of pixels by numerically inverting :func:`project` (slow: one solve per pixel).

    Each pixel's direction is parametrised by two angles (as the reference toolbox's
    ``estimate_direction``) and found by least squares on the pixel error, started from the
    direction of the pixel under an undistorted model.
    """
    uv = np.asarray(uv, dtype=np.float64)
    out = np.full((uv.shape[0], 3), np.nan)

    def direction(ab):
        a, b = ab
        return np.array([np.sin(b), -np.sin(a) * np.cos(b), np.cos(a) * np.cos(b)])

    for i, target in enumerate(uv):
        if model == "equirectangular":
            lon0 = ((target[0] + 0.5) / width - 0.5) * 2 * np.pi
            lat0 = ((target[1] + 0.5) / height - 0.5) * np.pi
            start = np.array(
                [np.cos(lat0) * np.sin(lon0), np.sin(lat0), np.cos(lat0) * np.cos(lon0)]
            )
        else:
            fx, fy, cx, cy = intrinsics[:4]
            start = np.array([(target[0] - cx) / fx, (target[1] - cy) / fy, 1.0])
        start /= np.linalg.norm(start)
        # rotate the parametrisation so that the start direction is (a, b) = (0, 0)
        zaxis = start
        helper = np.array([1.0, 0.0, 0.0]) if abs(zaxis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        xaxis = np.cross(helper, zaxis)
        xaxis /= np.linalg.norm(xaxis)
        yaxis = np.cross(zaxis, xaxis)
        R = np.stack([xaxis, yaxis, zaxis], axis=1)

        def residual(ab, target=target, R=R):
            p = (R @ direction(ab))[None]
            r = project(model, intrinsics, distortion, width, height, p)[0] - target
            return np.nan_to_num(r, nan=1e6)

        sol = least_squares(residual, np.zeros(2), xtol=1e-15, ftol=1e-15, gtol=1e-15)
        if np.max(np.abs(sol.fun)) < 1e-6:
            out[i] = R @ direction(sol.x)
    return out


def project_jacobian_numeric(model, intrinsics, distortion, width, height, points, h=1e-6):
    """Central-difference Jacobian ``d uv / d p`` of :func:`project`, shape (N, 2, 3)."""
    P = np.asarray(points, dtype=np.float64)
    J = np.empty((P.shape[0], 2, 3))
    for k in range(3):
        step = h * np.maximum(1.0, np.abs(P[:, k]))
        dp = np.zeros_like(P)
        dp[:, k] = step
        plus = project(model, intrinsics, distortion, width, height, P + dp)
        minus = project(model, intrinsics, distortion, width, height, P - dp)
        J[:, :, k] = (plus - minus) / (2 * step[:, None])
    return J
