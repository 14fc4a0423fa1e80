"""Joint-histogram kernels of the NID cost (paper Eq. 2-4), hard-binned and B-spline smoothed.

Both kernels take LiDAR points as coordinate rows ``xyz`` (3, N) with their intensity bins, the
camera (model id + flat params) and an image already quantised to bins, transform the points
with ``T_camera_lidar``, project them, and accumulate the joint histogram of (LiDAR bin, image
bin):

- :func:`joint_hist_hard`: each point falls on its nearest pixel (``floor(u + 0.5)``), integer
  counts (the paper's form, for Nelder-Mead), projecting blocks of points with a vectorised loop;
- :func:`_joint_hist_smooth`: each point spreads a unit of weight over the 4 x 4 pixels around it
  with uniform cubic B-spline weights (knots at pixel centres; border pixels clamped), and, on
  request, the derivative of every histogram cell with respect to a left se(3) perturbation
  ``T <- exp(delta) T``, ``delta = [v, omega]``, through the camera model's Jacobian.

A point counts when it projects validly inside the image (``-0.5 <= u < W - 0.5``, same for v).
Work is split into a fixed number of chunks with private histograms that are summed in chunk
order, so the result is the same whatever the number of threads, and the serial and parallel
builds of each kernel (compiled from one Python function) agree bit for bit. Each parallel kernel
is a single parallel region (nothing but the ``prange`` loop runs multithreaded; tested).

Public wrapper: :class:`nbcalib.registration.nid.NIDCost`; slow references:
:mod:`nbcalib.reference.nid`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_inline, jit_parallel
from nbcalib.kernels.projection import project_point, project_point_jacobian
from nbcalib.kernels.projection_batch import nearest_pixels

#: Chunks per call: enough to keep 2-8 threads busy; fixed so results do not depend on threads.
N_CHUNKS = 16

#: Points the hard kernel handles at once (their pixels, 16 KiB, stay in the L1 cache).
BLOCK = 4096


@jit_inline
def _chunk_bounds(n, n_chunks, c):
    """Points ``[lo, hi)`` of chunk ``c`` of ``n_chunks`` near-equal chunks of ``n`` points."""
    step = (n + n_chunks - 1) // n_chunks
    return min(n, c * step), min(n, (c + 1) * step)


@jit_inline
def _row_windows(point_bins, n, bins, rows, n_chunks):
    """Per chunk, the first histogram row its points use and how many (a window of rows).

    With one histogram (``rows == bins``) every chunk's window is all of it. With stacked
    histograms of groups (``rows = groups * bins``), each chunk needs only the groups its
    points fall in: a pass over the points' rows finds them (grouped points come sorted by
    group, so a chunk's window is a few groups). Returns ``(first, span, offset)`` per chunk,
    ``offset`` the start of the chunk's part in a flat buffer of ``offset[-1]`` rows.
    """
    # np.empty and loops, not np.zeros: in a parallel kernel an array expression is a parallel
    # loop of its own (see _joint_hist_hard_impl)
    first = np.empty(n_chunks, dtype=np.int64)
    span = np.empty(n_chunks, dtype=np.int64)
    offset = np.empty(n_chunks + 1, dtype=np.int64)
    offset[0] = 0
    for c in range(n_chunks):
        lo, hi = _chunk_bounds(n, n_chunks, c)
        first[c] = 0
        span[c] = 0
        if rows == bins:
            span[c] = bins
        elif hi > lo:
            g_lo = rows
            g_hi = 0
            for i in range(lo, hi):
                g = point_bins[i] // bins
                g_lo = min(g_lo, g)
                g_hi = max(g_hi, g)
            first[c] = g_lo * bins
            span[c] = (g_hi - g_lo + 1) * bins
        offset[c + 1] = offset[c] + span[c]
    return first, span, offset


def _joint_hist_hard_impl(
    model_id, params, T, xyz, point_bins, image_ext, width, height, bins, rows
):
    """Hard-binned joint histogram (int64, rows x bins) of the points' nearest pixels.

    ``point_bins`` holds each point's histogram *row*, in ``[0, rows)``: its LiDAR bin, or, for
    ``rows / bins`` stacked histograms of groups of points (:func:`grouped_rows`),
    ``group * bins + LiDAR bin``; ``bins`` is the number of image bins (the columns).

    ``image_ext`` is the row-major image of bins followed by one sentinel pixel of value
    ``bins`` (see :func:`padded_image_bins`). Each chunk handles its points ``BLOCK`` at a time:
    the vectorised :func:`~nbcalib.kernels.projection_batch.nearest_pixels` writes their pixels
    into a buffer that stays in the L1 cache, the points that miss the image pointing at the
    sentinel; then one branch-free loop counts each point in cell ``(a, image_ext[pixel])`` of a
    ``rows x (bins + 1)`` histogram, whose last column (the misses) is dropped at the end. The
    counts go to four interleaved private histograms, so that consecutive points in one cell do
    not wait for each other's increment. Measured on 1 M points against 1920 x 1080 (serial,
    benchmarks/bench_nid.py): 11 ms for a scalar projection loop, 4.3 ms with the vectorised
    one and a branching count loop, 3.1 ms like this. A chunk's private histograms hold only
    its window of rows (:func:`_row_windows`), so that hundreds of groups cost no more memory
    than their points touch.

    The whole call is one parallel region: nothing is a NumPy array expression outside the
    ``prange`` loop, since numba runs each as a parallel loop of its own, and waking the
    threads costs ~50 us each time with passive waiting (see :mod:`nbcalib.kernels._jit`).
    """
    n = xyz.shape[1]
    cols = bins + 1
    sentinel = width * height
    first, span, offset = _row_windows(point_bins, n, bins, rows, N_CHUNKS)
    parts = np.empty(offset[N_CHUNKS] * cols, dtype=np.int64)
    for c in prange(N_CHUNKS):
        r0 = first[c]
        stride = span[c] * cols
        counts = np.empty(4 * stride, dtype=np.int32)
        for k in range(4 * stride):
            counts[k] = 0
        pix = np.empty(BLOCK, dtype=np.int32)
        lo, hi = _chunk_bounds(n, N_CHUNKS, c)
        for s in range(lo, hi, BLOCK):
            e = min(s + BLOCK, hi)
            nearest_pixels(
                model_id,
                params,
                T,
                xyz[0, s:e],
                xyz[1, s:e],
                xyz[2, s:e],
                width,
                height,
                sentinel,
                pix,
            )
            row = point_bins[s:e]  # each point's histogram row (its LiDAR bin)
            m = e - s
            m4 = m - m % 4
            for j in range(0, m4, 4):
                counts[(row[j] - r0) * cols + image_ext[pix[j]]] += 1
                counts[stride + (row[j + 1] - r0) * cols + image_ext[pix[j + 1]]] += 1
                counts[2 * stride + (row[j + 2] - r0) * cols + image_ext[pix[j + 2]]] += 1
                counts[3 * stride + (row[j + 3] - r0) * cols + image_ext[pix[j + 3]]] += 1
            for j in range(m4, m):
                counts[(row[j] - r0) * cols + image_ext[pix[j]]] += 1
        base = offset[c] * cols
        for k in range(stride):
            parts[base + k] = counts[k] + counts[stride + k] + counts[2 * stride + k]
            parts[base + k] += counts[3 * stride + k]
    hist = np.empty((rows, bins), dtype=np.int64)
    for a in range(rows):
        for b in range(bins):
            hist[a, b] = 0
    for c in range(N_CHUNKS):
        base = offset[c] * cols
        for a in range(span[c]):
            for b in range(bins):
                hist[first[c] + a, b] += parts[base + a * cols + b]
    return hist


_joint_hist_hard = jit(_joint_hist_hard_impl)
_joint_hist_hard_parallel = jit_parallel(_joint_hist_hard_impl)


def padded_image_bins(image_bins, bins):
    """The image's bins (uint8, H x W) as one row-major array with a sentinel ``bins`` after it."""
    flat = np.empty(image_bins.size + 1, dtype=np.uint8)
    flat[:-1] = image_bins.reshape(-1)
    flat[-1] = bins
    return flat


