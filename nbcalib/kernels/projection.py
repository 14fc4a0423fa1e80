"""Camera projection kernels, one point at a time: camera-frame points to pixels and Jacobians.

Every model is a flat parameter vector ``params`` (float64, length :data:`N_PARAMS`) plus an integer
model id, so that any other kernel (z-buffer, NID cost, RANSAC, ray casting) can call
:func:`project_point` / :func:`~nbcalib.kernels.unprojection.unproject_pixel` without Python
objects. The public wrapper is :class:`nbcalib.camera.CameraModel`, which validates parameters and
fills ``params``; its batched loops are in :mod:`nbcalib.kernels.projection_batch` (with the
vectorised :func:`~nbcalib.kernels.projection_batch.nearest_pixels`) and
:mod:`nbcalib.kernels.unprojection` (pixels to bearings). The slow, readable references are in
:mod:`nbcalib.reference.camera`.

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


# --------------------------------------------------------------------------------------------
# Distortion on the normalised plane: pinhole family and omnidir share it
# --------------------------------------------------------------------------------------------


@jit_inline
def _distort_poly_terms(params, x, y, rational):
    """``(r2, den, xd, yd)`` of the Brown-Conrady / rational distortion, without validity tests.

    The one place its arithmetic is written: :func:`_distort_poly` tests ``r2`` and ``den``
    after it, and the branch-free loops of
    :func:`~nbcalib.kernels.projection_batch.nearest_pixels` fold the same tests into one
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
