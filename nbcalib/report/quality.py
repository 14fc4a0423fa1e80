"""Quality of a calibration: cost landscapes, uncertainty and a verdict, numbers only.

:func:`assess` looks at the summed NID cost (:func:`nbcalib.registration.costs.build_cost`, the
smooth B-spline form whatever optimiser produced the result) around a result ``T_camera_lidar``:

**Curves.** The NID along each of the six tangent axes ``delta = [v, omega]`` of the left
perturbation ``exp(delta) @ T_camera_lidar`` (docs/conventions.md section 3), with the visible
points fixed at the result. ``v`` is the displacement of the camera centre expressed in camera
axes (x right, y down, z forward; its norm is the translation error of
:func:`nbcalib.metrics.pose_errors`), ``omega`` a rotation about the camera axes.

**Uncertainty: curvature of the cost, scaled.** NID is not a likelihood, but a histogram
log-likelihood of the image given the LiDAR intensities changes like ``N x NID`` for ``N``
independent samples (mutual information times ``N`` is a log-likelihood ratio). Points that fall
into one pixel see one image value and are not independent, so each pair counts ``N_k`` =
*distinct pixels hit by its visible points*. The Fisher information is then
``sum_k N_k H_k / scale``, ``H_k`` the Hessian of pair ``k``'s NID (central differences of its
exact gradient), and the covariance its inverse. An eigen-direction of ``H_k`` without positive
curvature is measured again from the NID values themselves (second differences along it at 1, 2,
4, ... ``max_curvature_scale`` Hessian steps, the first positive one is kept): at a converged
result the gradient differences of a weak direction are within the cost's sub-pixel roughness
(demo-sized synthetic pairs, 3 of 20 single-pair results 1.3-3.3 cm off had one such direction,
whose NID nonetheless rose at 5 mm to 1 cm), and only a direction along which the NID does not
rise at any of these scales is flat. ``scale`` (:attr:`AssessConfig.scale`) absorbs
what the model leaves out: the joint entropy's units, image blur and spatial correlation, and the
bias of the synthetic-to-real gap; it was tuned on synthetic pairs with known truth
(benchmarks/bench_report_coverage.py, half the pairs to tune, half to check). With two or more
pairs, the spread of each pair's own optimum (one Newton step ``-H_k^-1 g_k`` from the joint
result, clipped to the curves' range) is added as the covariance of the mean, so disagreeing
pairs widen the interval. The
curvature is used rather than a bootstrap because it costs a dozen gradient evaluations per pair,
where a bootstrap refits the pose tens of times.

**Uncertainty: what curvature cannot see.** A bias that changes over the image (the camera's
shading against the LiDAR's falloff) moves the minimum without flattening the cost. The regional
cost is a sum of one NID per image region, so the same dozen evaluations give every region's
gradient and Hessian; the regions are joined into about ``jackknife_blocks`` blocks of
neighbouring regions (median cuts of their pixel centroids) and the delete-a-block jackknife
(:func:`_jackknife`: one Newton step to the minimum without each block, ``(B - 1) / B`` times
the steps' scatter) is added to the covariance, times ``jackknife_scale``. It holds the pairs'
spread too, so it replaces the per-pair term when there are blocks. Pairs disagree when a pair's
own optimum lies farther from the other pairs' than its and their uncertainties and the bias of
a single shot allow (:func:`pairs_elsewhere`: the bias from a floor, or from the other pairs'
spread when there are three or more), a false-alarm rate that does not grow with ``K``.

**Uncertainty: where registration ends from elsewhere.** A real single shot's cost has shallow
minima within a degree of each other; which one fine registration finds depends on its start,
and neither the curvature nor the jackknife at the result sees the others. Fine registration is
run again, for a single pair, from :attr:`AssessConfig.restarts` starts around the result
(:func:`restart_starts`: turned by exactly ``restart_rotation_deg``, moved by exactly
``restart_translation``, seeded directions; each scores at most ``restart_points`` of the
pair's points when set); ``restart_scale`` times the mean outer product of
where they end (:attr:`Quality.restart_offsets`) joins the covariance, and a median end farther
than ``max_restart_rotation_deg`` in rotation makes the result suspect. Synthetic pairs'
restarts come back to within 0.3 cm / 0.01 deg; real ones end centimetres and tenths of a degree
away. With
two or more pairs there are no restarts: the pairs' own spread (the jackknife over their regions,
the pair test) measures the bias of a shot, and restarting many pairs would cost minutes.

**Move from the start.** Fine registration may not leave its trust region around the start
(:attr:`RefineConfig.trust_translation <nbcalib.registration.config.RefineConfig>`,
``trust_rotation_deg``); a result on the region's edge may have been stopped there short of its
optimum. And a result should not move from its start further than the two stated uncertainties
allow: if the start is within ``s`` of the truth and the result within ``u`` (both bounds at
:attr:`AssessConfig.confidence`), the move is at most ``sqrt(s^2 + u^2)`` (exact for independent,
isotropic Gaussian errors, whose difference is Gaussian with the summed variance), separately
for the camera centre (metres) and the rotation (degrees). ``u`` is the result's total
uncertainty (``translation_total_cm``, ``rotation_total_deg``); ``s`` the start's stated one
(``--init-uncertainty``, :attr:`nbcalib.products.Start.uncertainty`), or, when none is stated,
the trust region itself: the automatic initial guess states none (its reprojection fit says
nothing of how far its matches are off), so a result outside the trust region is the only move
it calls too far.

**Verdict.** ``"ok"`` unless one of these holds (each adds a one-line reason): too few points in
view; a flat cost (an uncertainty above the limits, or a cost that hardly rises along an axis);
a curve whose lowest sample lies clearly away from the result (not at a minimum); a result far
from the initial guess; a result on the edge of the trust region; a move from the start beyond
what the start's and the result's uncertainties allow; pairs that disagree; an optimiser that
did not converge; an NID so high that image and LiDAR share almost no information; restarts
around the result that end elsewhere (it depends on the start). Each kind of
reason comes with a line of what to do next (:data:`ADVICE`, :attr:`Quality.next_steps`).

Example
-------
>>> quality = assess(pairs, result.T_camera_lidar, T_init=T_init)       # doctest: +SKIP
>>> quality.verdict, quality.reasons, quality.uncertainty["translation_total_cm"]  # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.metrics import interval_quantiles
from nbcalib.progress import Progress
from nbcalib.registration.nid import GroupedNIDCost, MultiNIDCost
from nbcalib.registration.refine import RefineConfig, RegistrationPair, build_cost
from nbcalib.report.assessment import Quality, load_quality
from nbcalib.report.config import AssessConfig
from nbcalib.report.uncertainty import (
    AXIS_NAMES,
    _block_material,
    _curves,
    _hessian,
    _inverse_psd,
    _jackknife,
    _newton_inverse,
    _pixels_covered,
    _remeasure_flat_directions,
    _restart_offsets,
    _uncertainty,
    leave_one_out,
    views,
)
from nbcalib.report.verdict import (
    _move_allowed,
    advice,
    format_bound,
    pairs_elsewhere,
    reasons,
)
from nbcalib.transforms import invert_T, pose_error, validate_T

__all__ = [
    "AXIS_NAMES",
    "AssessConfig",
    "Quality",
    "assess",
    "format_bound",
    "interval_quantiles",
    "load_quality",
    "rejudge",
]


#: Points of one NID term from which the report uses the parallel kernels.
PARALLEL_MIN_POINTS = 100_000


def assess(
    pairs: Sequence[RegistrationPair],
    T_camera_lidar,
    *,
    T_init=None,
    config: RefineConfig | None = None,
    converged: bool | None = None,
    assess_config: AssessConfig | None = None,
    start_uncertainty: tuple[float, float] | None = None,
    progress: bool | Callable[[str], None] | None = None,
) -> Quality:
    """Judge a calibration result: NID curves, uncertainty, verdict (module docstring).

    Parameters
    ----------
    pairs : sequence of RegistrationPair
        The LiDAR-camera pairs the result was computed from.
    T_camera_lidar : array_like of shape (4, 4)
        The result, ``p_camera = T_camera_lidar @ p_lidar``.
    T_init : array_like of shape (4, 4), optional
        The initial guess the optimiser started from.
    config : RefineConfig, optional
        The refinement settings (bins, hidden-point removal, the trust region around
        ``T_init``); the smooth NID is used whatever the optimiser.
    converged : bool, optional
        Whether the optimiser converged (``RefineResult.converged``); False adds a reason.
    assess_config : AssessConfig, optional
        Ranges, steps, scale and verdict limits.
    start_uncertainty : tuple of 2 floats, optional
        How far ``T_init`` may be from the truth, metres and degrees, at the report's
        confidence (default: not stated, the trust region stands in; module docstring).
    progress : bool or callable, optional
        ``True`` for a progress display (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or a
        callback called with a short text after each step (a pair, an NID curve).

    Returns
    -------
    Quality
    """
    if not pairs:
        raise ValueError("assess needs at least one LiDAR-camera pair")
    acfg = assess_config or AssessConfig()
    # the smooth form has a gradient. assess makes ~150 evaluations per pair: serial kernels
    # for a few thousand points, where threads cost more CPU than they save
    # (bench_report_coverage on a loaded 2-core machine: 0.4 s CPU per case serial, 0.8-6.3 s
    # with the parallel kernels); the parallel ones from PARALLEL_MIN_POINTS on (a dense cloud
    # puts a million and more in view)
    # the pose is judged with the camera the result goes with (the pairs'): restarts and the
    # cost refine and measure the pose alone, whatever refined the intrinsics before
    config = replace(config or RefineConfig(), intrinsics=None)
    rcfg = replace(config, optimizer="lbfgs")
    if start_uncertainty is not None:
        from nbcalib.products import check_uncertainty

        start_uncertainty = check_uncertainty(start_uncertainty, "the start")
    T = validate_T(np.asarray(T_camera_lidar, dtype=np.float64), "T_camera_lidar")
    steps = np.array([acfg.hessian_translation] * 3 + [math.radians(acfg.hessian_rotation_deg)] * 3)

    # a single shot only: with two or more views their own spread (the jackknife over their
    # regions, the pair test) measures the shot-to-shot bias that restarts find, and restarting
    # a many-pair job costs minutes (a 2-pair Livox report 15 -> 117 s). Pairs that all show
    # one view (a camera that did not move) are one shot however many there are
    labels = views([p.image for p in pairs])
    n_restarts = acfg.restarts if len(np.unique(labels)) == 1 else 0
    from nbcalib.registration.intrinsics import MIN_PAIRS

    # the intrinsics check measures jobs of MIN_PAIRS pairs or more (a step of its own)
    checked = acfg.intrinsics_check and len(pairs) >= MIN_PAIRS
    n_steps = len(pairs) + 6 + n_restarts + int(checked)
    with Progress(n_steps, "quality", enabled=progress is True) as display:

        def step(what: str) -> None:
            if callable(progress):
                progress(what)
            display.update(what=what)

        def material(pair):  # one pair's cost, gradient and Hessians: independent of the rest
            cost, counts = build_cost([pair], T, rcfg, n_pairs=len(pairs))
            for term in cost.costs:  # several pairs run on threads, each with serial kernels
                term.parallel = (
                    rcfg.parallel and len(pairs) == 1 and len(term) >= PARALLEL_MIN_POINTS
                )
            value, grad = cost.value_and_grad(T)
            grouped = [
                (t, w) for t, w in zip(cost.costs, cost.weights) if isinstance(t, GroupedNIDCost)
            ]
            H_raw, block = np.zeros((6, 6)), None
            if counts[0] > 0:
                blocks = None
                if grouped:  # the regional terms' Hessians, measured once for the blocks
                    g_b, blocks = _block_material(grouped, T, steps, acfg.jackknife_blocks)
                    block = (g_b, blocks)
                rest = [
                    (t, w)
                    for t, w in zip(cost.costs, cost.weights)
                    if not isinstance(t, GroupedNIDCost)
                ]
                H_raw = _hessian(MultiNIDCost(*zip(*rest)) if rest else None, T, steps, blocks)
            H, n_again = H_raw, 0
            if counts[0] > 0:
                H, n_again = _remeasure_flat_directions(
                    cost, T, H_raw, steps, value, acfg.max_curvature_scale
                )
            pixels = _pixels_covered(pair, T, rcfg)
            return cost, counts[0], pixels, value, grad, H, H_raw, n_again, block

        costs, nids, visible, pixels, grads = [], [], [], [], []
        hessians, raw_hessians, remeasured = [], [], []
        block_pair, block_grads, block_hessians = [], [], []
        for k, made in enumerate(thread_map(material, pairs)):  # pairs on every core
            cost, n_visible, n_pixels, value, grad, H, H_raw, n_again, block = made
            visible.append(n_visible)
            pixels.append(n_pixels)
            nids.append(value)
            grads.append(grad)
            if block is not None:
                block_pair += [k] * len(block[0])
                block_grads.append(block[0])
                block_hessians.append(block[1])
            hessians.append(H)
            raw_hessians.append(H_raw)
            remeasured.append(n_again)
            costs.append(cost)
            step(f"Hessian of {pairs[k].name or f'pair {k}'}")

        curve_offsets, curve_values = _curves(costs, T, acfg, step)
        restart_offsets = np.zeros((0, 6))
        if n_restarts and sum(visible) > 0:
            restart_offsets = _restart_offsets(pairs, T, config, acfg, step)
        intrinsics = None
        if acfg.intrinsics_check and sum(visible) > 0:
            from nbcalib.report.intrinsics import check_intrinsics

            intrinsics = check_intrinsics(pairs, T, rcfg, acfg.intrinsics_tolerance).to_dict()
            if checked:
                step("intrinsics check")
    init_change = None
    if T_init is not None:
        T0 = validate_T(np.asarray(T_init, dtype=np.float64), "T_init")
        dt, dr = pose_error(invert_T(T), invert_T(T0))
        init_change = (float(dt), float(dr))
    quality = Quality(
        T_camera_lidar=T,
        names=[p.name or f"pair {i}" for i, p in enumerate(pairs)],
        nid=float(sum(nids)),
        nid_per_pair=np.array(nids, dtype=np.float64),
        visible_points=np.array(visible, dtype=np.int64),
        pixels_covered=np.array(pixels, dtype=np.int64),
        curve_offsets=curve_offsets,
        curve_values=curve_values,
        gradient=np.sum(grads, axis=0),
        hessian=sum(n * h for n, h in zip(pixels, hessians)),
        covariance=np.zeros((6, 6)),
        pair_offsets=None,
        init_change=init_change,
        converged=converged,
        uncertainty={},
        pair_gradients=np.array(grads, dtype=np.float64),
        pair_hessians=np.array(hessians, dtype=np.float64),
        pair_hessians_raw=np.array(raw_hessians, dtype=np.float64),
        pair_remeasured=np.array(remeasured, dtype=np.int64),
        block_pair=np.array(block_pair, dtype=np.int64),
        block_gradients=np.concatenate(block_grads) if block_grads else np.zeros((0, 6)),
        block_hessians=np.concatenate(block_hessians) if block_hessians else np.zeros((0, 6, 6)),
        restart_offsets=restart_offsets,
        views=labels,
        trust_region=(rcfg.trust_translation, rcfg.trust_rotation_deg),
        start_uncertainty=start_uncertainty,
        intrinsics_check=intrinsics,
    )
    return rejudge(quality, acfg)


def rejudge(quality: Quality, assess_config: AssessConfig) -> Quality:
    """Redo the uncertainty and verdict of ``quality`` under other settings, without new costs.

    Uses the stored gradients, Hessians and curves; the curve ranges and Hessian steps of
    ``assess_config`` are not applied (they need new cost evaluations).

    Parameters
    ----------
    quality : Quality
        From :func:`assess`.
    assess_config : AssessConfig
        New scale, confidence and verdict limits.

    Returns
    -------
    Quality
        A copy with ``covariance``, ``pair_offsets``, ``uncertainty``, ``move_allowed``,
        ``verdict``, ``reasons`` and ``config`` replaced.
    """
    acfg = assess_config
    q = replace(quality, config=acfg, reasons=[], next_steps=[])
    cov_curvature, n_negative = _inverse_psd(q.hessian)
    covariance = acfg.scale * cov_curvature
    spans = np.array([acfg.curve_translation] * 3 + [math.radians(acfg.curve_rotation_deg)] * 3)
    jackknife = _jackknife(q.block_gradients, q.block_hessians, spans)
    if jackknife is not None:
        covariance = covariance + acfg.jackknife_scale * jackknife
    pair_ratios = []
    n_pairs = len(q.names)
    if n_pairs >= 2:
        offsets, owns = np.empty((n_pairs, 6)), np.empty((n_pairs, 6, 6))
        raw = q.pair_hessians_raw if len(q.pair_hessians_raw) == n_pairs else q.pair_hessians
        for k in range(n_pairs):
            n = float(q.pixels_covered[k])
            h_inv, _ = _inverse_psd(n * q.pair_hessians[k])
            # the pair's own optimum: a Newton step along its directions of clear positive
            # curvature only (a flat or non-convex direction says nothing about where the pair's
            # minimum is, and its floored inverse sent steps to the clip on good results), kept
            # within the range the curves examine, where the cost was actually looked at. The
            # step is the minimum of the gradient's own quadratic model, so it takes the
            # curvature from the gradient differences: along a direction re-measured from the
            # values that model has no minimum (demo seed 2: a 3.4 cm step along tz there called
            # a good pair disagreeing)
            step = -(_newton_inverse(n * raw[k]) @ (n * q.pair_gradients[k]))
            offsets[k] = np.clip(step, -spans, spans)
            owns[k] = acfg.scale * h_inv
            mine = q.block_pair == k
            pair_jackknife = _jackknife(q.block_gradients[mine], q.block_hessians[mine], spans)
            if pair_jackknife is not None:
                owns[k] += acfg.jackknife_scale * pair_jackknife
        floor = np.array(
            [acfg.pair_bias_translation] * 3 + [math.radians(acfg.pair_bias_rotation_deg)] * 3
        )
        pair_ratios = pairs_elsewhere(offsets, owns, floor, acfg.pair_disagreement_quantile)
        q.pair_offsets = offsets
        if n_pairs >= 3:
            q.leave_one_out = leave_one_out(q.pair_gradients, raw, spans)
        if jackknife is None:  # the blocks' spread holds the pairs' when there are blocks
            covariance = covariance + np.cov(offsets.T, ddof=1) / n_pairs
    # judged as if there had been fewer: restart_starts are seeded, so the first k of the stored
    # ends are exactly those k restarts would have found
    q.restart_offsets = np.asarray(q.restart_offsets, dtype=np.float64)[: acfg.restarts]
    n_restarts = len(q.restart_offsets)
    if n_restarts:
        ends = np.asarray(q.restart_offsets, dtype=np.float64)
        covariance = covariance + acfg.restart_scale * (ends.T @ ends) / n_restarts
    q.covariance = covariance
    q.uncertainty = _uncertainty(covariance, acfg.confidence)
    q.uncertainty["method"] = (
        f"curvature of the summed NID, weighted by pixels covered, scale {acfg.scale:.4g}"
        + (
            f" + jackknife over {len(q.block_pair)} blocks of image regions, scale "
            f"{acfg.jackknife_scale:.4g}"
            if jackknife is not None
            else (" + spread of per-pair optima" if n_pairs >= 2 else "")
        )
        + (
            f" + ends of {n_restarts} restarts {acfg.restart_rotation_deg:g} deg / "
            f"{100 * acfg.restart_translation:g} cm around it, scale {acfg.restart_scale:.4g}"
            if n_restarts
            else ""
        )
    )
    q.move_allowed = _move_allowed(q)
    found = reasons(q, n_negative, pair_ratios)
    q.reasons = [line for _, line in found]
    q.next_steps = list(dict.fromkeys(advice(kind, q) for kind, _ in found))
    q.verdict = "suspect" if q.reasons else "ok"
    return q