def joint_hist_hard(
    model_id, params, T, xyz, point_bins, image_bins, bins, *, parallel, padded, groups=1
):
    """Hard-binned joint histogram (int64, ``groups * bins`` x bins) of points ``xyz`` (3, N).

    ``padded`` is :func:`padded_image_bins` of ``image_bins`` (kept by the caller between calls).
    With ``groups > 1`` the histogram is ``groups`` stacked ones: ``point_bins`` is then each
    point's row, ``group * bins + LiDAR bin`` (:func:`grouped_rows`).
    """
    kernel = _joint_hist_hard_parallel if parallel else _joint_hist_hard
    height, width = image_bins.shape
    return kernel(model_id, params, T, xyz, point_bins, padded, width, height, bins, groups * bins)


_SIXTH = 1.0 / 6.0


@jit
def _bspline(s):
    """Uniform cubic B-spline weights of the 4 knots around ``s`` in [0, 1) and derivatives."""
    t = 1.0 - s
    s2 = s * s
    s3 = s2 * s
    w0 = t * t * t * _SIXTH
    w1 = (3.0 * s3 - 6.0 * s2 + 4.0) * _SIXTH
    w2 = (-3.0 * s3 + 3.0 * s2 + 3.0 * s + 1.0) * _SIXTH
    w3 = s3 * _SIXTH
    d0 = -0.5 * t * t
    d1 = 1.5 * s2 - 2.0 * s
    d2 = -1.5 * s2 + s + 0.5
    d3 = 0.5 * s2
    return w0, w1, w2, w3, d0, d1, d2, d3


