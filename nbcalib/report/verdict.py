"""The verdict of a calibration: each reason to distrust it, and what to do about it.

:func:`reasons` reads a :class:`~nbcalib.report.quality.Quality` (its uncertainty, curves,
pairs, restarts and move from the start; the module docstring of :mod:`nbcalib.report.quality`
tells what each test means); :data:`ADVICE` gives one line of advice per kind of reason, and
:func:`pairs_elsewhere` is the test of a pair whose own optimum lies elsewhere.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.report.uncertainty import AXIS_NAMES
from nbcalib.wording import say

if TYPE_CHECKING:
    from nbcalib.report.assessment import Quality

__all__ = ["ADVICE", "MANY_VIEWS", "advice", "format_bound", "pairs_elsewhere", "reasons"]

#: Pairs of at least this many distinct views are independent evidence: their agreement, not
#: each one's sharpness, the NID level or the start, says whether the result holds.
MANY_VIEWS = 3

#: An uncertainty beyond these says only that the cost does not pin the pose down: no rig's
#: extrinsic is unknown by more than 10 metres, and no rotation error exceeds 180 degrees.
UNBOUNDED_CM = 1000.0
UNBOUNDED_DEG = 180.0


def format_bound(value: float, unit: str) -> str:
    """An uncertainty as people read it: ``"0.52 cm"``, ``"0.031 deg"``, or ``"unbounded"``.

    Parameters
    ----------
    value : float
        Centimetres (``unit="cm"``) or degrees (``unit="deg"``).
    unit : {"cm", "deg"}
    """
    limit, digits = (UNBOUNDED_CM, 2) if unit == "cm" else (UNBOUNDED_DEG, 3)
    if not math.isfinite(value) or abs(value) > limit:
        return f"unbounded (> {limit:g} {unit}: the cost does not fix it)"
    return f"{value:.{digits}f} {unit}"


def _move_allowed(q: Quality) -> tuple[float, float] | None:
    """Largest move from the start the two uncertainties allow: ``sqrt(s^2 + u^2)`` each."""
    used = q.start_uncertainty_used
    if q.init_change is None or used is None:
        return None
    (s_t, s_r), u = used[0], q.uncertainty
    return (
        math.hypot(s_t, u["translation_total_cm"] / 100.0),
        math.hypot(s_r, u["rotation_total_deg"]),
    )


def _move_reasons(q: Quality) -> list[tuple[str, str]]:
    """The trust-region and move-from-the-start reasons (module docstring)."""
    if q.init_change is None:
        return []
    dt, dr = q.init_change
    reasons = []
    if q.at_trust_boundary:
        rt, rr = q.trust_region
        reasons.append(
            (
                "trust_edge",
                f"reached the trust region around the start: moved {dt:.3f} m / {dr:.2f} deg "
                f"(region {rt:g} m / {rr:g} deg); the optimum may lie beyond it",
            )
        )
    if q.move_allowed is not None:
        (at, ar), (stated, source) = q.move_allowed, q.start_uncertainty_used
        moved, allowed = [], []
        if dt > at:
            moved.append(f"{100 * dt:.1f} cm")
            allowed.append(f"{100 * at:.1f} cm")
        if dr > ar:
            moved.append(f"{dr:.2f} deg")
            allowed.append(f"{ar:.2f} deg")
        if moved:
            whose = "stated" if source == "stated" else "none stated: the trust region"
            reasons.append(
                (
                    "moved_far",
                    f"moved {' and '.join(moved)} from the start, more than the "
                    f"{' and '.join(allowed)} the start's ({whose}, {100 * stated[0]:.1f} cm, "
                    f"{stated[1]:.2f} deg) and the result's uncertainties allow",
                )
            )
    return reasons


#: What to do next, one line per kind of reason (:attr:`Quality.next_steps`). Settings are named
#: as the API names them (:mod:`nbcalib.wording`); :func:`advice` spells them for the front end.
_MEASURED_START = (
    "start from a measured pose (run.force, run.init=X,Y,Z,QX,QY,QZ,QW) or from picked points "
    "(run.force, run.manual=picks.json)"
)
_MORE_VIEWS = (
    "add pairs seen from other places or headings (a folder of frames, inputs.frames=DIR, or "
    "inputs.pair_count=N images of a recording) and calibrate them together"
)
ADVICE = {
    "few_points": (
        "Few LiDAR points land in the image: check the camera file (model, image size, "
        "intrinsics) and the start; more scans per pair (preprocess.neighbors=K) make a denser "
        "cloud."
    ),
    "no_information": (
        "Check that each image and its LiDAR data show the same moment and place, then "
        f"{_MEASURED_START}."
    ),
    "flat": (
        f"This view does not pin the pose down: {_MORE_VIEWS}; texture and structure at several "
        "depths help."
    ),
    "not_at_minimum": (
        "The optimiser stopped short of the minimum: calibrate again from this result "
        "(run.force, run.init set to results.T_lidar_camera of calib.json)."
    ),
    "far_from_guess": f"The start was probably wrong: {_MEASURED_START}, then calibrate again.",
    "pairs_disagree": (
        "Look at the named pairs' overlays (a wrong image, a time offset, motion during the "
        "pair): calibrate without them, or record them again."
    ),
    "not_converged": ("Calibrate again with more iterations (run.force, refine.max_outer=20)."),
}
ADVICE["unstable"] = (
    "The cost has several minima near this result and which one registration finds depends on "
    f"the start: {_MORE_VIEWS}, or {_MEASURED_START}."
)
ADVICE["trust_edge"] = ADVICE["moved_far"] = ADVICE["far_from_guess"]
ADVICE["rests_on"] = (
    "One frame decides the result alone: look at its overlays (a wrong image, a time offset, "
    "motion), calibrate without it, or add frames seen from other places so that no frame "
    "decides alone."
)
ADVICE["flat_frames"] = (
    "These frames do not pin the named axes down: add frames seen from other places or "
    "headings, with structure near the camera (a few metres) as well as far (a forward "
    "translation shows only in near structure), and calibrate them together."
)
#: Advice for a job of several pairs that all show one view, in place of "flat" and "unstable".
ONE_VIEW = (
    "The pairs all show one view (the camera did not move between them), so they add up to one "
    "shot: record frames from other places or headings (drive or carry the rig between them) "
    "and calibrate them together."
)


def advice(kind: str, q: Quality) -> str:
    """The line of advice for a reason of ``kind`` in this job (:data:`ADVICE`)."""
    if kind in ("flat", "unstable") and len(q.names) >= 2 and q.n_views == 1:
        return say(ONE_VIEW)
    return say(ADVICE[kind])


def pairs_elsewhere(offsets, own_covariances, bias_floor, quantile: float) -> list[float]:
    """How far each pair's optimum lies from the other pairs', in units of its test's limit.

    A pair's optimum (``offsets[k]``, from the joint result) differs from the other pairs'
    mean by its noise and theirs (``own_covariances``: curvature and each pair's own
    jackknife) and by the bias each single shot leaves, which no measure within a pair sees:
    the pairs of one synthetic rig sit 0.1-1.4 cm / 0.01-0.16 deg (standard deviation per
    axis) from each other, with every pair's own uncertainty far smaller. That bias is taken as
    ``bias_floor`` (standard deviation per axis) or, with three or more pairs, as the spread of
    the *other* pairs' optima where that is larger (estimated without the pair under test, so
    that a pair far off cannot hide behind its own distance; on the axis itself or pooled over
    the three axes of its kind, whichever is larger). Per axis, the residual over its standard
    deviation is compared with the two-sided quantile of the normal (bias from the floor) or of
    Student's t (bias estimated: ``K - 2`` degrees of freedom, ``3 (K - 2)`` pooled) at
    ``(1 - quantile) / (6 K)``: with agreeing pairs the chance that any axis of any pair is
    called elsewhere stays below ``1 - quantile`` whatever ``K`` (Bonferroni).

    Parameters
    ----------
    offsets : ndarray of shape (K, 6)
        Each pair's optimum minus the joint result, ``delta = [v, omega]`` (m, rad), K >= 2.
    own_covariances : ndarray of shape (K, 6, 6)
    bias_floor : array_like of shape (6,)
        Least standard deviation of a pair's bias per axis (m, rad).
    quantile : float
        In (0, 1): :attr:`AssessConfig.pair_disagreement_quantile`.

    Returns
    -------
    list of float
        Per pair, the largest ``|residual| / (sigma * limit)`` over the axes: above 1 the pair
        disagrees.
    """
    from scipy.special import ndtri, stdtrit  # without scipy.stats (~1 s to import)

    offsets = np.asarray(offsets, dtype=np.float64)
    own = np.array([np.diag(c) for c in np.asarray(own_covariances, dtype=np.float64)])
    floor2 = np.asarray(bias_floor, dtype=np.float64) ** 2
    n_pairs = len(offsets)
    if n_pairs < 2:
        raise ValueError("the pair test needs at least two pairs")
    upper = 1.0 - 0.5 * (1.0 - quantile) / (6 * n_pairs)
    m = n_pairs - 1  # the other pairs
    # candidates for the bias variance per axis, each with the limit of its own precision: the
    # floor (known: normal), the other pairs' spread pooled over the three axes of a kind
    # (3 (K - 2) degrees of freedom, so that two pairs agreeing by chance on one axis do not make
    # a third look far off) and on the axis itself (K - 2: an axis whose pairs scatter more than
    # the others of its kind); the largest is used
    limits = np.array([ndtri(upper)] + ([stdtrit(3 * (m - 1), upper), stdtrit(m - 1, upper)]
                                        if m >= 2 else []))  # fmt: skip
    out = []
    for k in range(n_pairs):
        others = np.delete(offsets, k, axis=0)
        variances = [floor2]
        if m >= 2:
            per_axis = np.var(others, axis=0, ddof=1)
            variances += [np.repeat([per_axis[:3].mean(), per_axis[3:].mean()], 3), per_axis]
        choice = np.argmax(np.array(variances), axis=0)
        bias = np.choose(choice, variances)
        limit = limits[choice]
        var = own[k] + np.delete(own, k, axis=0).mean(axis=0) / m + bias * (1.0 + 1.0 / m)
        residual = np.abs(offsets[k] - others.mean(axis=0))
        # a zero variance (both floors set to 0, no curvature, pairs identical) makes any
        # residual infinitely far and none at all agree, rather than a nan that is never flagged
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(var > 0.0, residual / np.sqrt(var), np.where(residual > 0.0, np.inf, 0.0))
        out.append(float(np.max(z / limit)))
    return out


def reasons(q: Quality, n_negative: int, pair_ratios: list[float]) -> list[tuple[str, str]]:
    """``(kind, line)`` per reason to distrust the result (empty: ok); kinds of :data:`ADVICE`."""
    c = q.config
    reasons = []
    # independent views that agree judge the result; the single-shot tests below (each pair's
    # sharpness, the NID level, the distance from the start) do not apply to them
    independent = q.n_views >= MANY_VIEWS
    total_visible = int(q.visible_points.sum())
    if total_visible < c.min_visible_points:
        reasons.append(
            (
                "few_points",
                f"too few points in view: {total_visible} visible "
                f"(at least {c.min_visible_points})",
            )
        )
    if not independent and q.nid_per_pair.size and float(np.mean(q.nid_per_pair)) > c.max_nid:
        reasons.append(
            (
                "no_information",
                f"image and LiDAR share almost no information: NID {np.mean(q.nid_per_pair):.3f} "
                f"(limit {c.max_nid}); wrong image, wrong pose or no texture",
            )
        )
    u = q.uncertainty
    flat = []
    if n_negative:
        flat.append(f"{n_negative} direction(s) with no curvature")
    if u["translation_total_cm"] > 100.0 * c.max_translation_uncertainty:
        flat.append(
            f"translation uncertainty {format_bound(u['translation_total_cm'], 'cm')} "
            f"(limit {100 * c.max_translation_uncertainty:.1f})"
        )
    if u["rotation_total_deg"] > c.max_rotation_uncertainty_deg:
        flat.append(
            f"rotation uncertainty {format_bound(u['rotation_total_deg'], 'deg')} "
            f"(limit {c.max_rotation_uncertainty_deg:.2f})"
        )
    n_pairs = max(len(q.names), 1)
    centre = q.curve_values.shape[1] // 2
    rise = 0.5 * (q.curve_values[:, 0] + q.curve_values[:, -1]) - q.curve_values[:, centre]
    flat_axes = [AXIS_NAMES[a] for a in range(6) if rise[a] / n_pairs < c.min_curve_rise]
    if flat_axes and not independent:
        flat.append(f"NID hardly rises along {', '.join(flat_axes)}")
    if flat:
        kind = "flat_frames" if independent else "flat"
        reasons.append((kind, "flat cost: " + "; ".join(flat)))
    off_axes = []
    limits = [c.max_minimum_offset_translation] * 3 + [
        math.radians(c.max_minimum_offset_rotation_deg)
    ] * 3
    for a in range(6):
        best = int(np.argmin(q.curve_values[a]))
        drop = q.curve_values[a, centre] - q.curve_values[a, best]
        if abs(q.curve_offsets[a, best]) > limits[a] and drop > 0.25 * c.min_curve_rise * n_pairs:
            unit = (100.0, "cm") if a < 3 else (math.degrees(1.0), "deg")
            off_axes.append(f"{AXIS_NAMES[a]} {unit[0] * q.curve_offsets[a, best]:+.2f} {unit[1]}")
    if off_axes:
        reasons.append(
            ("not_at_minimum", "not at a minimum: the NID is lower at " + ", ".join(off_axes))
        )
    if q.init_change is not None and not independent:
        dt, dr = q.init_change
        if dt > c.max_init_translation or dr > c.max_init_rotation_deg:
            reasons.append(
                (
                    "far_from_guess",
                    f"initial guess and result far apart: {100 * dt:.1f} cm, {dr:.2f} deg (limits "
                    f"{100 * c.max_init_translation:.0f} cm, {c.max_init_rotation_deg:.1f} deg)",
                )
            )
    reasons += _move_reasons(q)
    if len(q.restart_offsets):
        turned = np.degrees(np.linalg.norm(np.asarray(q.restart_offsets)[:, 3:], axis=1))
        median = float(np.median(turned))
        if median > c.max_restart_rotation_deg:
            reasons.append(
                (
                    "unstable",
                    f"the result depends on where registration starts: from "
                    f"{len(turned)} starts {c.restart_rotation_deg:g} deg / "
                    f"{100 * c.restart_translation:g} cm around it, it ends {median:.2f} deg "
                    f"from it (median; limit {c.max_restart_rotation_deg:.2f})",
                )
            )
    if pair_ratios:
        bad = [name for name, ratio in zip(q.names, pair_ratios) if ratio > 1.0]
        if bad:
            reasons.append(
                (
                    "pairs_disagree",
                    f"pairs disagree: the optimum of {', '.join(bad)} lies elsewhere",
                )
            )
    if independent and q.leave_one_out is not None:
        reasons += _leave_one_out_reasons(q)
    if q.converged is False:
        reasons.append(
            ("not_converged", "the optimiser did not converge (stopped at its iteration limit)")
        )
    return reasons


def _leave_one_out_reasons(q: Quality) -> list[tuple[str, str]]:
    """A pair without which the result moves beyond its own uncertainty decides it alone."""
    u = q.uncertainty
    limit_m, limit_deg = u["translation_total_cm"] / 100.0, u["rotation_total_deg"]
    moves = np.asarray(q.leave_one_out, dtype=np.float64)
    t = np.linalg.norm(moves[:, :3], axis=1)
    r = np.degrees(np.linalg.norm(moves[:, 3:], axis=1))
    bad = [k for k in range(len(moves)) if t[k] > limit_m or r[k] > limit_deg]
    if not bad:
        return []
    k = max(bad, key=lambda j: max(t[j] / max(limit_m, 1e-12), r[j] / max(limit_deg, 1e-12)))
    return [
        (
            "rests_on",
            f"the result rests on {', '.join(q.names[j] for j in bad)}: without {q.names[k]} it "
            f"moves {100 * t[k]:.2f} cm / {r[k]:.3f} deg, more than its uncertainty "
            f"({100 * limit_m:.2f} cm / {limit_deg:.3f} deg)",
        )
    ]
