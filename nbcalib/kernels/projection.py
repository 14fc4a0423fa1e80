"""Camera projection kernels: camera-frame points to pixels, their Jacobians, and unprojection.

Every model is a flat parameter vector ``params`` (float64, length :data:`N_PARAMS`) plus an integer
model id, so that any other kernel (z-buffer, NID cost, RANSAC, ray casting) can call
:func:`project_point` / :func:`unproject_pixel` without Python objects. The public wrapper is
:class:`nbcalib.camera.CameraModel`, which validates parameters and fills ``params``; the slow,
readable references are in :mod:`nbcalib.reference.camera`.

Layout of ``params`` (unused slots are 0)::

    0 fx   1 fy   2 cx   3 cy   4 xi (omnidir)
    5..12  distortion d0..d7 in the model's order
           plumb_bob / rational_polynomial / pinhole: k1 k2 p1 p2 k3 k4 k5 k6
           fisheye: k1 k2 k3 k4;  atan: omega;  omnidir: k1 k2 p1 p2
    13     domain limit: r^2 on the normalised plane (pinhole family, omnidir) or the largest angle
           to the optical axis (fisheye), beyond which the distortion stops being monotonic and a
           point would fold back into the image; inf when there is no such limit
    14 width   15 height

Conventions (docs/conventions.md): camera optical frame (x right, y down, z forward), pixel centres
at integer coordinates. Invalid points (behind the camera, outside the model's domain, non-finite)
get ``valid = False`` and NaN pixels; they are never folded forward.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit, jit_inline

N_PARAMS = 16
P_FX, P_FY, P_CX, P_CY, P_XI = 0, 1, 2, 3, 4
P_DIST = 5
P_LIMIT = 13
P_WIDTH, P_HEIGHT = 14, 15

PINHOLE = 0
PLUMB_BOB = 1
RATIONAL_POLYNOMIAL = 2
FISHEYE = 3
ATAN = 4
OMNIDIR = 5
EQUIRECTANGULAR = 6

#: below this ratio rho/z (fisheye) or a*r (atan), the exact expressions lose digits to
#: cancellation and the series expansions (error O(t^4), i.e. < 1e-16 relative) are used
_SERIES_T = 1e-4
_NEWTON_ITERS = 30


# --------------------------------------------------------------------------------------------
# Distortion on the normalised plane: pinhole family and omnidir share it
# --------------------------------------------------------------------------------------------


@jit_inline
def _distort_poly_terms(params, x, y, rational):
    """``(r2, den, xd, yd)`` of the Brown-Conrady / rational distortion, without validity tests.

    The one place its arithmetic is written: :func:`_distort_poly` tests ``r2`` and ``den``
    after it, and the branch-free loops of :func:`nearest_pixels` fold the same tests into one
    boolean, so both give identical pixels. ``rational`` False (k4 = k5 = k6 = 0, a constant
    at the call site) skips the denominator: ``den = 1`` and ``radial = num``, which is what
    ``num / 1.0`` gives for every finite ``r2``.
    """
    k1 = params[P_DIST + 0]
    k2 = params[P_DIST + 1]
    p1 = params[P_DIST + 2]
    p2 = params[P_DIST + 3]
    k3 = params[P_DIST + 4]
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if rational:
        den = 1.0 + r2 * (params[P_DIST + 5] + r2 * (params[P_DIST + 6] + r2 * params[P_DIST + 7]))
        radial = num / den
    else:
        den = 1.0
        radial = num
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return r2, den, xd, yd


@jit_inline
def _distort_poly(params, x, y):
    """Brown-Conrady / rational distortion of a normalised point; returns (xd, yd, ok)."""
    r2, den, xd, yd = _distort_poly_terms(params, x, y, True)
    if not r2 <= params[P_LIMIT]:
        return math.nan, math.nan, False
    if den <= 0.0:
        return math.nan, math.nan, False
    return xd, yd, True


@jit
def _distort_poly_jacobian(params, x, y):
    """Jacobian of :func:`_distort_poly`: returns (xd, yd, a00, a01, a10, a11, ok)."""
    k1 = params[P_DIST + 0]
    k2 = params[P_DIST + 1]
    p1 = params[P_DIST + 2]
    p2 = params[P_DIST + 3]
    k3 = params[P_DIST + 4]
    k4 = params[P_DIST + 5]
    k5 = params[P_DIST + 6]
    k6 = params[P_DIST + 7]
    r2 = x * x + y * y
    if not r2 <= params[P_LIMIT]:
        return math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    if den <= 0.0:
        return math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False
    radial = num / den
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    a00 = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
    a01 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
    a10 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
    a11 = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, a00, a01, a10, a11, True


@jit
def _undistort_poly(params, xd, yd):
    """Invert :func:`_distort_poly` by Newton's method; returns (x, y, ok).

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
            f = r * rad - rd
            df = rad + 2.0 * r2 * drad
            if df <= 0.0:
                break
            step = f / df
            r_new = r - step
            if r_new < 0.0:
                r_new = 0.5 * r
            if r_new > r_hi:
                r_new = 0.5 * (r + r_hi)
            r = r_new
            if abs(step) <= 1e-15 * (1.0 + r):
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