@jit
def _smooth_chunk(
    model_id,
    params,
    T,
    xyz,
    point_bins,
    image_bins,
    bins,
    lo,
    hi,
    r0,
    base,
    span,
    hist,
    dhist,
    want_grad,
    n_intr,
    center_step,
):
    """One chunk of :func:`_joint_hist_smooth_impl`: points ``[lo, hi)`` into its private rows.

    The chunk's rows are ``hist[base:base + span]`` (and ``dhist``'s), row ``base`` holding
    histogram row ``r0``; they are zeroed here. Returns the chunk's count of points in the
    image. A kernel of its own, not inlined: the serial and the parallel driver call the one
    compiled body (with the body compiled into it, the parallel driver took 8.7 s to compile
    on a first run; 2.5 s calling it; docs/BENCHMARKS.md 7).
    """
    height, width = image_bins.shape
    n_grad = 6 + n_intr
    for a in range(base, base + span):
        for b in range(bins):
            hist[a, b] = 0.0
            if want_grad:
                for k in range(n_grad):
                    dhist[a, b, k] = 0.0
    wu = np.empty(4)
    wv = np.empty(4)
    du = np.empty(4)
    dv = np.empty(4)
    cols = np.empty(4, dtype=np.int64)
    patch = np.empty(16, dtype=np.int64)
    m = np.empty((2, 6))
    count = 0
    for i in range(lo, hi):
        x = xyz[0, i]
        y = xyz[1, i]
        z = xyz[2, i]
        xc = T[0, 0] * x + T[0, 1] * y + T[0, 2] * z + T[0, 3]
        yc = T[1, 0] * x + T[1, 1] * y + T[1, 2] * z + T[1, 3]
        zc = T[2, 0] * x + T[2, 1] * y + T[2, 2] * z + T[2, 3]
        if want_grad:
            u, v, j00, j01, j02, j10, j11, j12, ok = project_point_jacobian(
                model_id, params, xc, yc, zc
            )
        else:  # value only: the inlined projection, no Jacobian (same pixels, tested)
            u, v, ok = project_point(model_id, params, xc, yc, zc)
            j00 = j01 = j02 = j10 = j11 = j12 = 0.0
        if not ok:
            continue
        if not (u >= -0.5 and u < width - 0.5 and v >= -0.5 and v < height - 0.5):
            continue
        count += 1
        ku = math.floor(u)
        kv = math.floor(v)
        for ju in range(4):
            cols[ju] = min(max(ku - 1 + ju, 0), width - 1)
        for jv in range(4):
            py = min(max(kv - 1 + jv, 0), height - 1)
            for ju in range(4):
                patch[4 * jv + ju] = image_bins[py, cols[ju]]
        differ = 0
        for j in range(1, 16):
            differ |= patch[j] ^ patch[0]
        a = point_bins[i] - r0 + base  # the point's row in its chunk's part
        if differ == 0:  # one bin under the whole patch: weight 1, derivative 0
            hist[a, patch[0]] += 1.0
            continue
        wu[0], wu[1], wu[2], wu[3], du[0], du[1], du[2], du[3] = _bspline(u - ku)
        wv[0], wv[1], wv[2], wv[3], dv[0], dv[1], dv[2], dv[3] = _bspline(v - kv)
        if want_grad:
            # d(u, v)/d delta = J_proj @ [I, -[p_c]x]  (left perturbation, delta = [v, w])
            m[0, 0] = j00
            m[0, 1] = j01
            m[0, 2] = j02
            m[0, 3] = -j01 * zc + j02 * yc
            m[0, 4] = j00 * zc - j02 * xc
            m[0, 5] = -j00 * yc + j01 * xc
            m[1, 0] = j10
            m[1, 1] = j11
            m[1, 2] = j12
            m[1, 3] = -j11 * zc + j12 * yc
            m[1, 4] = j10 * zc - j12 * xc
            m[1, 5] = -j10 * yc + j11 * xc
        for jv in range(4):
            for ju in range(4):
                b = patch[4 * jv + ju]
                hist[a, b] += wu[ju] * wv[jv]
                if want_grad:
                    gu = du[ju] * wv[jv]
                    gv = wu[ju] * dv[jv]
                    for k in range(6):
                        dhist[a, b, k] += gu * m[0, k] + gv * m[1, k]
                    if n_intr > 0:  # u = fx e^lambda mx + cx: du/dlambda = u - cx
                        dhist[a, b, 6] += gu * (u - params[2]) + gv * (v - params[3])
                    if n_intr > 1:  # the principal point, in full-resolution pixels
                        dhist[a, b, 7] += gu * center_step
                        dhist[a, b, 8] += gv * center_step
    return count


