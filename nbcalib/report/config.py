"""Settings of the quality assessment (``nbcalib report``), importable without numba.

:class:`AssessConfig` is the ``assess`` section of the pipeline's config
(:class:`nbcalib.config.CalibrationConfig`).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["AssessConfig"]


@dataclass(frozen=True)
class AssessConfig:
    """Settings of :func:`~nbcalib.report.quality.assess`; lengths in metres, angles in degrees.

    Attributes
    ----------
    confidence : float
        Confidence of the stated intervals (0.95); a start's stated uncertainty
        (``--init-uncertainty``) is read at the same confidence when the move from the start is
        checked against the two uncertainties (:mod:`nbcalib.report.quality`).
    scale : float
        Variance scale of the curvature model (:mod:`nbcalib.report.quality`); tuned on
        synthetic pairs by benchmarks/bench_report_coverage.py.
    curve_samples : int
        Samples per NID curve (odd, so that the result itself is one).
    curve_translation, curve_rotation_deg : float
        Half-range of the translation and rotation curves.
    hessian_translation, hessian_rotation_deg : float
        Central-difference steps of the Hessian.
    max_curvature_scale : int
        An eigen-direction of a pair's Hessian without positive curvature is measured again by
        second differences of the NID along it at 1, 2, 4, ... up to this many Hessian steps
        (0: never; :mod:`nbcalib.report.quality`).
    min_visible_points : int
        Fewer visible points over all pairs is "too few points in view".
    max_translation_uncertainty, max_rotation_uncertainty_deg : float
        A stated total uncertainty (at ``confidence``) above these is "flat cost".
    min_curve_rise : float
        A curve whose ends rise less than this above the result (NID units, per pair) is flat.
    max_minimum_offset_translation, max_minimum_offset_rotation_deg : float
        A curve's lowest sample farther than this from the result, and lower than it by more
        than ``min_curve_rise / 4``, means the result is not at a minimum.
    max_init_translation, max_init_rotation_deg : float
        Result and initial guess farther apart than this are "far apart" (a fixed limit; a
        result on the edge of fine registration's trust region, or farther from its start than
        the start's and the result's uncertainties allow, is suspect too, whatever these are).
    max_nid : float
        A mean per-pair NID above this means image and LiDAR share almost no information.
    pair_disagreement_quantile : float
        Pairs disagree when a pair's own optimum lies farther from the other pairs' mean than
        their uncertainties and a single shot's bias allow, each axis of each of ``K`` pairs
        tested at ``(1 - q) / (6 K)`` (:func:`~nbcalib.report.verdict.pairs_elsewhere`): with
        agreeing pairs, the chance that any of them is called elsewhere is below ``1 - q``
        whatever ``K``.
    pair_bias_translation, pair_bias_rotation_deg : float
        Standard deviation per axis of a pair's own single-shot bias (the part of its optimum
        that another pair of the same rig does not share), the least the pair test allows
        for; with three or more pairs the spread of the other pairs' optima raises it
        (:mod:`nbcalib.report.quality`).
    jackknife_blocks : int
        Blocks of neighbouring image regions per pair for the jackknife part of the
        uncertainty (:mod:`nbcalib.report.quality`; 0 or 1: none); a pair with fewer regions
        has fewer blocks.
    jackknife_scale : float
        Variance scale of the jackknife part (1: the jackknife as it is).
    restarts : int
        For a single pair, fine registration is run again from this many starts around the
        result (0: none; :mod:`nbcalib.report.quality`); where they end adds to the
        uncertainty, and a median end far from the result in rotation makes it suspect. With
        two or more pairs there are none: their own spread measures a shot's bias.
    restart_translation, restart_rotation_deg : float
        How far each restart starts from the result: its camera centre moved by exactly this
        many metres, its rotation turned by exactly this many degrees (random directions).
    restart_scale : float
        Variance scale of the restarts' part: ``restart_scale`` times the mean outer product of
        their ends' offsets from the result.
    max_restart_rotation_deg : float
        A median restart ending farther than this from the result in rotation means the
        result depends on where registration starts ("unstable").
    restart_points : int or None
        Points of the pair each restart scores at most (a seeded subset of the visible ones,
        as fine registration's ``points_per_pixel`` budget; a pair with fewer keeps them all).
        None (default): fine registration's own budget. 50 000 points made four restarts of a
        synthetic spinning64 x pinhole pair 4.6 times cheaper, ending a median 0.18 cm / 0.014
        deg from the result, and left the real coverage of docs/BENCHMARKS.md 11 as it was,
        but a Livox x pinhole pair's restarts then scattered to a "flat cost" (8.7 cm stated)
        on a good result; 100 000 kept it ok (0.74 cm) with its report 34 -> 25 s, not yet
        measured at scale (docs/BENCHMARKS.md 10).
    intrinsics_check : bool
        Check whether the given focal length agrees with the data at the result
        (:func:`~nbcalib.report.intrinsics.check_intrinsics`; jobs of three pairs or more).
    intrinsics_tolerance : float
        Focal deviations up to this fraction are not flagged (0.003, 0.3 %).
    """

    confidence: float = 0.95
    # tuned by benchmarks/bench_report_coverage.py on demo-sized pairs (640 x 480, 0.02 m voxel,
    # 1 and 3 pairs), tuning half: 8.15 with the hybrid optimiser (RefineConfig default since
    # 2026-12-01 ~21:00 UTC), 6.78 with L-BFGS alone before; the first tuning (2026-11-23,
    # 400 x 300 pairs with <= 20 000 points) gave 2.06, with which good three-pair results
    # were called "pairs disagree"
    scale: float = 8.15
    curve_samples: int = 21
    curve_translation: float = 0.10
    curve_rotation_deg: float = 2.0
    hessian_translation: float = 0.005
    hessian_rotation_deg: float = 0.1
    max_curvature_scale: int = 16
    min_visible_points: int = 2000
    max_translation_uncertainty: float = 0.05
    max_rotation_uncertainty_deg: float = 1.0
    min_curve_rise: float = 0.002
    max_minimum_offset_translation: float = 0.02
    max_minimum_offset_rotation_deg: float = 0.4
    max_init_translation: float = 0.20
    max_init_rotation_deg: float = 4.0
    max_nid: float = 0.97
    pair_disagreement_quantile: float = 0.999
    # the median over axes and rigs of the pairs' scatter (standard deviation of their own
    # optima per axis) on bench_verdict's tune rigs of 2 and 5 pairs: 0.27 cm / 0.045 deg
    # (docs/BENCHMARKS.md 11)
    pair_bias_translation: float = 0.003
    pair_bias_rotation_deg: float = 0.05
    jackknife_blocks: int = 16
    # bench_verdict's tune half (2026-12-05, 22 synthetic and 75 real runs): the least of 1, 2,
    # 4, 8 whose synthetic per-axis coverage reaches 93 % (84.1, 84.8, 89.4, 94.7 %); the check
    # half 87.5 -> 100 %. Also real results beyond 1 deg / 10 cm called ok 15 -> 5 of 53 (a
    # wide jackknife is a flat cost), real good ones 10 -> 2 of 41 (docs/BENCHMARKS.md 11)
    jackknife_scale: float = 8.0
    # bench_verdict's real runs (2026-12-05; 152 single pairs of 38 sets from 4 starts each):
    # restarts from 1 deg / 5 cm end a median 4.4 cm / 0.18 deg from a result within
    # 0.3 deg / 5 cm of the reference and 5.1 cm / 0.82 deg from one beyond 1 deg / 10 cm;
    # on synthetic pairs they come back to within 0.3 cm / 0.01 deg. restart_scale: the least
    # of 1, 2, 3 whose real tune half is covered at >= 93 % per axis (through the CLI: 89.8,
    # 92.2, 93.8 %; the check half 93.9 %, 73.0 % without restarts). max_restart_rotation_deg:
    # the largest of 0.1, 0.15, ... 0.3 that calls no tune result beyond 1 deg / 10 cm ok (its
    # least median end is 0.22 deg); the check half: 0 of 26 such results under it
    # (docs/BENCHMARKS.md 11)
    restarts: int = 4
    restart_translation: float = 0.05
    restart_rotation_deg: float = 1.0
    restart_scale: float = 3.0
    max_restart_rotation_deg: float = 0.2
    restart_points: int | None = None
    intrinsics_check: bool = True
    intrinsics_tolerance: float = 0.003

    def __post_init__(self):
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")
        if not 0.0 < self.pair_disagreement_quantile < 1.0:
            raise ValueError("pair_disagreement_quantile must be in (0, 1)")
        if not self.scale > 0.0:
            raise ValueError(f"scale must be > 0, got {self.scale}")
        if not (self.pair_bias_translation >= 0.0 and self.pair_bias_rotation_deg >= 0.0):
            raise ValueError("pair_bias_translation and pair_bias_rotation_deg must be >= 0")
        if self.jackknife_blocks < 0:
            raise ValueError(f"jackknife_blocks must be >= 0, got {self.jackknife_blocks}")
        if not self.jackknife_scale >= 0.0:
            raise ValueError(f"jackknife_scale must be >= 0, got {self.jackknife_scale}")
        if self.restarts < 0:
            raise ValueError(f"restarts must be >= 0, got {self.restarts}")
        if not (self.restart_translation >= 0.0 and self.restart_rotation_deg >= 0.0):
            raise ValueError("restart_translation and restart_rotation_deg must be >= 0")
        if not (self.restart_scale >= 0.0 and self.max_restart_rotation_deg >= 0.0):
            raise ValueError("restart_scale and max_restart_rotation_deg must be >= 0")
        if not self.intrinsics_tolerance >= 0.0:
            raise ValueError(f"intrinsics_tolerance must be >= 0, got {self.intrinsics_tolerance}")
        if self.restart_points is not None and self.restart_points < 1:
            raise ValueError(f"restart_points must be >= 1 or None, got {self.restart_points}")
        if self.max_curvature_scale < 0:
            raise ValueError(f"max_curvature_scale must be >= 0, got {self.max_curvature_scale}")
        if self.curve_samples < 3 or self.curve_samples % 2 == 0:
            raise ValueError(f"curve_samples must be odd and >= 3, got {self.curve_samples}")
        positive = (
            "curve_translation",
            "curve_rotation_deg",
            "hessian_translation",
            "hessian_rotation_deg",
        )
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0")
