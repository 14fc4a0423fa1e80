"""The initial guess of ``T_camera_lidar`` from 2D-3D correspondences (paper section III-D).

The correspondences come from matching (:mod:`nbcalib.matching`) or from hand-picked pairs.

- :mod:`~nbcalib.initial_guess.config`: :class:`InitialGuessConfig`, the stage's settings;
- :mod:`~nbcalib.initial_guess.ransac`: rotation-only RANSAC (Algorithm 1), numba, parallel and
  deterministic for a seed;
- :mod:`~nbcalib.initial_guess.lm`: Levenberg-Marquardt with a Cauchy kernel on the
  reprojection error (Eq. 1), analytic Jacobians;
- :mod:`~nbcalib.initial_guess.estimate`: both together, a polish of the winner (translation
  RANSAC, inlier refits), with inliers, RMS and a success flag;
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

import importlib

_EXPORTS = {
    "InitialGuessConfig": "config",
    "MIN_CORRESPONDENCES": "estimate",
    "InitialGuess": "estimate",
    "estimate_initial_guess": "estimate",
    "translation_from_bearings": "estimate",
    "translation_ransac": "estimate",
    "LMResult": "lm",
    "cauchy_loss": "lm",
    "refine_pose_lm": "lm",
    "reprojection_errors": "lm",
    "reprojection_residuals": "lm",
    "ManualCorrespondence": "manual",
    "read_manual_correspondences": "manual",
    "resolve_manual_correspondences": "manual",
    "write_manual_correspondences": "manual",
    "RotationRansacResult": "ransac",
    "estimate_rotation_ransac": "ransac",
    "usable_correspondences": "ransac",
    "SyntheticCorrespondences": "synthetic",
    "synthetic_correspondences": "synthetic",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"nbcalib.initial_guess.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'nbcalib.initial_guess' has no attribute {name!r}")


def __dir__():
    return __all__