def _joint_hist_smooth_impl(
    model_id,
    params,
    T,
    xyz,
    point_bins,
    image_bins,
    bins,
    rows,
    n_chunks,
    want_grad,
    n_intr,
    center_step,
):
    """B-spline joint histogram (rows x bins), its derivative (rows x bins x 6 + n_intr), count.

    The derivative's first six columns are with respect to the pose (``delta = [v, omega]``);
    ``n_intr`` more (0, 1 or 3) with respect to the camera's intrinsics (issue 47): column 6 to
    ``lambda``, the log of a common scale of ``fx`` and ``fy`` (``du/dlambda = u - cx``, exact
    for every model with a focal length, :meth:`nbcalib.camera.CameraModel.
    intrinsics_jacobian`); columns 7 and 8 to ``cx`` and ``cy`` in pixels of the full
    resolution, of which one moves a pixel of this pyramid level by ``center_step``
    (``2^-level``).

    ``point_bins`` holds each point's histogram row in ``[0, rows)``: its LiDAR bin (``rows =
    bins``), or ``group * bins + LiDAR bin`` for ``rows / bins`` stacked histograms of groups
    of points (:func:`grouped_rows`); ``bins`` is the number of image bins (the columns).

    Per point (:func:`_smooth_chunk`, one chunk of points at a time), the image bins of the
    4 x 4 patch are gathered first. When they are all equal (30-55 % of the points on equalised
    real images, 1-4 % on noisy synthetic ones), the point adds exactly its total weight, 1, to
    one cell and nothing to the derivative: the weights sum to 1 at every position, so their
    derivatives sum to 0, and the B-spline weights, the derivative terms and the 16 x 7
    histogram updates are skipped (1.15-1.25 x faster on a real image, the same speed on noisy
    ones). Otherwise each pixel adds its weight and derivative terms to its cell. Tried and
    dropped: summing the terms over runs of equal bins, or over the patch's bin range, before
    updating the cells; 10-25 % slower on the noisy benchmark image and on synthetic renders,
    where branch mispredictions cost more than the saved updates. The count of points in the
    image is kept per chunk (one write per chunk, no false sharing between threads). Each
    chunk's private histogram holds only its window of rows (:func:`_row_windows`): with
    hundreds of groups, what its points touch.
    """
    n = xyz.shape[1]
    first, span, offset = _row_windows(point_bins, n, bins, rows, n_chunks)
    total_rows = offset[n_chunks]
    # per-chunk histograms in flat buffers, zeroed by their own chunk: np.zeros here would be a
    # parallel loop of its own (see _joint_hist_hard_impl)
    n_grad = 6 + n_intr
    hist = np.empty((total_rows, bins))
    dhist = np.empty((total_rows if want_grad else 1, bins, n_grad))
    counts = np.empty(n_chunks, dtype=np.int64)
    for c in prange(n_chunks):
        lo, hi = _chunk_bounds(n, n_chunks, c)
        counts[c] = _smooth_chunk(
            model_id,
            params,
            T,
            xyz,
            point_bins,
            image_bins,
            bins,
            lo,
            hi,
            first[c],
            offset[c],
            span[c],
            hist,
            dhist,
            want_grad,
            n_intr,
            center_step,
        )
    # the chunks' parts summed in chunk order (the same sums, in the same order, for every
    # number of threads)
    out = np.empty((rows, bins))
    dout = np.empty((rows, bins, n_grad))
    for a in range(rows):
        for b in range(bins):
            out[a, b] = 0.0
            for k in range(n_grad):
                dout[a, b, k] = 0.0
    for c in range(n_chunks):
        for a in range(span[c]):
            src = offset[c] + a
            dst = first[c] + a
            for b in range(bins):
                out[dst, b] += hist[src, b]
                if want_grad:
                    for k in range(n_grad):
                        dout[dst, b, k] += dhist[src, b, k]
    n_in = 0
    for c in range(n_chunks):
        n_in += counts[c]
    return out, dout, n_in


