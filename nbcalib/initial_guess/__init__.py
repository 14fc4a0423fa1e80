"""The initial guess of ``T_camera_lidar`` from 2D-3D correspondences (paper section III-D).

The correspondences come from matching (:mod:`nbcalib.matching`) or from hand-picked pairs.

- :mod:`~nbcalib.initial_guess.config`: :class:`InitialGuessConfig`, the stage's settings;
- :mod:`~nbcalib.initial_guess.ransac`: rotation-only RANSAC (Algorithm 1), numba, parallel and
  deterministic for a seed;
- :mod:`~nbcalib.initial_guess.lm`: Levenberg-Marquardt with a Cauchy kernel on the
  reprojection error (Eq. 1), analytic Jacobians;
- :mod:`~nbcalib.initial_guess.estimate`: both together, a polish of the winner (translation
  RANSAC, inlier refits), with inliers, RMS and a success flag;
- :mod:`~nbcalib.initial_guess.success`: the guess and its success test (inliers, rival poses,
  precision); :mod:`~nbcalib.initial_guess.translation`: translations for a known rotation;
- :mod:`~nbcalib.initial_guess.manual` and :mod:`~nbcalib.initial_guess.picker`: hand-picked
  correspondences (file format, interactive picker);
- :mod:`~nbcalib.initial_guess.synthetic`: correspondences with known answer.

Example
-------
>>> from nbcalib.camera import example_camera
>>> from nbcalib.initial_guess import estimate_initial_guess, synthetic_correspondences
>>> from nbcalib.synthetic import default_T_camera_lidar
>>> camera = example_camera("fisheye")
>>> truth = default_T_camera_lidar("spinning", 0)
>>> c = synthetic_correspondences(camera, truth, 0, n_inliers=100, outlier_fraction=0.8)
>>> guess = estimate_initial_guess(camera, c.uv_camera, c.points_lidar)
>>> guess.success, guess.n_inliers                                   # doctest: +SKIP
(True, 100)
"""

from __future__ import annotations

from nbcalib._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    "nbcalib.initial_guess",
    {
        "config": ("InitialGuessConfig",),
        "estimate": (
            "MIN_CORRESPONDENCES",
            "InitialGuess",
            "estimate_initial_guess",
            "pose_uncertainty",
            "translation_from_bearings",
            "translation_ransac",
        ),
        "lm": (
            "LMResult",
            "cauchy_loss",
            "refine_pose_lm",
            "reprojection_errors",
            "reprojection_residuals",
        ),
        "manual": (
            "ManualCorrespondence",
            "read_manual_correspondences",
            "resolve_manual_correspondences",
            "write_manual_correspondences",
        ),
        "ransac": ("RotationRansacResult", "estimate_rotation_ransac", "usable_correspondences"),
        "synthetic": ("SyntheticCorrespondences", "synthetic_correspondences"),
    },
)
