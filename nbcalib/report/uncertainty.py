"""The numbers behind a calibration's uncertainty: Hessians, curves, jackknife, restarts.

The pieces :func:`nbcalib.report.quality.assess` and :func:`~nbcalib.report.quality.rejudge`
assemble (their module docstring tells what each part of the uncertainty holds): each pair's
Hessian from central differences of its exact gradient, its flat directions measured again
from the NID values, the delete-a-block jackknife over image regions, the NID curves along the
six axes, the restarts of fine registration around a result, and the confidence bounds.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.metrics import interval_quantiles
from nbcalib.registration.costs import point_budget
from nbcalib.registration.costs.regional import median_cut_regions
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine, visible_subset
from nbcalib.report.config import AssessConfig
from nbcalib.transforms import invert_T, offset_pose, se3_exp, se3_log

__all__ = ["AXIS_NAMES", "RESTART_SEED", "SAME_VIEW", "leave_one_out", "restart_starts", "views"]

#: Names of the six tangent axes, in the order of ``delta = [v, omega]`` (camera axes).
AXIS_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")


def _pixels_covered(pair: RegistrationPair, T: np.ndarray, config: RefineConfig) -> int:
    """Distinct pixels ``floor(uv + 0.5)`` hit by the pair's visible points.

    With hidden-point removal the z-buffer's own pixels (the pair keeps them for its last
    poses): no projection and no sort of the visible points again (0.6 s a Livox pair).
    """
    width, height = pair.camera.width, pair.camera.height
    if config.hidden_point_removal:
        _, pixel = pair.visibility(T, config.depth_margin, config.window)
        hit = np.zeros(width * height, dtype=bool)
        hit[pixel] = True
        return int(np.count_nonzero(hit))
    keep = visible_subset(pair, T, config)
    if keep.size == 0:
        return 0
    points = pair.rows(keep)[0]
    uv, valid = pair.camera.project(points @ T[:3, :3].T + T[:3, 3], in_image=True)
    pix = np.floor(uv[valid] + 0.5).astype(np.int64)
    hit = np.zeros(pair.camera.width * pair.camera.height, dtype=bool)  # O(N), not a sort
    hit[pix[:, 1] * pair.camera.width + pix[:, 0]] = True
    return int(np.count_nonzero(hit))


#: Seed of the restarts' directions: the same result is always judged from the same starts.
RESTART_SEED = 29


def restart_starts(T_camera_lidar: np.ndarray, count: int, distance: float, angle_deg: float):
    """``count`` starts around a pose ``T_camera_lidar`` (seeded: always the same ones).

    Each is turned by exactly ``angle_deg`` about a random axis and its camera centre moved by
    exactly ``distance`` metres in a random direction.
    """
    rng = np.random.default_rng(RESTART_SEED)
    return [offset_pose(T_camera_lidar, angle_deg, distance, rng) for _ in range(count)]


def _restart_offsets(pairs, T: np.ndarray, config: RefineConfig, acfg: AssessConfig, step):
    """Where fine registration ends from :func:`restart_starts` around the result ``T``.

    Returns ``delta`` (R, 6) per restart, with ``exp(delta) @ T`` its end.
    On a synthetic pair the restarts come back to within 0.3 cm / 0.01 deg; on real pairs the
    single shot's cost has several shallow minima within a degree and the ends scatter by
    centimetres and tenths of a degree (docs/BENCHMARKS.md 11), a spread that neither the
    curvature nor the image regions' jackknife sees.
    """
    starts = restart_starts(T, acfg.restarts, acfg.restart_translation, acfg.restart_rotation_deg)
    if acfg.restart_points is not None:  # at most restart_points per pair
        camera = max((p.camera for p in pairs), key=lambda c: c.width * c.height)
        pixels = camera.width * camera.height
        budget = acfg.restart_points
        own = point_budget(camera, config, len(pairs))
        budget = budget if own is None else min(budget, own)
        config = replace(config, points_per_pixel=budget / pixels, min_sampled_points=budget)
    out = np.empty((len(starts), 6))
    for k, T0 in enumerate(starts):
        out[k] = se3_log(refine(pairs, T0, config).T_camera_lidar @ invert_T(T))
        step(f"restart {k + 1} of {len(starts)}")
    return out


def _hessian(cost, T: np.ndarray, steps: np.ndarray, blocks=None) -> np.ndarray:
    """Symmetric Hessian (6, 6) w.r.t. ``delta`` by central differences of gradients.

    ``cost``: the terms measured here (None: none); ``blocks`` (B, 6, 6): Hessians of the other
    terms' parts (:func:`_block_material`, the same steps), added without evaluating them again.
    """
    H = np.zeros((6, 6)) if blocks is None else np.sum(blocks, axis=0)
    for j in range(6 if cost is not None else 0):
        d = np.zeros(6)
        d[j] = steps[j]
        _, g_plus = cost.value_and_grad(se3_exp(d) @ T)
        _, g_minus = cost.value_and_grad(se3_exp(-d) @ T)
        H[:, j] += (g_plus - g_minus) / (2.0 * steps[j])
    return 0.5 * (H + H.T)


def _block_material(grouped, T: np.ndarray, steps: np.ndarray, n_blocks: int):
    """Gradients (B, 6) and Hessians (B, 6, 6) of blocks of neighbouring image regions.

    ``grouped``: the pair's ``(GroupedNIDCost, weight)`` terms. Each region's weighted gradient
    at ``T`` and its Hessian by central differences of those gradients (the same steps as
    :func:`_hessian`, 13 evaluations in all); the regions are then joined into about
    ``n_blocks`` blocks by median cuts of their pixel centroids
    (:func:`~nbcalib.registration.costs.regional.median_cut_regions`: neighbours together,
    since what biases a region biases its neighbours too).
    """
    weights, grads, centroids = [], [], []
    hess = []
    for term, w in grouped:
        _, g0 = term.each_group(T)
        H = np.empty((term.n_groups, 6, 6))
        for j in range(6):
            d = np.zeros(6)
            d[j] = steps[j]
            _, g_plus = term.each_group(se3_exp(d) @ T)
            _, g_minus = term.each_group(se3_exp(-d) @ T)
            H[:, :, j] = (g_plus - g_minus) / (2.0 * steps[j])
        weights.append(w * term.weights)
        grads.append(g0)
        hess.append(H)
        uv, valid = term.camera.project(term.points @ T[:3, :3].T + T[:3, 3])
        ok = valid & np.isfinite(uv).all(axis=1)
        group = term.group_of_point[ok]
        n = np.maximum(np.bincount(group, minlength=term.n_groups), 1)
        centroids.append(
            np.column_stack(
                [np.bincount(group, uv[ok, c], minlength=term.n_groups) / n for c in (0, 1)]
            )
        )
    weights, grads = np.concatenate(weights), np.concatenate(grads)
    hess, centroids = np.concatenate(hess), np.concatenate(centroids)
    n_regions = len(weights)
    per_block = max(1, -(-n_regions // max(n_blocks, 1)))  # ceil: about n_blocks blocks
    block = median_cut_regions(centroids, per_block) if n_blocks > 1 else np.zeros(n_regions, int)
    n = int(block.max()) + 1
    g_b = np.zeros((n, 6))
    h_b = np.zeros((n, 6, 6))
    np.add.at(g_b, block, weights[:, None] * grads)
    np.add.at(h_b, block, weights[:, None, None] * hess)
    return g_b, 0.5 * (h_b + h_b.transpose(0, 2, 1))


def _remeasure_flat_directions(
    cost, T: np.ndarray, H: np.ndarray, steps: np.ndarray, value: float, max_scale: int
) -> tuple[np.ndarray, int]:
    """``H`` with each non-positive eigenvalue replaced by the NID's own rise along it.

    Along a unit eigenvector ``d`` of ``H`` with eigenvalue ``<= 0``, the second difference
    ``(f(m u) + f(-m u) - 2 f(0)) / (m^2 |u|^2)`` of the cost values is taken for ``m = 1, 2, 4,
    ... <= max_scale``, ``u = d`` scaled to one Hessian step (``|d / steps| = 1``); the first
    positive one becomes the eigenvalue. Where none is positive the eigenvalue stays (a flat
    direction). Returns the new symmetric matrix and how many directions were measured again.
    """
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    if max_scale < 1 or np.all(w > 0.0):
        return H, 0
    n_again = 0
    for j in np.flatnonzero(w <= 0.0):
        n_again += 1
        u = V[:, j] / np.linalg.norm(V[:, j] / steps)
        m = 1
        while m <= max_scale:
            rise = cost.value(se3_exp(m * u) @ T) + cost.value(se3_exp(-m * u) @ T) - 2.0 * value
            curvature = rise / (m * m * float(u @ u))
            if curvature > 0.0:
                w[j] = curvature
                break
            m *= 2
    return (V * w) @ V.T, n_again


def _curves(costs, T: np.ndarray, config: AssessConfig, step) -> tuple[np.ndarray, np.ndarray]:
    """Summed NID along each axis; offsets (6, S) in m / rad, values (6, S).

    ``step(what)`` is called after each axis.
    """
    s = np.linspace(-1.0, 1.0, config.curve_samples)
    spans = [config.curve_translation] * 3 + [math.radians(config.curve_rotation_deg)] * 3
    offsets = np.array([span * s for span in spans])
    values = np.empty_like(offsets)
    for axis in range(6):
        poses = []
        for offset in offsets[axis]:
            d = np.zeros(6)
            d[axis] = offset
            poses.append(se3_exp(d) @ T)
        # each pair's whole curve on its own thread (one pool an axis), summed in pair order
        per_pair = thread_map(lambda c, poses=poses: [c.value(Td) for Td in poses], costs)
        for i in range(len(poses)):
            values[axis, i] = sum(curve[i] for curve in per_pair)
        step(f"NID curve {AXIS_NAMES[axis]}")
    return offsets, values


def _inverse_psd(H: np.ndarray) -> tuple[np.ndarray, int]:
    """Inverse of a symmetric matrix with eigenvalues floored; also the count of non-positive.

    A direction of zero or negative curvature gets the floor ``1e-9 * max(|eig|)`` (a huge but
    finite variance), so that a flat cost shows up as a large uncertainty.
    """
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    top = float(np.max(np.abs(w))) if w.size else 0.0
    floor = max(top * 1e-9, 1e-300)
    n_negative = int(np.sum(w <= 0.0))
    w = np.maximum(w, floor)
    return (V / w) @ V.T, n_negative


def _newton_inverse(H: np.ndarray, rcond: float = 1e-3) -> np.ndarray:
    """Pseudo-inverse of a symmetric matrix over its eigenvalues above ``rcond * max``.

    Non-positive and nearly flat directions get no step at all (unlike :func:`_inverse_psd`,
    which gives them a huge variance).
    """
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    top = float(np.max(w)) if w.size else 0.0
    if top <= 0.0:
        return np.zeros_like(H)
    inv_w = np.where(w > rcond * top, 1.0 / np.where(w > 0, w, 1.0), 0.0)
    return (V * inv_w) @ V.T


def _jackknife(block_gradients, block_hessians, spans) -> np.ndarray | None:
    """Delete-a-block jackknife covariance (6, 6) of the cost's minimum; None under 3 blocks.

    The cost is the sum of the blocks' terms; without block ``b`` its minimum lies one Newton
    step ``-(H - H_b)^+ (g - g_b)`` from the result (``g``, ``H``: the sums; ``^+`` over
    directions of clear curvature, :func:`_newton_inverse`; each step clipped to ``spans``,
    the range the curves examine). The covariance is ``(B - 1) / B`` times the steps' summed
    outer products about their mean (Efron and Stein): how far the minimum moves when a part
    of the image is left out, which is what a bias that changes over the image does to it.
    """
    B = len(block_gradients)
    if B < 3:
        return None
    g, H = block_gradients.sum(axis=0), block_hessians.sum(axis=0)
    steps = np.empty((B, 6))
    for b in range(B):
        step = -(_newton_inverse(H - block_hessians[b]) @ (g - block_gradients[b]))
        steps[b] = np.clip(step, -spans, spans)
    d = steps - steps.mean(axis=0)
    return (B - 1) / B * (d.T @ d)


def _uncertainty(covariance: np.ndarray, confidence: float) -> dict:
    half, t_bound, r_bound = interval_quantiles(covariance, confidence)
    return {
        "confidence": confidence,
        "translation_cm": [100.0 * float(x) for x in half[:3]],
        "rotation_deg": [math.degrees(float(x)) for x in half[3:]],
        "translation_total_cm": 100.0 * t_bound,
        "rotation_total_deg": math.degrees(r_bound),
        "axes": "camera axes: x right, y down, z forward",
    }


#: Two images whose standardised 64-pixel-wide thumbnails correlate this much show one scene; so
#: do images linked by a chain of such pairs. Measured: the ACFR poses (a parked car) correlate
#: 0.94-1.00; KITTI raw frames at walking pace 0.95-0.98 with their neighbours (0.57 first to
#: last: one scene seen a little further on at each frame), 0.86-0.96 every other frame;
#: KITTI odometry and Waymo frames of other streets, and synthetic pairs of a room or a street
#: from other rig poses, 0.68 at most. At 0.9, ten KITTI raw frames (every other one) fell into
#: three views, were judged by their agreement, and a result 24 cm / 2.5 deg off was called ok.
SAME_VIEW = 0.8


def _thumbnail(image: np.ndarray, width: int = 64) -> np.ndarray:
    import cv2

    image = np.asarray(image, dtype=np.float32)
    height = max(8, round(width * image.shape[0] / image.shape[1]))
    small = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA).ravel()
    return (small - small.mean()) / (small.std() + 1e-6)


def views(images) -> np.ndarray:
    """A label per image: images of one scene share it (:data:`SAME_VIEW`).

    Two images show one scene when their thumbnails correlate at least :data:`SAME_VIEW`, or
    when a chain of such images links them (single linkage): the frames of a camera that did
    not move, and the frames of a slow drive past one scene, whose neighbours are alike though
    its ends are not. Frames of one scene share the scene's bias, so they are one shot's
    evidence, however many.

    Parameters
    ----------
    images : sequence of ndarray of shape (H, W)
        The pairs' grey camera images.

    Returns
    -------
    ndarray of shape (K,), int64
        Scene labels 0, 1, ... in order of first appearance.
    """
    thumbs = [_thumbnail(im) for im in images]
    parent = list(range(len(thumbs)))

    def root(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i in range(len(thumbs)):
        for j in range(i + 1, len(thumbs)):
            a, b = thumbs[i], thumbs[j]
            if a.shape == b.shape and float(a @ b) / a.size >= SAME_VIEW:
                parent[root(j)] = root(i)
    labels, first = [], {}
    for k in range(len(thumbs)):
        labels.append(first.setdefault(root(k), len(first)))
    return np.asarray(labels, dtype=np.int64)


def leave_one_out(pair_gradients, pair_hessians, spans) -> np.ndarray:
    """Where the joint minimum moves with each pair left out: one Newton step per pair.

    The summed cost's gradient and Hessian at the result less the pair's own, a Newton step
    along the directions of clear positive curvature (:func:`_newton_inverse`), clipped to
    ``spans`` (the range the curves examine).

    Returns
    -------
    ndarray of shape (K, 6)
        ``delta = [v, omega]`` of each pair's leave-one-out minimum from the result (m, rad).
    """
    g = np.asarray(pair_gradients, dtype=np.float64)
    H = np.asarray(pair_hessians, dtype=np.float64)
    g_all, H_all = g.sum(axis=0), H.sum(axis=0)
    out = np.empty((len(g), 6))
    for k in range(len(g)):
        step = -(_newton_inverse(H_all - H[k]) @ (g_all - g[k]))
        out[k] = np.clip(step, -spans, spans)
    return out