_joint_hist_smooth = jit(_joint_hist_smooth_impl)
_joint_hist_smooth_parallel = jit_parallel(_joint_hist_smooth_impl)


@jit
def _nid_from_hist(hist, dhist, want_grad):
    """NID of a joint histogram (rows: LiDAR bins, columns: image bins) and its gradient.

    ``NID = (H_joint - MI) / H_joint = (2 H_joint - H_lidar - H_image) / H_joint`` with natural-log
    entropies of the normalised histograms (empty cells contribute 0). The gradient is
    ``sum_ab dNID/dp_ab * dp_ab/d delta`` with ``dhist`` the derivative of the unnormalised
    histogram; the normalisation (number of points in the image) is held fixed. Returns
    ``(nid, grad (K,))``, ``K = dhist.shape[2]`` (6 pose columns and any intrinsics'); NID
    is 1 (no shared information) when the histogram is empty or has a
    single occupied cell.
    """
    bins_l, bins_i = hist.shape
    total = hist.sum()
    n_grad = dhist.shape[2]
    grad = np.zeros(n_grad)
    if total <= 0.0:
        return 1.0, grad
    row = np.zeros(bins_l)
    col = np.zeros(bins_i)
    for a in range(bins_l):
        for b in range(bins_i):
            row[a] += hist[a, b]
            col[b] += hist[a, b]
    h_joint = 0.0
    h_lidar = 0.0
    h_image = 0.0
    for a in range(bins_l):
        for b in range(bins_i):
            p = hist[a, b] / total
            if p > 0.0:
                h_joint -= p * math.log(p)
    for a in range(bins_l):
        p = row[a] / total
        if p > 0.0:
            h_lidar -= p * math.log(p)
    for b in range(bins_i):
        p = col[b] / total
        if p > 0.0:
            h_image -= p * math.log(p)
    if h_joint <= 0.0:
        return 1.0, grad
    nid = (2.0 * h_joint - h_lidar - h_image) / h_joint
    if want_grad:
        s = 2.0 * h_joint - h_lidar - h_image
        for a in range(bins_l):
            pa = row[a] / total
            la = math.log(pa) + 1.0 if pa > 0.0 else 0.0
            for b in range(bins_i):
                p = hist[a, b] / total
                if p <= 0.0:
                    continue
                dhj = -(math.log(p) + 1.0)
                dhi = -(math.log(col[b] / total) + 1.0)
                dhl = -la
                coef = ((2.0 * dhj - dhl - dhi) * h_joint - s * dhj) / (h_joint * h_joint)
                for k in range(n_grad):
                    grad[k] += coef * dhist[a, b, k] / total
    return nid, grad


