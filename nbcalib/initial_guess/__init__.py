"""The initial guess of ``T_camera_lidar`` from 2D-3D correspondences (paper section III-D).

- :mod:`~nbcalib.initial_guess.correspondences`: keypoint matches lifted to 3-D points through
  the LiDAR index map, pooled over pairs;
- :mod:`~nbcalib.initial_guess.ransac`: rotation-only RANSAC (Algorithm 1), numba, parallel and
  deterministic for a seed;
- :mod:`~nbcalib.initial_guess.lm`: Levenberg-Marquardt with a Cauchy kernel on the
  reprojection error (Eq. 1), analytic Jacobians;
- :mod:`~nbcalib.initial_guess.multiview`: matches against camera-shaped LiDAR views at several
  headings (or around a prior), the view with the best RANSAC support kept;
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

from nbcalib.initial_guess.correspondences import (
    Correspondences,
    correspondences_from_matches,
    lift_lidar_pixels,
    lift_matches,
    pool_correspondences,
)
from nbcalib.initial_guess.estimate import (
    MIN_CORRESPONDENCES,
    InitialGuess,
    estimate_initial_guess,
    translation_from_bearings,
    translation_ransac,
)
from nbcalib.initial_guess.lm import (
    LMResult,
    cauchy_loss,
    refine_pose_lm,
    reprojection_errors,
    reprojection_residuals,
)
from nbcalib.initial_guess.manual import (
    ManualCorrespondence,
    read_manual_correspondences,
    resolve_manual_correspondences,
    write_manual_correspondences,
)
from nbcalib.initial_guess.multiview import MultiViewMatches, ViewMatches, match_views
from nbcalib.initial_guess.ransac import (
    RotationRansacResult,
    estimate_rotation_ransac,
    usable_correspondences,
)
from nbcalib.initial_guess.synthetic import SyntheticCorrespondences, synthetic_correspondences

__all__ = [
    "MIN_CORRESPONDENCES",
    "Correspondences",
    "InitialGuess",
    "LMResult",
    "ManualCorrespondence",
    "MultiViewMatches",
    "RotationRansacResult",
    "SyntheticCorrespondences",
    "ViewMatches",
    "cauchy_loss",
    "correspondences_from_matches",
    "estimate_initial_guess",
    "estimate_rotation_ransac",
    "lift_lidar_pixels",
    "lift_matches",
    "match_views",
    "pool_correspondences",
    "read_manual_correspondences",
    "refine_pose_lm",
    "reprojection_errors",
    "reprojection_residuals",
    "resolve_manual_correspondences",
    "synthetic_correspondences",
    "translation_from_bearings",
    "translation_ransac",
    "usable_correspondences",
    "write_manual_correspondences",
]
