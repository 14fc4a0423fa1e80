"""Slow, readable references of the dense-cloud kernels.

They mirror :mod:`nbcalib.kernels.voxelmap` and :mod:`nbcalib.kernels.ct_icp`: each function
spells out the semantics with dictionaries, brute-force searches and ``numpy.linalg.eigh``; the
tests hold the kernels equal to them (integer outputs exactly, floats to ~1e-12, or ~1e-9 where
the kernel's closed-form eigenvectors meet ``eigh``).
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.transforms import interpolate_pose

__all__ = [
    "VoxelMapReference",
    "associate",
    "deskew",
    "knn_bruteforce",
    "normal_equations",
    "select_points",
    "voxel_deduplicate",
    "voxel_first_indices",
    "voxel_key",
]


def voxel_key(p, voxel_size: float) -> tuple[int, int, int]:
    """Integer voxel coordinates ``floor(p / voxel_size)`` of one point (a division, as kernels)."""
    return (
        math.floor(p[0] / voxel_size),
        math.floor(p[1] / voxel_size),
        math.floor(p[2] / voxel_size),
    )


def voxel_first_indices(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """Index of the first point of each voxel, voxels in order of first appearance."""
    first: dict[tuple[int, int, int], int] = {}
    for i, p in enumerate(points):
        first.setdefault(voxel_key(p, voxel_size), i)
    return np.array(list(first.values()), dtype=np.int64)


def voxel_deduplicate(
    points: np.ndarray, intensity: np.ndarray, voxel_size: float, rule: str
) -> tuple[np.ndarray, np.ndarray]:
    """One point per voxel, voxels in order of first appearance.

    ``rule="last"``: the last point and intensity that fell into the voxel (the reference
    toolbox's overwrite); ``rule="mean"``: the mean of its points and of their intensities, summed
    in input order.
    """
    voxels: dict[tuple[int, int, int], list[float]] = {}
    for p, v in zip(points, intensity):
        key = voxel_key(p, voxel_size)
        if rule == "last":
            voxels[key] = [p[0], p[1], p[2], v, 1.0]
        else:
            acc = voxels.setdefault(key, [0.0, 0.0, 0.0, 0.0, 0.0])
            acc[0] += p[0]
            acc[1] += p[1]
            acc[2] += p[2]
            acc[3] += v
            acc[4] += 1.0
    values = np.array(list(voxels.values()), dtype=np.float64).reshape(-1, 5)
    if rule == "mean":
        values[:, :4] /= values[:, 4:5]
    return values[:, :3].copy(), values[:, 3].copy()


class VoxelMapReference:
    """The iVox-like map as a dictionary of lists.

    A point goes to the list of its voxel unless that list already holds ``max_points_per_voxel``
    points or a point closer than ``min_spacing``. Voxels are numbered (``slot``) in order of
    first appearance, and a stored point's flat index is ``slot * max_points_per_voxel + j``, as in
    the kernel.
    """

    def __init__(self, voxel_size: float, max_points_per_voxel: int, min_spacing: float):
        self.voxel_size = voxel_size
        self.capacity = max_points_per_voxel
        self.min_spacing = min_spacing
        self.voxels: dict[tuple[int, int, int], list[np.ndarray]] = {}

    def insert(self, points: np.ndarray) -> int:
        """Add points (M, 3) one by one; returns how many were stored."""
        kept = 0
        for p in points:
            cell = self.voxels.setdefault(voxel_key(p, self.voxel_size), [])
            if len(cell) >= self.capacity:
                continue
            if any(np.sum((q - p) ** 2) < self.min_spacing**2 for q in cell):
                continue
            cell.append(np.array(p, dtype=np.float64))
            kept += 1
        return kept

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Stored points (M, 3) and their flat indices (M,), in slot order."""
        pts, flat = [], []
        for slot, cell in enumerate(self.voxels.values()):
            for j, q in enumerate(cell):
                pts.append(q)
                flat.append(slot * self.capacity + j)
        return np.array(pts, dtype=np.float64).reshape(-1, 3), np.array(flat, dtype=np.int64)


def knn_bruteforce(
    points: np.ndarray, flat: np.ndarray, queries: np.ndarray, k: int, max_distance: float
) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest of ``points`` (with ids ``flat``) to each query, within ``max_distance``.

    Ordered by (squared distance, id); padded with -1 / inf. Returns (Q, k) ids and squared
    distances.
    """
    idx = np.full((len(queries), k), -1, dtype=np.int64)
    d2_out = np.full((len(queries), k), np.inf)
    for i, q in enumerate(queries):
        d = points - q
        d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]  # as the kernel sums
        inside = np.flatnonzero(d2 <= max_distance * max_distance)
        order = sorted(inside, key=lambda j: (d2[j], flat[j]))[:k]
        idx[i, : len(order)] = flat[order]
        d2_out[i, : len(order)] = d2[order]
    return idx, d2_out


def deskew(points: np.ndarray, s: np.ndarray, T_world_begin, T_world_end) -> np.ndarray:
    """Each point moved with ``interpolate_pose(T_world_begin, T_world_end, s_i)``."""
    out = np.empty_like(points, dtype=np.float64)
    for i, (p, si) in enumerate(zip(points, s)):
        T = interpolate_pose(T_world_begin, T_world_end, float(si))
        out[i] = T[:3, :3] @ p + T[:3, 3]
    return out


def associate(
    points: np.ndarray,
    s: np.ndarray,
    T_world_begin,
    T_world_end,
    map_ref: VoxelMapReference,
    k: int,
    max_distance: float,
    min_neighbors: int,
    max_thickness: float,
) -> np.ndarray:
    """Plane of each source point: (N, 5) rows ``[nx, ny, nz, n . mu, a2D^2]`` (0 weight: none).

    The ``k`` nearest map points within ``max_distance`` of the deskewed point (brute force);
    with at least ``min_neighbors`` of them, the plane through their mean with the normal of the
    smallest eigenvalue of their covariance (``eigh``), the CT-ICP planarity ``a2D`` and a
    thickness gate ``sqrt(l0) <= max_thickness``. Normals are signed so that their largest
    component is positive (the kernel's sign is arbitrary; residuals and normal equations do not
    depend on it).
    """
    world = deskew(points, s, T_world_begin, T_world_end)
    map_points, flat = map_ref.points()
    ids, _ = knn_bruteforce(map_points, flat, world, k, max_distance)
    position = {f: i for i, f in enumerate(flat)}
    planes = np.zeros((len(points), 5))
    for i in range(len(points)):
        found = [position[f] for f in ids[i] if f >= 0]
        if len(found) < min_neighbors:
            continue
        nb = map_points[found]
        mu = nb.mean(axis=0)
        cov = (nb - mu).T @ (nb - mu) / len(found)
        lam, vec = np.linalg.eigh(cov)
        l0 = max(lam[0], 0.0)
        if lam[2] <= 0.0:
            continue
        a2d = (math.sqrt(max(lam[1], 0.0)) - math.sqrt(l0)) / math.sqrt(lam[2])
        if a2d <= 0.0 or l0 > max_thickness**2:
            continue
        n = vec[:, 0]
        n = n if n[np.argmax(np.abs(n))] > 0 else -n
        planes[i] = [n[0], n[1], n[2], n @ mu, a2d * a2d]
    return planes


def normal_equations(
    points: np.ndarray,
    s: np.ndarray,
    T_world_begin,
    T_world_end,
    planes: np.ndarray,
    robust_scale: float,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Point-to-plane normal equations over ``[v_b, w_b, v_e, w_e]`` (see :mod:`..kernels.ct_icp`).

    Returns ``H`` (12, 12), ``g`` (12,), the weighted cost and the number of residuals.
    """
    H = np.zeros((12, 12))
    g = np.zeros(12)
    cost, used = 0.0, 0
    for p, si, plane in zip(points, s, planes):
        if plane[4] <= 0.0:
            continue
        T = interpolate_pose(T_world_begin, T_world_end, float(si))
        q = T[:3, :3] @ p  # the point rotated into the world frame, before translation
        n = plane[:3]
        r = n @ (q + T[:3, 3]) - plane[3]
        w = plane[4] * (robust_scale**2 / (robust_scale**2 + r * r)) ** 2
        qxn = np.cross(q, n)
        J = np.concatenate([(1 - si) * n, (1 - si) * qxn, si * n, si * qxn])
        H += w * np.outer(J, J)
        g += w * J * r
        cost += w * r * r
        used += 1
    return H, g, cost, used


def select_points(
    points: np.ndarray,
    intensity: np.ndarray,
    times: np.ndarray | None,
    frame_rate: float,
    clockwise: bool,
    start_azimuth_deg: float,
    min_distance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, float]:
    """Finite rows at or beyond ``min_distance``, their intensity and normalised times.

    Times are the given ones or the azimuth times (clockwise or not, from
    ``start_azimuth_deg``, one turn per ``1 / frame_rate`` seconds); normalised over all finite
    rows. Returns ``(points, intensity, s, number of finite rows, duration)``.
    """
    ok = np.isfinite(points).all(axis=1) & np.isfinite(intensity)
    if times is not None:
        ok &= np.isfinite(times)
    p = points[ok]
    if times is None:
        azimuth = np.arctan2(p[:, 1], p[:, 0])
        start = np.radians(start_azimuth_deg)
        turned = start - azimuth if clockwise else azimuth - start
        fraction = np.mod(turned, 2 * np.pi) / (2 * np.pi)
        t = np.where(fraction >= 1.0, 0.0, fraction) / frame_rate
    else:
        t = times[ok]
    duration = float(t.max() - t.min()) if len(t) else 0.0
    s = (t - t.min()) / duration if duration > 0 else np.zeros(len(t))
    far = np.sum(p * p, axis=1) >= min_distance**2
    return p[far], intensity[ok][far], s[far], int(ok.sum()), duration