# --------------------------------------------------------------------------------------------
# Per-model projection. Value functions are small and inlined into every calling kernel
# (jit_inline); the Jacobian functions repeat the value arithmetic expression for expression, so
# both paths give bit-identical pixels (tested), and add the derivatives.
# --------------------------------------------------------------------------------------------

_NAN9 = (math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, math.nan, False)


@jit_inline
def _pinhole_family_value(params, X, Y, Z):
    """pinhole, plumb_bob, rational_polynomial (they differ only in which coefficients are 0)."""
    if not Z > 0.0:
        return math.nan, math.nan, False
    iz = 1.0 / Z
    xd, yd, ok = _distort_poly(params, X * iz, Y * iz)
    if not ok:
        return math.nan, math.nan, False
    return params[P_FX] * xd + params[P_CX], params[P_FY] * yd + params[P_CY], True


@jit
def _pinhole_family_jacobian(params, X, Y, Z):
    if not Z > 0.0:
        return _NAN9
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    xd, yd, a00, a01, a10, a11, ok = _distort_poly_jacobian(params, x, y)
    if not ok:
        return _NAN9
    fx = params[P_FX]
    fy = params[P_FY]
    # d(x, y)/dP = [[iz, 0, -x iz], [0, iz, -y iz]]
    j00 = fx * a00 * iz
    j01 = fx * a01 * iz
    j02 = -fx * (a00 * x + a01 * y) * iz
    j10 = fy * a10 * iz
    j11 = fy * a11 * iz
    j12 = -fy * (a10 * x + a11 * y) * iz
    return fx * xd + params[P_CX], fy * yd + params[P_CY], j00, j01, j02, j10, j11, j12, True


@jit_inline
def _fisheye_scale(params, X, Y, Z):
    """Kannala-Brandt: s = theta_d / rho with theta = atan2(rho, z) (no |z| folding).

    Returns ``(s, theta, rho, ok)``; near the axis (rho < 1e-4 z) the series of s is used.
    """
    rho = math.sqrt(X * X + Y * Y)
    if not (rho > 0.0 or Z > 0.0):  # on the axis behind the camera, or NaN
        return math.nan, math.nan, math.nan, False
    theta = math.atan2(rho, Z)
    if not theta <= params[P_LIMIT]:
        return math.nan, math.nan, math.nan, False
    if Z > 0.0 and rho < _SERIES_T * Z:
        # s = (1/Z) (1 + (k1 - 1/3) t^2 + O(t^4)), t = rho / Z
        q = rho / Z
        return (1.0 + (params[P_DIST] - 1.0 / 3.0) * q * q) / Z, theta, rho, True
    t2 = theta * theta
    k1 = params[P_DIST + 0]
    k2 = params[P_DIST + 1]
    k3 = params[P_DIST + 2]
    k4 = params[P_DIST + 3]
    theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    return theta_d / rho, theta, rho, True


@jit_inline
def _fisheye_value(params, X, Y, Z):
    s, _, _, ok = _fisheye_scale(params, X, Y, Z)
    if not ok:
        return math.nan, math.nan, False
    return params[P_FX] * s * X + params[P_CX], params[P_FY] * s * Y + params[P_CY], True


@jit
def _fisheye_jacobian(params, X, Y, Z):
    s, theta, rho, ok = _fisheye_scale(params, X, Y, Z)
    if not ok:
        return _NAN9
    k1 = params[P_DIST + 0]
    k2 = params[P_DIST + 1]
    k3 = params[P_DIST + 2]
    k4 = params[P_DIST + 3]
    rho2 = rho * rho
    t2 = theta * theta
    if Z > 0.0 and rho < _SERIES_T * Z:
        q = rho / Z
        c = k1 - 1.0 / 3.0
        ds_drho_over_rho = 2.0 * c / (Z * Z * Z)
        ds_dz = -(1.0 + 3.0 * c * q * q) / (Z * Z)
    else:
        theta_d = theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
        dtheta_d = 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
        n2 = rho2 + Z * Z
        ds_drho_over_rho = (dtheta_d * Z / n2 * rho - theta_d) / (rho2 * rho)
        ds_dz = -dtheta_d / n2
    fx = params[P_FX]
    fy = params[P_FY]
    # xd = s X, yd = s Y;  ds/dX = ds/drho * X / rho
    j00 = fx * (s + X * X * ds_drho_over_rho)
    j01 = fx * (X * Y * ds_drho_over_rho)
    j02 = fx * (X * ds_dz)
    j10 = fy * (X * Y * ds_drho_over_rho)
    j11 = fy * (s + Y * Y * ds_drho_over_rho)
    j12 = fy * (Y * ds_dz)
    u = fx * s * X + params[P_CX]
    v = fy * s * Y + params[P_CY]
    return u, v, j00, j01, j02, j10, j11, j12, True


