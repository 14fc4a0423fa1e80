"""Several starts around a many-pair result: leave a wrong basin, keep the lowest minimum.

Fine registration converges to the minimum of the basin it starts in. A guess pooled from many
frames is often 10-25 cm off in translation, and there the summed NID of single real scans has
other minima: on ten KITTI odometry frames, one of three starts 3 deg / 20 cm from KITTI's
calibration ended 21 cm away, at an NID 0.016 above the minimum the others found (the minima
of the right basin differ by 0.0002). The rotation is pinned far better than the translation,
so :func:`basin_search` starts fine registration's first stage (Nelder-Mead over the pyramid)
again from the result's camera moved by ``basin_translation`` along each camera axis, both ways,
and keeps the end with the lowest summed NID, all of them scored by one cost built at the
result (the same visible points and regions for every candidate); fine registration's last
stage (L-BFGS) then polishes the one kept. A candidate has to beat the result by
:data:`MARGIN` per pair: the minima of one basin differ by less, and the result stays where it
is rather than hop between them.

Only for two or more pairs: one pair's report restarts registration around the result already
(:attr:`nbcalib.report.config.AssessConfig.restarts`), and its basin is wide where the data are
dense (docs/BENCHMARKS.md 5.4).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nbcalib.transforms import se3_exp

__all__ = ["MARGIN", "basin_search", "basin_starts"]

#: NID per pair a candidate must be lower by to replace the result.
MARGIN = 5e-5


def basin_starts(T_camera_lidar, distance: float) -> list[np.ndarray]:
    """The pose with its camera moved by ``distance`` along each camera axis, both ways (6)."""
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    starts = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            delta = np.zeros(6)
            delta[axis] = sign * distance
            starts.append(se3_exp(delta) @ T)
    return starts


def basin_search(pairs, region, config, result, run_stage, report) -> bool:
    """Restart the first stage around ``result`` and keep the lowest end (module docstring).

    Parameters
    ----------
    pairs : sequence of RegistrationPair
    region : TrustRegion
        The run's trust region (every candidate stays in it).
    config : RefineConfig
        The first stage's settings (Nelder-Mead over the pyramid).
    result : RefineResult
        The run so far; its pose is replaced when a candidate is kept.
    run_stage : callable
        ``run_stage(config, start, result)`` runs one stage from ``start`` into ``result``
        (:func:`nbcalib.registration.refine._run_levels`).
    report : callable
        The run's progress callback, for each candidate's outer iterations.

    Returns
    -------
    bool
        A candidate replaced the result.
    """
    from nbcalib.registration.costs import build_cost
    from nbcalib.registration.refine import RefineResult

    T = result.T_camera_lidar.copy()
    scoring = replace(config, optimizer="lbfgs")
    cost, _ = build_cost(pairs, T, scoring)
    best_value = cost.value(T) - MARGIN * len(pairs)
    best = None
    for start in basin_starts(T, config.basin_translation):
        if not region.contains(start):
            start = region.project(start)
        trial = RefineResult(start.copy(), T_init=result.T_init)
        run_stage(config, trial, report)
        value = cost.value(trial.T_camera_lidar)
        result.basin_candidates.append((trial.T_camera_lidar.copy(), float(value)))
        if value < best_value:
            best, best_value = trial, value
    if best is None:
        return False
    result.T_camera_lidar = best.T_camera_lidar.copy()
    result.history.extend(best.history)
    return True
