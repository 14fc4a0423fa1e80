"""What an assessment holds: the :class:`Quality` record, and its file.

:func:`nbcalib.report.quality.assess` measures it, :mod:`nbcalib.report.verdict` judges it,
the HTML report and its figures draw it; :meth:`Quality.save` and :func:`load_quality` keep it
in ``report/quality.npz`` so that the verdict can be judged again without a cost. This module
holds the record only, so that everything that reads it sits above it.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import asdict, dataclass, field, fields

import numpy as np

from nbcalib.registration.trust import on_trust_boundary
from nbcalib.report.config import AssessConfig
from nbcalib.report.uncertainty import AXIS_NAMES

__all__ = ["Quality", "load_quality"]


def _finite(value, cap: float = 1e6):
    """Replace non-finite numbers (JSON cannot hold them) by +-cap, recursively."""
    if isinstance(value, dict):
        return {k: _finite(v, cap) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v, cap) for v in value]
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else math.copysign(cap, v) if not math.isnan(v) else cap
    return value


@dataclass
class Quality:
    """What :func:`assess` found; every array is float64.

    Attributes
    ----------
    T_camera_lidar : ndarray of shape (4, 4)
        The assessed result, ``p_camera = T_camera_lidar @ p_lidar``.
    names : list of str
        Pair names.
    nid : float
        Summed NID over the pairs at the result (smooth form).
    nid_per_pair : ndarray of shape (K,)
        Each pair's NID at the result.
    visible_points : ndarray of shape (K,), int64
        Points of each pair visible from the result (after hidden-point removal).
    pixels_covered : ndarray of shape (K,), int64
        Distinct image pixels hit by those points (the independent samples of the model).
    curve_offsets : ndarray of shape (6, S)
        Offsets along each axis of :data:`AXIS_NAMES`: metres for ``tx, ty, tz``, radians for
        ``rx, ry, rz``.
    curve_values : ndarray of shape (6, S)
        Summed NID at those offsets.
    gradient : ndarray of shape (6,)
        Gradient of the summed NID at the result w.r.t. ``delta = [v, omega]``.
    hessian : ndarray of shape (6, 6)
        Information-weighted Hessian ``sum_k N_k H_k`` (symmetric).
    covariance : ndarray of shape (6, 6)
        Stated covariance of ``delta`` (m and rad), scale and pair spread included.
    pair_offsets : ndarray of shape (K, 6) or None
        Each pair's own optimum relative to the result (one Newton step), when K >= 2.
    init_change : tuple of 2 floats or None
        Distance from the initial guess: metres (camera centre) and degrees.
    converged : bool or None
        Whether the optimiser converged, if known.
    uncertainty : dict
        Human units at :attr:`confidence`: ``translation_cm`` and ``rotation_deg`` (3 values
        each, half-widths along the camera axes), ``translation_total_cm`` and
        ``rotation_total_deg`` (bounds on the error norms), ``confidence``, ``method``.
    verdict : {"ok", "suspect"}
    reasons : list of str
        Why the result is suspect (empty when ok).
    next_steps : list of str
        What to do about them, one line per kind of reason (:data:`ADVICE`; empty when ok).
    pair_gradients : ndarray of shape (K, 6)
        Each pair's NID gradient at the result.
    pair_hessians : ndarray of shape (K, 6, 6)
        Each pair's NID Hessian at the result (not weighted), directions without positive
        curvature measured again from the NID values (module docstring).
    pair_remeasured : ndarray of shape (K,), int64
        How many eigen-directions of each pair's Hessian were measured again that way.
    pair_hessians_raw : ndarray of shape (K, 6, 6)
        The same Hessians from the gradient differences alone, before that; the per-pair
        optima (Newton steps of the gradient's own quadratic model) use them.
    block_pair : ndarray of shape (B,), int64
        The pair of each block of image regions (the jackknife's units, module docstring);
        empty when no pair's cost has regions (``RefineConfig.cost = "nid"``).
    block_gradients : ndarray of shape (B, 6)
        Each block's share of its pair's NID gradient at the result (the blocks of a pair sum
        to the gradient of its regional term).
    block_hessians : ndarray of shape (B, 6, 6)
        Each block's share of its pair's Hessian (central differences of its gradient).
    restart_offsets : ndarray of shape (R, 6)
        Where fine registration ends when started again around the result
        (:attr:`AssessConfig.restarts` starts), ``delta`` with ``exp(delta) @ T_camera_lidar``
        the end; empty when there were no restarts.
    views : ndarray of shape (K,), int64
        A label per pair: pairs whose camera images show one view share it
        (:func:`~nbcalib.report.uncertainty.views`; a camera that did not move between them).
        Empty when not known: each pair its own view.
    leave_one_out : ndarray of shape (K, 6) or None
        Where the result moves with each pair left out (one Newton step), when K >= 3
        (:func:`~nbcalib.report.uncertainty.leave_one_out`).
    trust_region : tuple of 2 floats or None
        Fine registration's trust region around the start: metres and degrees.
    start_uncertainty : tuple of 2 floats or None
        The start's stated uncertainty (metres, degrees; None: not stated).
    move_allowed : tuple of 2 floats or None
        The largest move from the start that the start's and the result's uncertainties allow
        (metres, degrees; module docstring); None without a start.
    config : AssessConfig
    """

    T_camera_lidar: np.ndarray
    names: list[str]
    nid: float
    nid_per_pair: np.ndarray
    visible_points: np.ndarray
    pixels_covered: np.ndarray
    curve_offsets: np.ndarray
    curve_values: np.ndarray
    gradient: np.ndarray
    hessian: np.ndarray
    covariance: np.ndarray
    pair_offsets: np.ndarray | None
    init_change: tuple[float, float] | None
    converged: bool | None
    uncertainty: dict
    pair_gradients: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)), repr=False)
    pair_hessians: np.ndarray = field(default_factory=lambda: np.zeros((0, 6, 6)), repr=False)
    pair_remeasured: np.ndarray = field(
        default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False
    )
    pair_hessians_raw: np.ndarray = field(default_factory=lambda: np.zeros((0, 6, 6)), repr=False)
    block_pair: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    block_gradients: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)), repr=False)
    block_hessians: np.ndarray = field(default_factory=lambda: np.zeros((0, 6, 6)), repr=False)
    restart_offsets: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)), repr=False)
    views: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    leave_one_out: np.ndarray | None = field(default=None, repr=False)
    trust_region: tuple[float, float] | None = None
    start_uncertainty: tuple[float, float] | None = None
    move_allowed: tuple[float, float] | None = None
    verdict: str = "ok"
    reasons: list[str] = field(default_factory=list)
    next_steps: list[str] = field(default_factory=list)
    config: AssessConfig = field(default_factory=AssessConfig, repr=False)
    #: Whether the given focal length agrees with the data
    #: (:meth:`nbcalib.report.intrinsics.IntrinsicsCheck.to_dict`; None: not checked).
    intrinsics_check: dict | None = None

    @property
    def at_trust_boundary(self) -> bool | None:
        """The result lies on the edge of the trust region around the start (None: unknown)."""
        if self.init_change is None or self.trust_region is None:
            return None
        return on_trust_boundary(self.init_change, self.trust_region)

    @property
    def start_uncertainty_used(self) -> tuple[tuple[float, float], str] | None:
        """The start's uncertainty the verdict takes (metres, degrees) and where it came from.

        The stated one (``"stated"``), else the trust region (``"trust region"``); None when
        neither is known.
        """
        if self.start_uncertainty is not None:
            return tuple(self.start_uncertainty), "stated"
        if self.trust_region is not None:
            return tuple(self.trust_region), "trust region"
        return None

    @property
    def n_views(self) -> int:
        """Distinct views among the pairs (each pair its own when not known)."""
        return len(np.unique(self.views)) if len(self.views) == len(self.names) else len(self.names)

    @property
    def sigma(self) -> np.ndarray:
        """Standard deviations of ``delta`` (6,): metres, then radians."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def to_dict(self) -> dict:
        """JSON-ready summary for ``calib.json`` (``nbcalib.quality``); finite numbers only."""
        out = {
            "verdict": self.verdict,
            "reasons": list(self.reasons),
            "next_steps": list(self.next_steps),
            "uncertainty": _finite(self.uncertainty),
            "nid": _finite(self.nid),
            "pairs": [
                {
                    "name": name,
                    "nid": _finite(float(nid)),
                    "visible_points": int(n),
                    "pixels_covered": int(p),
                }
                for name, nid, n, p in zip(
                    self.names, self.nid_per_pair, self.visible_points, self.pixels_covered
                )
            ],
            "curves": {
                "axes": list(AXIS_NAMES),
                "offsets": "metres for tx, ty, tz; radians for rx, ry, rz",
                "offset": _finite(self.curve_offsets.tolist()),
                "nid": _finite(self.curve_values.tolist()),
            },
            "covariance": _finite(self.covariance.tolist()),
            "converged": self.converged,
        }
        if self.init_change is not None:
            out["change_from_init"] = {
                "translation_m": _finite(self.init_change[0]),
                "rotation_deg": _finite(self.init_change[1]),
            }
            move = {
                "translation_m": _finite(self.init_change[0]),
                "rotation_deg": _finite(self.init_change[1]),
            }
            if self.move_allowed is not None:
                move["allowed_translation_m"] = _finite(self.move_allowed[0])
                move["allowed_rotation_deg"] = _finite(self.move_allowed[1])
            used = self.start_uncertainty_used
            if used is not None:
                move["start_uncertainty"] = {
                    "translation_m": _finite(used[0][0]),
                    "rotation_deg": _finite(used[0][1]),
                    "source": used[1],
                }
            if self.trust_region is not None:
                move["trust_region"] = {
                    "translation_m": _finite(self.trust_region[0]),
                    "rotation_deg": _finite(self.trust_region[1]),
                }
                move["at_trust_boundary"] = bool(self.at_trust_boundary)
            out["move_from_start"] = move
        if self.pair_offsets is not None:
            out["pair_offsets"] = _finite(self.pair_offsets.tolist())
        if self.intrinsics_check is not None:
            out["intrinsics_check"] = _finite(self.intrinsics_check)
        return out

    def save(self, path) -> None:
        """Write everything :func:`rejudge` needs to ``path`` (``.npz``; :func:`load_quality`).

        ``nbcalib report`` writes it as ``report/quality.npz``, so that the uncertainty and the
        verdict can be judged again under other settings without evaluating a cost.
        """
        from nbcalib.io._files import write_bytes_atomic

        arrays, plain = {}, {}
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                arrays[f.name] = value
            elif f.name == "config":
                plain[f.name] = asdict(value)
            else:
                plain[f.name] = value
        buffer = io.BytesIO()
        np.savez_compressed(buffer, _plain=np.array(json.dumps(_finite(plain))), **arrays)
        write_bytes_atomic(path, [buffer.getvalue()])


def load_quality(path) -> Quality:
    """The :class:`Quality` that :meth:`Quality.save` wrote to ``path``."""
    with np.load(path, allow_pickle=False) as data:
        plain = json.loads(str(data["_plain"]))
        arrays = {k: data[k] for k in data.files if k != "_plain"}
    config = AssessConfig(
        **{k: tuple(v) if isinstance(v, list) else v for k, v in plain.pop("config").items()}
    )
    for name in ("init_change", "trust_region", "start_uncertainty", "move_allowed"):
        if plain.get(name) is not None:
            plain[name] = tuple(plain[name])
    return Quality(**plain, **arrays, config=config)