@jit_inline
def _atan_factor(params, r2):
    """FOV model factor f(r) = atan(a r) / (w r), a = 2 tan(w / 2); series near r = 0."""
    w = params[P_DIST]
    if w < 1e-7:
        return 1.0
    a = 2.0 * math.tan(0.5 * w)
    r = math.sqrt(r2)
    s = a * r
    if s < _SERIES_T:
        return a / w * (1.0 - s * s / 3.0 + s * s * s * s / 5.0)
    return math.atan(s) / (w * r)


@jit_inline
def _atan_value(params, X, Y, Z):
    """FOV (ATAN) model of Devernay and Faugeras, omega in params[P_DIST]."""
    if not Z > 0.0:
        return math.nan, math.nan, False
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    f = _atan_factor(params, x * x + y * y)
    return params[P_FX] * f * x + params[P_CX], params[P_FY] * f * y + params[P_CY], True


@jit
def _atan_jacobian(params, X, Y, Z):
    if not Z > 0.0:
        return _NAN9
    w = params[P_DIST]
    iz = 1.0 / Z
    x = X * iz
    y = Y * iz
    r2 = x * x + y * y
    f = _atan_factor(params, r2)
    if w < 1e-7:
        g = 0.0
    else:
        a = 2.0 * math.tan(0.5 * w)
        r = math.sqrt(r2)
        s = a * r
        if s < _SERIES_T:
            g = a * a * a / w * (-2.0 / 3.0 + 4.0 * s * s / 5.0)
        else:
            g = (s / (1.0 + s * s) - math.atan(s)) / (w * r2 * r)  # f'(r) / r
    fx = params[P_FX]
    fy = params[P_FY]
    a00 = f + g * x * x
    a01 = g * x * y
    a11 = f + g * y * y
    j00 = fx * a00 * iz
    j01 = fx * a01 * iz
    j02 = -fx * (a00 * x + a01 * y) * iz
    j10 = fy * a01 * iz
    j11 = fy * a11 * iz
    j12 = -fy * (a01 * x + a11 * y) * iz
    return fx * f * x + params[P_CX], fy * f * y + params[P_CY], j00, j01, j02, j10, j11, j12, True


@jit_inline
def _omnidir_denominator(params, X, Y, Z):
    """Unified (Mei) model: ``d = z + xi |P|`` on the visible part of the sphere, else NaN."""
    xi = params[P_XI]
    n = math.sqrt(X * X + Y * Y + Z * Z)
    if not n > 0.0:
        return math.nan, n
    # visible part of the sphere: s_z > -min(xi, 1/xi) (tangent cone for xi > 1)
    zmin = -min(xi, 1.0 / xi) if xi > 0.0 else 0.0
    if not Z > zmin * n:
        return math.nan, n
    return Z + xi * n, n


@jit_inline
def _omnidir_value(params, X, Y, Z):
    d, _ = _omnidir_denominator(params, X, Y, Z)
    if not d > 0.0:
        return math.nan, math.nan, False
    xd, yd, ok = _distort_poly(params, X / d, Y / d)
    if not ok:
        return math.nan, math.nan, False
    return params[P_FX] * xd + params[P_CX], params[P_FY] * yd + params[P_CY], True


@jit
def _omnidir_jacobian(params, X, Y, Z):
    d, n = _omnidir_denominator(params, X, Y, Z)
    if not d > 0.0:
        return _NAN9
    xi = params[P_XI]
    xd, yd, a00, a01, a10, a11, ok = _distort_poly_jacobian(params, X / d, Y / d)
    if not ok:
        return _NAN9
    fx = params[P_FX]
    fy = params[P_FY]
    # d d / dP = xi P / n + e_z
    id2 = 1.0 / (d * d)
    dd_dx = xi * X / n
    dd_dy = xi * Y / n
    dd_dz = 1.0 + xi * Z / n
    bx0 = (d - X * dd_dx) * id2
    bx1 = -X * dd_dy * id2
    bx2 = -X * dd_dz * id2
    by0 = -Y * dd_dx * id2
    by1 = (d - Y * dd_dy) * id2
    by2 = -Y * dd_dz * id2
    j00 = fx * (a00 * bx0 + a01 * by0)
    j01 = fx * (a00 * bx1 + a01 * by1)
    j02 = fx * (a00 * bx2 + a01 * by2)
    j10 = fy * (a10 * bx0 + a11 * by0)
    j11 = fy * (a10 * bx1 + a11 * by1)
    j12 = fy * (a10 * bx2 + a11 * by2)
    return fx * xd + params[P_CX], fy * yd + params[P_CY], j00, j01, j02, j10, j11, j12, True


