"""Continuous-time ICP kernels: deskewing and point-to-plane normal equations.

A scan's motion is described by two poses, ``T_world_begin`` and ``T_world_end`` (the sensor at
the first and last point time), and a point with normalised time ``s in [0, 1]`` is seen from the
interpolated pose (``docs/conventions.md``: slerp the rotation, lerp the translation)::

    R(s) = R_b exp(s phi),  phi = log(R_b^T R_e)      t(s) = (1 - s) t_b + s t_e
    p_world = R(s) p + t(s)

``phi`` is computed once per scan by the caller (``nbcalib.kernels.lie.so3_log``) and passed in.

**Association** (:func:`_associate`). Each source point, moved to the world frame, looks up its
``k`` nearest map points (:func:`nbcalib.kernels.voxelmap._knn_one`); when at least
``min_neighbors`` are found, their mean ``mu`` and covariance give a plane (normal ``n`` = the
eigenvector of the smallest eigenvalue ``l0 <= l1 <= l2``) with the CT-ICP planarity weight
``a2D^2``, ``a2D = (sqrt(l1) - sqrt(l0)) / sqrt(l2)``; patches thicker than ``max_thickness``
(``sqrt(l0)``: edges, corners, curved or cluttered surfaces) give no residual. The caller keeps
these planes over several Gauss-Newton steps and associates again when the points have moved.

**Normal equations** (:func:`_normal_equations`). The point-to-plane residual is
``r = n . p_world - n . mu``, weighted by ``a2D^2`` times the Geman-McClure weight
``(c^2 / (c^2 + r^2))^2`` of robust scale ``c``. The 12 parameters are the left increments of
the two poses on SO(3) x R^3, ``[v_b, w_b, v_e, w_e]`` with ``R <- exp(w) R`` and
``t <- t + v`` (the group in which the interpolation above is linear in ``t``), and the Jacobian
row is::

    d r / d[v_b, w_b, v_e, w_e] = [(1 - s) n, (1 - s) q x n, s n, s q x n],   q = R(s) p

(exact for the translations; for the rotations it neglects the change of the slerp path with
the end points, a second-order effect for intra-scan rotations of a few degrees).

Points are split into a fixed number of chunks whose partial sums are added in chunk order, so
the serial and the parallel kernels give identical bits whatever the thread count.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.lie import _so3_exp_scalars_into
from nbcalib.kernels.normals import _scatter3
from nbcalib.kernels.voxelmap import _knn_one

#: number of chunks the point loops are split into (fixed: it sets the summation order)
N_CHUNKS = 64


@jit
def _chunk_bounds(n, n_chunks, c):
    return (n * c) // n_chunks, (n * (c + 1)) // n_chunks


@jit
def _point_at(p, s, R_b, t_b, t_e, phi, E):
    """World point and rotated point ``q = R(s) p``, with ``E`` a (3, 3) scratch."""
    _so3_exp_scalars_into(s * phi[0], s * phi[1], s * phi[2], E)
    ex = E[0, 0] * p[0] + E[0, 1] * p[1] + E[0, 2] * p[2]
    ey = E[1, 0] * p[0] + E[1, 1] * p[1] + E[1, 2] * p[2]
    ez = E[2, 0] * p[0] + E[2, 1] * p[1] + E[2, 2] * p[2]
    qx = R_b[0, 0] * ex + R_b[0, 1] * ey + R_b[0, 2] * ez
    qy = R_b[1, 0] * ex + R_b[1, 1] * ey + R_b[1, 2] * ez
    qz = R_b[2, 0] * ex + R_b[2, 1] * ey + R_b[2, 2] * ez
    u = 1.0 - s
    wx = qx + u * t_b[0] + s * t_e[0]
    wy = qy + u * t_b[1] + s * t_e[1]
    wz = qz + u * t_b[2] + s * t_e[2]
    return wx, wy, wz, qx, qy, qz


def _deskew_impl(points, s, R_b, t_b, t_e, phi, out):
    n = points.shape[0]
    for c in prange(N_CHUNKS):
        E = np.empty((3, 3))
        lo, hi = _chunk_bounds(n, N_CHUNKS, c)
        for i in range(lo, hi):
            wx, wy, wz, _, _, _ = _point_at(points[i], s[i], R_b, t_b, t_e, phi, E)
            out[i, 0] = wx
            out[i, 1] = wy
            out[i, 2] = wz


#: Deskew ``points`` (N, 3) with normalised times ``s`` (N,) into ``out`` (N, 3) (world frame).
_deskew = jit(_deskew_impl)
_deskew_parallel = jit_parallel(_deskew_impl)


@jit
def _sym3_smallest(a00, a01, a02, a11, a12, a22):
    """Eigenvalues ``l0 <= l1 <= l2`` of a symmetric 3 x 3 matrix and a unit eigenvector of l0.

    Closed form (trigonometric solution of the characteristic cubic), the eigenvector as the
    longest cross product of two rows of ``A - l0 I``. Returns ``(l0, l1, l2, nx, ny, nz)``;
    the vector is (0, 0, 0) when ``A - l0 I`` has rank < 2 (l0 repeated).
    """
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1
    if p2 <= 0.0:
        return q, q, q, 0.0, 0.0, 0.0
    p = math.sqrt(p2 / 6.0)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    r = 0.5 * det / (p * p * p)
    r = min(max(r, -1.0), 1.0)
    angle = math.acos(r) / 3.0
    l2 = q + 2.0 * p * math.cos(angle)
    l0 = q + 2.0 * p * math.cos(angle + 2.0 * math.pi / 3.0)
    l1 = 3.0 * q - l0 - l2
    # rows of A - l0 I
    r0x, r0y, r0z = a00 - l0, a01, a02
    r1x, r1y, r1z = a01, a11 - l0, a12
    r2x, r2y, r2z = a02, a12, a22 - l0
    c0x, c0y, c0z = r0y * r1z - r0z * r1y, r0z * r1x - r0x * r1z, r0x * r1y - r0y * r1x
    c1x, c1y, c1z = r0y * r2z - r0z * r2y, r0z * r2x - r0x * r2z, r0x * r2y - r0y * r2x
    c2x, c2y, c2z = r1y * r2z - r1z * r2y, r1z * r2x - r1x * r2z, r1x * r2y - r1y * r2x
    n0 = c0x * c0x + c0y * c0y + c0z * c0z
    n1 = c1x * c1x + c1y * c1y + c1z * c1z
    n2 = c2x * c2x + c2y * c2y + c2z * c2z
    if n0 >= n1 and n0 >= n2:
        nx, ny, nz, nn = c0x, c0y, c0z, n0
    elif n1 >= n2:
        nx, ny, nz, nn = c1x, c1y, c1z, n1
    else:
        nx, ny, nz, nn = c2x, c2y, c2z, n2
    if nn <= 0.0:
        return l0, l1, l2, 0.0, 0.0, 0.0
    inv = 1.0 / math.sqrt(nn)
    return l0, l1, l2, nx * inv, ny * inv, nz * inv


@jit
def _plane(store_flat, idx, n):
    """Plane of the ``n`` points ``store_flat[idx[:n]]``: (mx, my, mz, nx, ny, nz, a2D, l0).

    Mean, unit normal, CT-ICP planarity ``a2D`` (0 when degenerate) and the smallest eigenvalue
    ``l0`` of the covariance (the squared thickness of the patch).
    """
    mx, my, mz, c00, c01, c02, c11, c12, c22 = _scatter3(store_flat, idx, n)
    l0, l1, l2, nx, ny, nz = _sym3_smallest(c00 / n, c01 / n, c02 / n, c11 / n, c12 / n, c22 / n)
    l0 = max(l0, 0.0)
    if l2 <= 0.0 or nx * nx + ny * ny + nz * nz == 0.0:
        return mx, my, mz, 0.0, 0.0, 0.0, 0.0, l0
    a2d = (math.sqrt(max(l1, 0.0)) - math.sqrt(l0)) / math.sqrt(l2)
    return mx, my, mz, nx, ny, nz, a2d, l0


#: columns of the per-point plane table written by :func:`_associate`
PLANE_NX, PLANE_NY, PLANE_NZ, PLANE_OFFSET, PLANE_WEIGHT = 0, 1, 2, 3, 4
PLANE_SIZE = 5


def _associate_impl(
    points,
    s,
    R_b,
    t_b,
    t_e,
    phi,
    table,
    counts,
    store,
    voxel_size,
    k,
    max_distance,
    min_neighbors,
    max_thickness,
    planes,
):
    n = points.shape[0]
    store_flat = store.reshape(-1, 3)
    max_d2 = max_distance * max_distance
    max_l0 = max_thickness * max_thickness
    for c in prange(N_CHUNKS):
        E = np.empty((3, 3))
        idx = np.empty(k, dtype=np.int64)
        d2 = np.empty(k)
        lo, hi = _chunk_bounds(n, N_CHUNKS, c)
        for i in range(lo, hi):
            wx, wy, wz, _, _, _ = _point_at(points[i], s[i], R_b, t_b, t_e, phi, E)
            found = _knn_one(table, counts, store, voxel_size, wx, wy, wz, max_d2, idx, d2)
            weight = 0.0
            mx = my = mz = nx = ny = nz = 0.0
            if found >= min_neighbors:
                mx, my, mz, nx, ny, nz, a2d, l0 = _plane(store_flat, idx, found)
                if a2d > 0.0 and l0 <= max_l0:
                    weight = a2d * a2d
                else:
                    nx = ny = nz = 0.0
            planes[i, PLANE_NX] = nx
            planes[i, PLANE_NY] = ny
            planes[i, PLANE_NZ] = nz
            planes[i, PLANE_OFFSET] = nx * mx + ny * my + nz * mz
            planes[i, PLANE_WEIGHT] = weight


#: Plane of each source point at the given poses into ``planes`` (N, PLANE_SIZE): unit normal,
#: offset ``n . mu`` and planarity weight ``a2D^2`` (a row of zeros: no plane).
_associate = jit(_associate_impl)
_associate_parallel = jit_parallel(_associate_impl)


def _normal_equations_impl(points, s, R_b, t_b, t_e, phi, planes, robust_scale):
    n = points.shape[0]
    # per-chunk sums, zeroed by their chunk: an np.zeros here (or an array expression after
    # the loop) would run as a parallel region of its own, each waking the threads (~50 us)
    H_parts = np.empty((N_CHUNKS, 12, 12))
    g_parts = np.empty((N_CHUNKS, 12))
    cost_parts = np.empty(N_CHUNKS)
    used_parts = np.empty(N_CHUNKS, dtype=np.int64)
    c2 = robust_scale * robust_scale
    for c in prange(N_CHUNKS):
        E = np.empty((3, 3))
        J = np.empty(12)
        H = H_parts[c]
        g = g_parts[c]
        for a in range(12):
            g[a] = 0.0
            for b in range(12):
                H[a, b] = 0.0
        cost_parts[c] = 0.0
        used_parts[c] = 0
        lo, hi = _chunk_bounds(n, N_CHUNKS, c)
        for i in range(lo, hi):
            a2d2 = planes[i, PLANE_WEIGHT]
            if a2d2 <= 0.0:
                continue
            nx, ny, nz = planes[i, PLANE_NX], planes[i, PLANE_NY], planes[i, PLANE_NZ]
            si = s[i]
            wx, wy, wz, qx, qy, qz = _point_at(points[i], si, R_b, t_b, t_e, phi, E)
            r = nx * wx + ny * wy + nz * wz - planes[i, PLANE_OFFSET]
            robust = c2 / (c2 + r * r)
            w = a2d2 * robust * robust
            # q x n
            cx = qy * nz - qz * ny
            cy = qz * nx - qx * nz
            cz = qx * ny - qy * nx
            u = 1.0 - si
            J[0], J[1], J[2] = u * nx, u * ny, u * nz
            J[3], J[4], J[5] = u * cx, u * cy, u * cz
            J[6], J[7], J[8] = si * nx, si * ny, si * nz
            J[9], J[10], J[11] = si * cx, si * cy, si * cz
            for a in range(12):
                wa = w * J[a]
                g[a] += wa * r
                for b in range(a, 12):
                    H[a, b] += wa * J[b]
            cost_parts[c] += w * r * r
            used_parts[c] += 1
    H_total = np.empty((12, 12))
    g_total = np.empty(12)
    for a in range(12):
        total = 0.0
        for c in range(N_CHUNKS):
            total += g_parts[c, a]
        g_total[a] = total
        for b in range(a, 12):
            total = 0.0
            for c in range(N_CHUNKS):
                total += H_parts[c, a, b]
            H_total[a, b] = total
    cost = 0.0
    used = 0
    for c in range(N_CHUNKS):
        cost += cost_parts[c]
        used += used_parts[c]
    for a in range(12):
        for b in range(a):
            H_total[a, b] = H_total[b, a]
    return H_total, g_total, cost, used


#: Point-to-plane normal equations against the planes of :func:`_associate` (module docstring);
#: returns (H (12, 12), g (12,), weighted cost, number of residuals).
_normal_equations = jit(_normal_equations_impl)
_normal_equations_parallel = jit_parallel(_normal_equations_impl)


@jit
def _select_points(
    points, intensity, times, has_times, frame_rate, clockwise, start_azimuth, min_d2, want_s
):
    """Finite points at or beyond ``sqrt(min_d2)`` from the sensor, with normalised times.

    A row counts when x, y, z, its intensity (and its time, with ``has_times``) are finite. The
    times are the given ones or, without ``has_times``, the azimuth times of
    :func:`nbcalib.odometry.scans.synthesize_times_from_azimuth`; ``s = (t - t_min) /
    (t_max - t_min)`` over all finite rows (0 when they share one time). Returns ``(points (M, 3),
    intensity (M,), s (M,), number of finite rows, t_max - t_min)``; ``s`` is empty unless
    ``want_s``.
    """
    n = points.shape[0]
    two_pi = 2.0 * math.pi
    t = np.empty(n)
    finite = np.zeros(n, dtype=np.bool_)
    n_finite = 0
    n_far = 0
    t_min, t_max = np.inf, -np.inf
    for i in range(n):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        ok = math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
        ok = ok and math.isfinite(intensity[i])
        if has_times:
            ok = ok and math.isfinite(times[i])
        if not ok:
            continue
        finite[i] = True
        n_finite += 1
        if x * x + y * y + z * z >= min_d2:
            n_far += 1
        if want_s:
            if has_times:
                ti = times[i]
            else:
                azimuth = math.atan2(y, x)
                turned = start_azimuth - azimuth if clockwise else azimuth - start_azimuth
                fraction = (turned - math.floor(turned / two_pi) * two_pi) / two_pi
                if fraction >= 1.0:
                    fraction = 0.0
                ti = fraction / frame_rate
            t[i] = ti
            t_min = min(t_min, ti)
            t_max = max(t_max, ti)
    duration = t_max - t_min if n_finite > 0 else 0.0
    out_points = np.empty((n_far, 3))
    out_intensity = np.empty(n_far)
    out_s = np.empty(n_far if want_s else 0)
    j = 0
    for i in range(n):
        if not finite[i]:
            continue
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        if x * x + y * y + z * z < min_d2:
            continue
        out_points[j, 0] = x
        out_points[j, 1] = y
        out_points[j, 2] = z
        out_intensity[j] = intensity[i]
        if want_s:
            out_s[j] = (t[i] - t_min) / duration if duration > 0.0 else 0.0
        j += 1
    return out_points, out_intensity, out_s, n_finite, max(duration, 0.0)
