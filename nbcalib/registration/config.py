"""Settings of fine registration, importable without numba or SciPy.

:class:`RefineConfig` is the ``refine`` section of the pipeline's config
(:class:`nbcalib.config.CalibrationConfig`), and command-line parsers take their defaults from
it; keeping it apart from
:mod:`nbcalib.registration.refine` (which loads the numba kernels) keeps every ``nbcalib``
command quick to start. :mod:`~nbcalib.registration.refine` re-exports it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["COSTS", "INTRINSICS_MODES", "OPTIMIZERS", "RENAMED", "RefineConfig"]

#: The intensity terms by name (:attr:`RefineConfig.cost`), each a module of
#: :mod:`nbcalib.registration.costs` whose ``terms(view, config)`` returns a list of
#: ``(term, weight)`` (weights summing to 1 per pair). The settings name them; the costs
#: package builds them (and imports this table, never the other way).
COSTS = {
    "regional": "nbcalib.registration.costs.regional",
    "nid": "nbcalib.registration.costs.nid",
}

#: Values of :attr:`RefineConfig.intrinsics` and how many intrinsics each refines.
INTRINSICS_MODES = {"focal": 1, "focal,center": 3}

#: Values of :attr:`RefineConfig.optimizer`.
OPTIMIZERS = ("hybrid", "lbfgs", "nelder_mead")

#: Former names of settings -> their names now; config files and records may use either.
RENAMED = {
    "max_total_translation": "trust_translation",
    "max_total_rotation_deg": "trust_rotation_deg",
}


@dataclass(frozen=True)
class RefineConfig:
    """Settings of fine registration; defaults follow the reference toolbox where sensible.

    Attributes
    ----------
    optimizer : {"hybrid", "lbfgs", "nelder_mead"}
        ``"hybrid"`` (default): Nelder-Mead on the hard NID over the pyramid, then L-BFGS on the
        smooth NID at full resolution from its result; ``"lbfgs"``: L-BFGS on the smooth NID
        over the pyramid (reference default: BFGS); ``"nelder_mead"``: Nelder-Mead on the hard
        NID (paper). On the synthetic benchmark the hybrid kept the Nelder-Mead basin and
        robustness and the L-BFGS accuracy (docs/BENCHMARKS.md, "Hybrid optimiser").
    cost : {"regional", "nid"}
        The intensity term (:mod:`nbcalib.registration.costs`). ``"regional"`` (default): the
        mean NID of regions of about ``region_points`` points each, one joint histogram per
        region (:mod:`~nbcalib.registration.costs.regional`); its minimum stays at the truth
        where one histogram's walks away (docs/BENCHMARKS.md, section 5.7). ``"nid"``: one
        joint histogram per pair (the paper and the reference), or per orientation class.
    region_points : int
        Points of a region of the regional cost: each has this many to twice this many
        (2000: about eight per cell of a 16 x 16 histogram).
    bins : int
        Histogram bins per axis (16).
    hidden_point_removal : bool
        Run the z-buffer visibility test before each outer iteration.
    depth_margin : float
        Metres behind the nearest point in a pixel that still count as visible (0.1).
    window : int
        Half-size of the pixel neighbourhood of the visibility test (0 = own pixel).
    max_outer : int
        Outer iterations at most per pyramid level, and per optimiser of the hybrid (10).
    max_translation, max_rotation_deg : float
        Trust box of one outer iteration around its start pose (0.2 m, 2 degrees).
    converge_translation, converge_rotation_deg : float
        Stop when an outer iteration moves the pose less than both.
    max_inner : int
        Iterations (L-BFGS) or, times 40, evaluations (Nelder-Mead) per outer iteration.
    lbfgs_ftol : float
        L-BFGS-B's stop on the relative reduction of the cost between iterations (1e-9). Its
        chart is scaled to 1 cm / 0.05 deg (:data:`~nbcalib.registration.optimize.
        LBFGS_SCALE`), so its first steps are that small: at 1e-7 the reduction of a first step
        on a cost far from its minimum stopped the search at once (3 deg / 10 cm off a textured
        synthetic pair, tests/test_calibrate.py).
    nelder_mead_init_step : float
        Initial simplex size in the tangent space, metres and radians, doubled per pyramid level
        (1e-2; reference: 1e-3, whose simplex converged in 3 / 2 / 0 / 0 of 5 starts 1 / 2 / 3 /
        5 degrees off, against 5 / 5 / 5 / 5 with 1e-2: docs/BENCHMARKS.md).
    nelder_mead_xatol, nelder_mead_fatol : float
        Nelder-Mead stops when its simplex is this small (metres and radians, doubled per
        pyramid level: 1e-4, a tenth of a millimetre) and its values this close (NID units:
        1e-5). The hard NID is a step function of the pose; with SciPy's 1e-8 the simplex
        went on shrinking far below the precision an outer iteration's stop asks for (1 mm,
        0.01 degree): about a third fewer evaluations, the same errors (docs/BENCHMARKS.md 5.3).
    pyramid_levels : int
        Coarse levels above the full-resolution image (0: full resolution only, as the
        reference). Level ``k`` halves the image ``k`` times; see the module docstring. Levels
        whose image would be smaller than ``min_pyramid_size`` pixels (its shorter side) are
        skipped: on a 400 x 300 image a 100 x 75 level let runs wander metres away.
    min_pyramid_size : int
        Shorter side, pixels, of the coarsest level used (240).
    trust_translation, trust_rotation_deg : float
        Trust region of the whole run around the initial guess (0.5 m, 5 degrees): no pose
        farther than this from it (camera centre in the LiDAR frame, rotation angle) is ever
        returned (:mod:`nbcalib.registration.trust`); a result on its edge is flagged
        (``RefineResult.at_trust_boundary``) and the verdict calls it suspect. The trust box
        bounds one outer iteration, not their sum: on a flat cost (a single real frame) the sum
        drifted 0.5-1.8 m and 5 degrees and more. The synthetic benchmark's starts (up to 30 cm
        and 5 degrees off) lie inside the default. Formerly ``max_total_translation`` and
        ``max_total_rotation_deg``, which stopped the run once it was outside, and are still
        read from config files and records (:data:`RENAMED`).
    orientation_classes : bool
        With ``cost = "nid"``, condition the NID on surface orientation: one joint histogram
        per class of normal direction, cost = point-weighted mean of the class NIDs
        (:mod:`nbcalib.registration.orientation`). False: one histogram (paper, reference).
    min_class_points : int
        Visible points every class of a pair needs (about 20 per histogram cell at 16 bins);
        otherwise that pair keeps one histogram. Single real scans (KITTI: 4-7 k points a
        class, noisy normals) stay on the plain NID this way.
    structure_weight : float
        Weight of the structure term beside each pair's intensity NID: the NID between LiDAR
        depth edges and image edges (:mod:`nbcalib.registration.structure`; 0: off, the
        paper and the reference).
    parallel : bool
        Multithreaded NID kernels (same values; slower in CPU time on a loaded machine).
    max_pairs : int or None
        Register only the first ``max_pairs`` pairs of a job (None: all).
    points_per_pixel : float or None
        Points of each pair the NID uses: at most this many per pixel of the camera image
        (full resolution, the same budget at every pyramid level), but never fewer than
        ``min_sampled_points``; a seeded random subset of the visible points (the same points
        for every pose). None uses every visible point. Default 0.25: a 16 x 16 joint
        histogram needs far fewer than the 1-2 million points a dense cloud puts in view; on
        the synthetic rigs and the real data the errors are those of every point, in 20-70 %
        less time (docs/BENCHMARKS.md, section 10).
    min_sampled_points : int
        The floor of ``points_per_pixel``'s budget (50 000): a pair with fewer visible points
        (a single real scan) keeps all of them at every level.
    job_points : int or None
        Points of all pairs of a job together at most: each pair uses at most an equal share
        (never below ``min_sampled_points``; None: no joint limit). A single pair keeps its
        own budget unless its camera has more than 4 million pixels; fifteen pairs use a
        fifteenth each (docs/BENCHMARKS.md, section 10).
    cloud_memory_mb : float or None
        Megabytes a job with a work directory keeps of its dense clouds (the work directory's
        float32 values) and of what fine registration and the report compute from them
        (visible sets, sample keys, KD-trees) from one use to the next (512). What does not
        fit is read again from the work directory, or computed again, when needed: the same
        numbers in more time (:mod:`nbcalib.clouds`). None: no limit.
    min_visible_points : int
        Fewer LiDAR points than this in the images at a pose being refined is refused (a user
        error: the start looks away from the cloud, or the camera does not fit the images):
        a joint histogram of 16 x 16 bins needs a few points per cell.
    intrinsics : {None, "focal", "focal,center"}
        Refine the camera's focal length (and principal point) with the extrinsic over every
        pair, after the pose alone (:mod:`nbcalib.registration.intrinsics`; None, the
        default: the intrinsics are given). Needs the smooth NID (optimiser ``hybrid`` or
        ``lbfgs``) and at least three pairs.
    intrinsics_focal_range, intrinsics_center_range : float
        How far the refinement may move them: the focal length by this fraction (0.05) and the
        principal point by this many pixels (25).
    intrinsics_max_focal_bound, intrinsics_max_center_bound : float
        The refined intrinsics are kept only when the frames determine them this well (95 %
        half-widths: 0.5 % of focal length, 2 pixels); otherwise the given camera and the pose
        found with it are the result, and the report says why.
    """

    optimizer: str = "hybrid"
    cost: str = "regional"
    region_points: int = 2000
    bins: int = 16
    hidden_point_removal: bool = True
    depth_margin: float = 0.1
    window: int = 0
    max_outer: int = 10
    max_translation: float = 0.2
    max_rotation_deg: float = 2.0
    converge_translation: float = 1e-3
    converge_rotation_deg: float = 0.01
    max_inner: int = 50
    lbfgs_ftol: float = 1e-9
    nelder_mead_init_step: float = 1e-2
    nelder_mead_xatol: float = 1e-4
    nelder_mead_fatol: float = 1e-5
    pyramid_levels: int = 2
    min_pyramid_size: int = 240
    trust_translation: float = 0.5
    trust_rotation_deg: float = 5.0
    orientation_classes: bool = True
    min_class_points: int = 5000
    structure_weight: float = 0.0
    parallel: bool = True
    max_pairs: int | None = None
    points_per_pixel: float | None = 0.25
    min_sampled_points: int = 50_000
    job_points: int | None = 1_000_000
    cloud_memory_mb: float | None = 512.0
    min_visible_points: int = 100
    intrinsics: str | None = None
    intrinsics_focal_range: float = 0.05
    intrinsics_center_range: float = 25.0
    intrinsics_max_focal_bound: float = 0.005
    intrinsics_max_center_bound: float = 2.0

    def __post_init__(self):
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(
                f"optimizer must be one of {', '.join(OPTIMIZERS)}, got {self.optimizer!r}"
            )
        for name in (
            "max_translation",
            "max_rotation_deg",
            "depth_margin",
            "trust_translation",
            "trust_rotation_deg",
            "structure_weight",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0")
        if not self.trust_rotation_deg < 180:
            raise ValueError(f"trust_rotation_deg must be < 180, got {self.trust_rotation_deg}")
        if not (self.nelder_mead_xatol > 0 and self.nelder_mead_fatol > 0):
            raise ValueError("nelder_mead_xatol and nelder_mead_fatol must be > 0")
        if not self.lbfgs_ftol > 0:
            raise ValueError(f"lbfgs_ftol must be > 0, got {self.lbfgs_ftol}")
        if self.max_outer < 1 or self.max_inner < 1:
            raise ValueError("max_outer and max_inner must be >= 1")
        if not 0 <= self.pyramid_levels <= 5:
            raise ValueError(f"pyramid_levels must be in [0, 5], got {self.pyramid_levels}")
        if self.min_class_points < 1:
            raise ValueError(f"min_class_points must be >= 1, got {self.min_class_points}")
        if self.max_pairs is not None and self.max_pairs < 1:
            raise ValueError(f"max_pairs must be >= 1, got {self.max_pairs}")
        if self.min_visible_points < 1:
            raise ValueError(f"min_visible_points must be >= 1, got {self.min_visible_points}")
        if self.min_sampled_points < 1:
            raise ValueError(f"min_sampled_points must be >= 1, got {self.min_sampled_points}")
        if self.cloud_memory_mb is not None and not self.cloud_memory_mb >= 0:
            raise ValueError(f"cloud_memory_mb must be >= 0 or None, got {self.cloud_memory_mb}")
        if self.job_points is not None and self.job_points < 1:
            raise ValueError(f"job_points must be >= 1 or None, got {self.job_points}")
        if self.points_per_pixel is not None and not self.points_per_pixel > 0:
            raise ValueError(f"points_per_pixel must be > 0 or None, got {self.points_per_pixel}")
        if self.cost not in COSTS:
            raise ValueError(f"cost must be one of {', '.join(COSTS)}, got {self.cost!r}")
        if self.region_points < 1:
            raise ValueError(f"region_points must be >= 1, got {self.region_points}")
        if self.bins < 2:
            raise ValueError(f"bins must be >= 2, got {self.bins}")
        if self.intrinsics is not None:
            if self.intrinsics not in INTRINSICS_MODES:
                raise ValueError(
                    f"intrinsics must be one of {', '.join(INTRINSICS_MODES)} or None, "
                    f"got {self.intrinsics!r}"
                )
            if self.optimizer == "nelder_mead":
                raise ValueError(
                    "intrinsics are refined with the smooth NID's gradient: optimizer hybrid or "
                    "lbfgs, not nelder_mead"
                )
        for name in (
            "intrinsics_focal_range",
            "intrinsics_center_range",
            "intrinsics_max_focal_bound",
            "intrinsics_max_center_bound",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0")
        if self.min_pyramid_size < 16:
            raise ValueError(f"min_pyramid_size must be >= 16, got {self.min_pyramid_size}")
