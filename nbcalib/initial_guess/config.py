"""Settings of the initial guess (paper section III-D), importable without numba.

:class:`InitialGuessConfig` is the ``initial_guess`` section of the pipeline's config
(:class:`nbcalib.config.CalibrationConfig`);
:func:`nbcalib.initial_guess.estimate.estimate_initial_guess` takes its defaults from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["INITIAL_TRANSLATIONS", "InitialGuessConfig"]

#: Values of :attr:`InitialGuessConfig.initial_translation`.
INITIAL_TRANSLATIONS = ("bearing", "zero")


@dataclass(frozen=True)
class InitialGuessConfig:
    """Rotation-only RANSAC, robust LM and the success test of the initial guess.

    ``candidates=1, local_optimization=False, initial_translation="zero", polish=False`` is the
    reference toolbox's procedure (:func:`~nbcalib.initial_guess.estimate.
    estimate_initial_guess` explains each step).

    Attributes
    ----------
    ransac_iterations : int
        Rotation-only RANSAC hypotheses (reference: 8192).
    ransac_threshold : float
        Inlier threshold on the reprojection error, pixels (the reference's effective 5 px);
        also the threshold that scores the camera-shaped views of matching.
    robust_kernel_width : float
        Cauchy kernel width of the LM refinement, pixels (reference: 10).
    confidence_weights : bool
        Weigh each correspondence by the matcher's confidence in the LM cost (False: all equal,
        paper Eq. 1 and the reference).
    min_inliers : int
        Final inliers an automatic guess needs to count as a success.
    min_manual_inliers : int
        The same for hand-picked correspondences.
    min_distinctiveness : float
        How many times more correspondences the final pose must explain than the best pose
        rotated more than 5 degrees from it explains among those the final pose leaves out,
        for success (0: no such test).
    min_shared_distinctiveness : float
        The same against what that rival explains among all correspondences, the final pose's
        inliers included (0: no such test). Wrong matches on real frames passed the first
        test alone (27 against 12, a guess 153 degrees off) but not this one (27 against 20);
        correct guesses had 1.7-3.3x (docs/BENCHMARKS.md, "Initial guess on real data").
    precision_scale : float
        Success needs the guess's error bounds from its inliers' reprojections
        (:func:`nbcalib.initial_guess.estimate.pose_uncertainty`, 95 %) times this within
        ``max_start_translation`` and ``max_start_rotation_deg`` (0: no such test). The bounds
        see the keypoints' noise, not the error the matches share (a rendered LiDAR image
        against a photograph): automatic guesses were 2-6x, once 16x, their bound off
        (docs/BENCHMARKS.md 11). Not applied to hand-picked correspondences, whose few picks
        make wide bounds without a shared error.
    max_start_translation, max_start_rotation_deg : float
        How far a start may be from the truth for fine registration to find it: the paper's
        0.5 m and 1 deg.
    candidates : int
        RANSAC rotations refined by LM (near-field parallax, which rotation-only RANSAC
        ignores, can make the true rotation only the second or third best).
    local_optimization : bool
        Fit the hypothesis's inliers before all correspondences, and repeat while the inlier
        set changes.
    initial_translation : {"bearing", "zero"}
        LM start translation: from the inliers' bearings, or zero (reference).
    max_initial_translation : float
        A ``"bearing"`` start translation longer than this is replaced by zero, metres.
    max_lm_iterations : int
        Step limit of each LM run.
    polish : bool
        Polish the winner: translation RANSAC, then LM refits of its inliers.
    polish_kernel_width : float
        Cauchy kernel width of the polish refits, pixels.
    translation_iterations : int
        Hypotheses of each translation RANSAC (polish, and the distinctiveness test).
    parallel : bool
        Run RANSAC on all threads (same result for a seed).
    """

    ransac_iterations: int = 8192
    ransac_threshold: float = 5.0
    robust_kernel_width: float = 10.0
    confidence_weights: bool = True
    min_inliers: int = 10
    min_manual_inliers: int = 3
    min_distinctiveness: float = 2.0
    min_shared_distinctiveness: float = 1.5
    precision_scale: float = 8.0
    max_start_translation: float = 0.5
    max_start_rotation_deg: float = 1.0
    candidates: int = 8
    local_optimization: bool = True
    initial_translation: str = "bearing"
    max_initial_translation: float = 2.0
    max_lm_iterations: int = 100
    polish: bool = True
    polish_kernel_width: float = 2.0
    translation_iterations: int = 1000
    parallel: bool = True

    def __post_init__(self):
        for name in ("ransac_threshold", "robust_kernel_width", "polish_kernel_width"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value}")
        for name in (
            "ransac_iterations",
            "min_inliers",
            "min_manual_inliers",
            "candidates",
            "max_lm_iterations",
            "translation_iterations",
        ):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {getattr(self, name)}")
        for name in ("min_distinctiveness", "min_shared_distinctiveness", "precision_scale"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be >= 0, got {value}")
        for name in ("max_start_translation", "max_start_rotation_deg"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.max_initial_translation >= 0:
            raise ValueError(
                f"max_initial_translation must be >= 0, got {self.max_initial_translation}"
            )
        if self.initial_translation not in INITIAL_TRANSLATIONS:
            raise ValueError(
                f"initial_translation must be one of {', '.join(INITIAL_TRANSLATIONS)}, "
                f"got {self.initial_translation!r}"
            )