@jit
def _quantise(values, bins):
    """Bin index ``min(int(v * bins), bins - 1)`` of values in [0, 1] (clamped), as uint8."""
    flat = values.ravel()
    out = np.empty(flat.shape[0], dtype=np.uint8)
    for i in range(flat.shape[0]):
        v = flat[i]
        k = int(v * bins) if v > 0.0 else 0
        if k > bins - 1:
            k = bins - 1
        out[i] = k
    return out.reshape(values.shape)


@jit
def _grouped_nid(hist, dhist, bins, weights, want_grad):
    """Weighted sum of the NIDs of ``weights.size`` stacked histograms, and its gradient.

    ``hist`` (groups * bins, bins) and ``dhist`` (groups * bins, bins, K) are the stacked
    histograms of :func:`_joint_hist_smooth_impl` (``dhist`` may have one row when
    ``want_grad`` is False); group ``g`` is rows ``[g * bins, (g + 1) * bins)``, its NID that of
    :func:`_nid_from_hist`.
    """
    value = 0.0
    n_grad = dhist.shape[2]
    grad = np.zeros(n_grad)
    empty = np.zeros((bins, bins, n_grad))
    for g in range(weights.size):
        h = hist[g * bins : (g + 1) * bins]
        d = dhist[g * bins : (g + 1) * bins] if want_grad else empty
        v, gg = _nid_from_hist(h, d, want_grad)
        value += weights[g] * v
        if want_grad:
            for k in range(n_grad):
                grad[k] += weights[g] * gg[k]
    return value, grad


@jit
def _each_group_nid(hist, dhist, bins, n_groups, want_grad):
    """Each group's own NID (G,) and gradient (G, 6) from stacked histograms, unweighted.

    The terms that :func:`_grouped_nid` sums: group ``g`` is rows ``[g * bins, (g + 1) *
    bins)`` of ``hist`` (and of ``dhist`` when ``want_grad``), its NID that of
    :func:`_nid_from_hist`.
    """
    values = np.empty(n_groups)
    n_grad = dhist.shape[2]
    grads = np.zeros((n_groups, n_grad))
    empty = np.zeros((bins, bins, n_grad))
    for g in range(n_groups):
        h = hist[g * bins : (g + 1) * bins]
        d = dhist[g * bins : (g + 1) * bins] if want_grad else empty
        v, gg = _nid_from_hist(h, d, want_grad)
        values[g] = v
        if want_grad:
            for k in range(n_grad):
                grads[g, k] = gg[k]
    return values, grads


def grouped_rows(groups, point_bins, bins):
    """Histogram row of each point of a grouped histogram: ``group * bins + LiDAR bin`` (int32)."""
    return (np.asarray(groups, dtype=np.int32) * np.int32(bins) + point_bins).astype(np.int32)