@jit_inline
def _equirectangular_value(params, X, Y, Z):
    """Longitude atan2(x, z) across the width, latitude down the height; poles excluded."""
    q = math.sqrt(X * X + Z * Z)
    if not q > 0.0:  # the two pole rays (and NaN) have no longitude
        return math.nan, math.nan, False
    u = params[P_WIDTH] * (0.5 + math.atan2(X, Z) / (2.0 * math.pi)) - 0.5
    v = params[P_HEIGHT] * (0.5 + math.atan2(Y, q) / math.pi) - 0.5
    return u, v, True


@jit
def _equirectangular_jacobian(params, X, Y, Z):
    u, v, ok = _equirectangular_value(params, X, Y, Z)
    if not ok:
        return _NAN9
    q2 = X * X + Z * Z
    q = math.sqrt(q2)
    cu = params[P_WIDTH] / (2.0 * math.pi)
    cv = params[P_HEIGHT] / math.pi
    n2 = q2 + Y * Y
    j00 = cu * Z / q2
    j01 = 0.0
    j02 = -cu * X / q2
    j10 = -cv * Y * X / (q * n2)
    j11 = cv * q / n2
    j12 = -cv * Y * Z / (q * n2)
    return u, v, j00, j01, j02, j10, j11, j12, True


@jit_inline
def _finite3(X, Y, Z):
    return math.isfinite(X) and math.isfinite(Y) and math.isfinite(Z)


@jit_inline
def project_point(model_id, params, X, Y, Z):
    """Project one camera-frame point; returns ``(u, v, valid)``. For use inside kernels."""
    if not _finite3(X, Y, Z):
        return math.nan, math.nan, False
    if model_id <= RATIONAL_POLYNOMIAL:
        return _pinhole_family_value(params, X, Y, Z)
    if model_id == FISHEYE:
        return _fisheye_value(params, X, Y, Z)
    if model_id == ATAN:
        return _atan_value(params, X, Y, Z)
    if model_id == OMNIDIR:
        return _omnidir_value(params, X, Y, Z)
    return _equirectangular_value(params, X, Y, Z)


@jit
def project_point_jacobian(model_id, params, X, Y, Z):
    """Project one point with ``d(u, v)/d(X, Y, Z)``.

    Returns ``(u, v, j00, j01, j02, j10, j11, j12, valid)``, row-major 2 x 3 Jacobian.
    """
    if not _finite3(X, Y, Z):
        return _NAN9
    if model_id <= RATIONAL_POLYNOMIAL:
        return _pinhole_family_jacobian(params, X, Y, Z)
    if model_id == FISHEYE:
        return _fisheye_jacobian(params, X, Y, Z)
    if model_id == ATAN:
        return _atan_jacobian(params, X, Y, Z)
    if model_id == OMNIDIR:
        return _omnidir_jacobian(params, X, Y, Z)
    return _equirectangular_jacobian(params, X, Y, Z)


# --------------------------------------------------------------------------------------------
# Unprojection: pixel -> unit bearing
# --------------------------------------------------------------------------------------------


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
            if df <= 0.0:
                break
            step = f / df
            t_new = theta - step
            if t_new < 0.0:
                t_new = 0.5 * theta
            if t_new > theta_max:
                t_new = 0.5 * (theta + theta_max)
            theta = t_new
            if abs(step) <= 1e-15 * (1.0 + theta):
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


# --------------------------------------------------------------------------------------------
# Batched kernels behind nbcalib.camera.CameraModel
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Nearest pixels of many points at once, written so that LLVM vectorises the loop
# --------------------------------------------------------------------------------------------
#
# project_point() returns early on every invalid case, so a loop over it runs one point at a
# time. The loops below compute every point's pixel without branches and fold the validity tests
# into one boolean, for the models whose arithmetic has no library calls (the pinhole family
# and omnidir); LLVM then runs 8 points per AVX-512 instruction. They evaluate exactly the
# expressions of the scalar helpers above, in the same order, with IEEE semantics (no
# fast-math), so every pixel and every validity decision is identical to project_point()
# followed by floor(u + 0.5) (tested). The other models go through project_point().
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
