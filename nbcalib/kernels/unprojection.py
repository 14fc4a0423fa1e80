"""Camera unprojection kernels: pixel positions to unit bearing vectors in the camera frame.

The inverse of :func:`nbcalib.kernels.projection.project_point` for every model, on the same
``params`` layout (:mod:`nbcalib.kernels.projection`): :func:`unproject_pixel` for one pixel
inside other kernels, ``_unproject`` for arrays behind
:meth:`nbcalib.camera.CameraModel.unproject`. Distortion is inverted by Newton's method; a pixel
whose inverse does not reproduce it (outside the model's monotonic domain) is invalid, with NaN
bearing. The slow, readable references are in :mod:`nbcalib.reference.camera`.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit
from nbcalib.kernels.projection import (
    ATAN,
    EQUIRECTANGULAR,
    FISHEYE,
    P_CX,
    P_CY,
    P_DIST,
    P_FX,
    P_FY,
    P_HEIGHT,
    P_LIMIT,
    P_WIDTH,
    P_XI,
    RATIONAL_POLYNOMIAL,
    _distort_poly,
    _distort_poly_jacobian,
)

_NEWTON_ITERS = 30


@jit
def _bounded_newton_step(x, f, df, x_hi):
    """One safeguarded Newton step for ``f(x) = 0`` on ``[0, x_hi]``: ``(x_new, stop)``.

    A step that would leave the interval goes half-way to its end instead; ``stop`` when the
    slope is not positive (``x`` is kept) or the step was negligible.
    """
    if df <= 0.0:
        return x, True
    step = f / df
    x_new = x - step
    if x_new < 0.0:
        x_new = 0.5 * x
    if x_new > x_hi:
        x_new = 0.5 * (x + x_hi)
    return x_new, abs(step) <= 1e-15 * (1.0 + x_new)


@jit
def _undistort_poly(params, xd, yd):
    """Invert :func:`~nbcalib.kernels.projection._distort_poly` by Newton's method: (x, y, ok).

    Starts from the radial-only inverse along the ray (1-D Newton, which is safe inside the
    monotonic domain), then polishes with 2-D Newton including the tangential terms.
    """
    k1 = params[P_DIST + 0]
    k2 = params[P_DIST + 1]
    k3 = params[P_DIST + 4]
    k4 = params[P_DIST + 5]
    k5 = params[P_DIST + 6]
    k6 = params[P_DIST + 7]
    limit = params[P_LIMIT]
    rd = math.sqrt(xd * xd + yd * yd)
    x = xd
    y = yd
    if rd > 0.0:
        # 1-D: find r with r * radial(r^2) = rd, r in [0, sqrt(limit)]
        r_hi = math.sqrt(limit) if limit < math.inf else math.inf
        r = min(rd, r_hi)
        for _ in range(_NEWTON_ITERS):
            r2 = r * r
            num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
            dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
            dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
            rad = num / den
            drad = (dnum * den - num * dden) / (den * den)
            r, stop = _bounded_newton_step(r, r * rad - rd, rad + 2.0 * r2 * drad, r_hi)
            if stop:
                break
        x = xd * r / rd
        y = yd * r / rd
    # 2-D Newton with the full model (tangential terms)
    for _ in range(_NEWTON_ITERS):
        fx, fy, a00, a01, a10, a11, ok = _distort_poly_jacobian(params, x, y)
        if not ok:
            return math.nan, math.nan, False
        ex = fx - xd
        ey = fy - yd
        det = a00 * a11 - a01 * a10
        if det == 0.0 or not math.isfinite(det):
            return math.nan, math.nan, False
        dx = (a11 * ex - a01 * ey) / det
        dy = (-a10 * ex + a00 * ey) / det
        x -= dx
        y -= dy
        if abs(dx) + abs(dy) <= 1e-15 * (1.0 + abs(x) + abs(y)):
            break
    fx, fy, ok = _distort_poly(params, x, y)
    if not ok or abs(fx - xd) + abs(fy - yd) > 1e-9 * (1.0 + rd):
        return math.nan, math.nan, False
    return x, y, True


@jit
def _normalise(x, y, z):
    n = math.sqrt(x * x + y * y + z * z)
    return x / n, y / n, z / n


@jit
def unproject_pixel(model_id, params, u, v):
    """Unit bearing ``(dx, dy, dz, valid)`` of pixel position ``(u, v)``. For use inside kernels."""
    nan = math.nan
    if not (math.isfinite(u) and math.isfinite(v)):
        return nan, nan, nan, False
    if model_id == EQUIRECTANGULAR:
        W = params[P_WIDTH]
        H = params[P_HEIGHT]
        lon = ((u + 0.5) / W - 0.5) * 2.0 * math.pi
        lat_down = ((v + 0.5) / H - 0.5) * math.pi
        if not (abs(lat_down) < 0.5 * math.pi and abs(lon) <= math.pi):
            return nan, nan, nan, False
        c = math.cos(lat_down)
        return c * math.sin(lon), math.sin(lat_down), c * math.cos(lon), True
    xd = (u - params[P_CX]) / params[P_FX]
    yd = (v - params[P_CY]) / params[P_FY]
    if model_id <= RATIONAL_POLYNOMIAL:
        x, y, ok = _undistort_poly(params, xd, yd)
        if not ok:
            return nan, nan, nan, False
        bx, by, bz = _normalise(x, y, 1.0)
        return bx, by, bz, True
    if model_id == FISHEYE:
        k1 = params[P_DIST + 0]
        k2 = params[P_DIST + 1]
        k3 = params[P_DIST + 2]
        k4 = params[P_DIST + 3]
        theta_max = params[P_LIMIT]
        theta_d = math.sqrt(xd * xd + yd * yd)
        if theta_d == 0.0:
            return 0.0, 0.0, 1.0, True
        theta = min(theta_d, theta_max)
        for _ in range(_NEWTON_ITERS):
            t2 = theta * theta
            f = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            df = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
            theta, stop = _bounded_newton_step(theta, f, df, theta_max)
            if stop:
                break
        t2 = theta * theta
        resid = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
        if not (abs(resid) <= 1e-9 * (1.0 + theta_d) and theta <= theta_max):
            return nan, nan, nan, False
        st = math.sin(theta) / theta_d
        return xd * st, yd * st, math.cos(theta), True
    if model_id == ATAN:
        w = params[P_DIST]
        rd = math.sqrt(xd * xd + yd * yd)
        if rd == 0.0:
            return 0.0, 0.0, 1.0, True
        if w < 1e-7:
            scale = 1.0
        else:
            if not rd * w < 0.5 * math.pi:
                return nan, nan, nan, False
            a = 2.0 * math.tan(0.5 * w)
            scale = math.tan(rd * w) / (a * rd)
        bx, by, bz = _normalise(xd * scale, yd * scale, 1.0)
        return bx, by, bz, True
    # omnidir
    xi = params[P_XI]
    x, y, ok = _undistort_poly(params, xd, yd)
    if not ok:
        return nan, nan, nan, False
    r2 = x * x + y * y
    disc = 1.0 + (1.0 - xi * xi) * r2
    if disc < 0.0:
        return nan, nan, nan, False
    eta = (xi + math.sqrt(disc)) / (r2 + 1.0)
    sx = eta * x
    sy = eta * y
    sz = eta - xi
    zmin = -min(xi, 1.0 / xi) if xi > 0.0 else 0.0
    if not sz > zmin:
        return nan, nan, nan, False
    bx, by, bz = _normalise(sx, sy, sz)
    return bx, by, bz, True


@jit
def _unproject(model_id, params, uv):
    n = uv.shape[0]
    bearings = np.empty((n, 3))
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        bx, by, bz, ok = unproject_pixel(model_id, params, uv[i, 0], uv[i, 1])
        bearings[i, 0] = bx
        bearings[i, 1] = by
        bearings[i, 2] = bz
        valid[i] = ok
    return bearings, valid
