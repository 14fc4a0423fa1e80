"""Batched projection kernels: arrays of LiDAR or camera points to pixels.

``_project`` and ``_project_jacobian`` loop :func:`nbcalib.kernels.projection.project_point` and
:func:`~nbcalib.kernels.projection.project_point_jacobian` over an (N, 3) array behind
:class:`nbcalib.camera.CameraModel`; :func:`nearest_pixels` moves and projects many LiDAR points
at once into pixel indices, in loops that LLVM vectorises (the NID cost's hot loop). Every pixel
equals the scalar kernels' (tested). ``params`` is laid out as in :mod:`nbcalib.kernels.projection`.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit, jit_inline
from nbcalib.kernels.projection import (
    OMNIDIR,
    P_CX,
    P_CY,
    P_DIST,
    P_FX,
    P_FY,
    P_LIMIT,
    P_XI,
    RATIONAL_POLYNOMIAL,
    _distort_poly_terms,
    project_point,
    project_point_jacobian,
)


@jit
def _project(model_id, params, points):
    n = points.shape[0]
    uv = np.empty((n, 2))
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        u, v, ok = project_point(model_id, params, points[i, 0], points[i, 1], points[i, 2])
        uv[i, 0] = u
        uv[i, 1] = v
        valid[i] = ok
    return uv, valid


@jit
def _project_jacobian(model_id, params, points):
    n = points.shape[0]
    uv = np.empty((n, 2))
    jac = np.empty((n, 2, 3))
    valid = np.empty(n, dtype=np.bool_)
    for i in range(n):
        r = project_point_jacobian(model_id, params, points[i, 0], points[i, 1], points[i, 2])
        uv[i, 0] = r[0]
        uv[i, 1] = r[1]
        jac[i, 0, 0] = r[2]
        jac[i, 0, 1] = r[3]
        jac[i, 0, 2] = r[4]
        jac[i, 1, 0] = r[5]
        jac[i, 1, 1] = r[6]
        jac[i, 1, 2] = r[7]
        valid[i] = r[8]
    return uv, jac, valid


# --------------------------------------------------------------------------------------------
# Nearest pixels of many points at once, written so that LLVM vectorises the loop
# --------------------------------------------------------------------------------------------
#
# project_point() returns early on every invalid case, so a loop over it runs one point at a
# time. The loops below compute every point's pixel without branches and fold the validity tests
# into one boolean, for the models whose arithmetic has no library calls (the pinhole family
# and omnidir); LLVM then runs 8 points per AVX-512 instruction. They evaluate exactly the
# expressions of the scalar helpers in nbcalib.kernels.projection, in the same order, with IEEE
# semantics (no fast-math), so every pixel and every validity decision is identical to
# project_point() followed by floor(u + 0.5) (tested). The other models go through
# project_point().
#
# Rounding: with a = u + 0.5, floor(a) lies in [0, W) exactly when 0 <= a < W (W an integer),
# and for a >= 0 truncation (int()) equals floor; so no floor() call is needed. Coordinates
# must be separate 1-D arrays: a strided (N, 3) layout defeats the vectoriser.


@jit_inline
def _pixel_index(fu, fv, ok, width, invalid):
    """``int(fv) * width + int(fu)`` where ``ok``, else ``invalid`` (invalid values unconverted)."""
    fu = fu if ok else 0.0
    fv = fv if ok else 0.0
    p = np.int32(fv) * np.int32(width) + np.int32(fu)
    return p if ok else np.int32(invalid)


@jit_inline
def _nearest_pixels_poly_loop(params, omni, rational, T, x, y, z, width, height, invalid, out):
    """Pinhole family or omnidir (``omni``); ``rational`` False when k4 = k5 = k6 = 0.

    Both flags are constants at each call site below, so numba's inlining leaves LLVM one
    straight loop per case. Without the rational denominator (``den = 1``) a non-finite ``r2``
    that ``den > 0`` would have rejected is rejected by the pixel range test instead.
    """
    fx = params[P_FX]
    fy = params[P_FY]
    cx = params[P_CX]
    cy = params[P_CY]
    xi = params[P_XI]
    limit = params[P_LIMIT]
    zmin = -min(xi, 1.0 / xi) if xi > 0.0 else 0.0
    r00, r01, r02, t0 = T[0, 0], T[0, 1], T[0, 2], T[0, 3]
    r10, r11, r12, t1 = T[1, 0], T[1, 1], T[1, 2], T[1, 3]
    r20, r21, r22, t2 = T[2, 0], T[2, 1], T[2, 2], T[2, 3]
    w = float(width)
    h = float(height)
    for i in range(x.shape[0]):
        px = x[i]
        py = y[i]
        pz = z[i]
        X = r00 * px + r01 * py + r02 * pz + t0
        Y = r10 * px + r11 * py + r12 * pz + t1
        Z = r20 * px + r21 * py + r22 * pz + t2
        finite = (X - X == 0.0) & (Y - Y == 0.0) & (Z - Z == 0.0)
        if omni:  # _omnidir_denominator, then X / d as in _omnidir_value
            n = math.sqrt(X * X + Y * Y + Z * Z)
            d = Z + xi * n
            front = (n > 0.0) & (Z > zmin * n) & (d > 0.0)
            xn = X / d
            yn = Y / d
        else:  # _pinhole_family_value
            iz = 1.0 / Z
            front = Z > 0.0
            xn = X * iz
            yn = Y * iz
        r2, den, xd, yd = _distort_poly_terms(params, xn, yn, rational)  # as _distort_poly
        fu = (fx * xd + cx) + 0.5
        fv = (fy * yd + cy) + 0.5
        ok = finite & front & (r2 <= limit) & (den > 0.0)
        ok = ok & (fu >= 0.0) & (fu < w) & (fv >= 0.0) & (fv < h)
        out[i] = _pixel_index(fu, fv, ok, width, invalid)


@jit
def _nearest_pixels_pinhole(params, T, x, y, z, width, height, invalid, out):
    _nearest_pixels_poly_loop(params, False, False, T, x, y, z, width, height, invalid, out)


@jit
def _nearest_pixels_rational(params, T, x, y, z, width, height, invalid, out):
    _nearest_pixels_poly_loop(params, False, True, T, x, y, z, width, height, invalid, out)


@jit
def _nearest_pixels_omnidir(params, T, x, y, z, width, height, invalid, out):
    _nearest_pixels_poly_loop(params, True, False, T, x, y, z, width, height, invalid, out)


@jit
def _nearest_pixels_any(model_id, params, T, x, y, z, width, height, invalid, out):
    """Any model, one point at a time through :func:`project_point`."""
    w = float(width)
    h = float(height)
    for i in range(x.shape[0]):
        X = T[0, 0] * x[i] + T[0, 1] * y[i] + T[0, 2] * z[i] + T[0, 3]
        Y = T[1, 0] * x[i] + T[1, 1] * y[i] + T[1, 2] * z[i] + T[1, 3]
        Z = T[2, 0] * x[i] + T[2, 1] * y[i] + T[2, 2] * z[i] + T[2, 3]
        u, v, ok = project_point(model_id, params, X, Y, Z)
        fu = u + 0.5
        fv = v + 0.5
        ok = ok & (fu >= 0.0) & (fu < w) & (fv >= 0.0) & (fv < h)
        out[i] = _pixel_index(fu, fv, ok, width, invalid)


@jit
def nearest_pixels(model_id, params, T, x, y, z, width, height, invalid, out):
    """Row-major index ``iv * width + iu`` of each LiDAR point's nearest pixel, or ``invalid``.

    ``x, y, z`` (1-D float arrays, LiDAR frame) are moved by ``T`` (4 x 4, camera <- LiDAR) and
    projected; ``(iu, iv) = floor((u, v) + 0.5)``; ``invalid`` (e.g. -1, or ``width * height``
    to index a sentinel after the image) where the projection is invalid or the pixel is
    outside ``width x height``. ``out`` (int32, same length) is overwritten.
    """
    rational = params[P_DIST + 5] != 0.0 or params[P_DIST + 6] != 0.0 or params[P_DIST + 7] != 0.0
    if model_id <= RATIONAL_POLYNOMIAL and not rational:
        _nearest_pixels_pinhole(params, T, x, y, z, width, height, invalid, out)
    elif model_id <= RATIONAL_POLYNOMIAL:
        _nearest_pixels_rational(params, T, x, y, z, width, height, invalid, out)
    elif model_id == OMNIDIR:  # its four coefficients are k1 k2 p1 p2: never rational
        _nearest_pixels_omnidir(params, T, x, y, z, width, height, invalid, out)
    else:
        _nearest_pixels_any(model_id, params, T, x, y, z, width, height, invalid, out)
