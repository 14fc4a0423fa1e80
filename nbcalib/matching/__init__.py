"""Keypoint matching between camera images and LiDAR intensity images (paper section III-D).

- :func:`find_correspondences`: the matching stage, one pair's 2D-3D correspondences
  (:mod:`~nbcalib.matching.find`), with its settings :class:`MatchConfig`
  (:mod:`~nbcalib.matching.config`);
- :mod:`~nbcalib.matching.multiview`: matches against camera-shaped LiDAR views at several
  headings (or around a prior), the view with the best RANSAC support kept;
- :mod:`~nbcalib.matching.correspondences`: keypoint matches lifted to 3-D points through an
  index map, pooled over pairs;
- :func:`match_images`: the public entry point; learned matchers through onnxruntime, or the
  SIFT fallback (:mod:`~nbcalib.matching.match`).
- :func:`available_matchers`: what can run here, best first.
- :class:`Matches`, :func:`read_matches_json`, :func:`write_matches_json`: the
  ``<name>_matches.json`` file of the reference toolbox (:mod:`~nbcalib.matching.matches`).
- :func:`draw_matches`: the side-by-side picture (:mod:`~nbcalib.matching.draw`).
- :mod:`~nbcalib.matching.onnx_export`: torch -> ONNX (``nbcalib models export``; needs torch).
- :mod:`~nbcalib.matching.normalize`: image normalisations across the modality gap.
- :mod:`~nbcalib.matching.views`: camera-shaped LiDAR views (the real camera's model at the
  LiDAR's resolution, at several headings), rendered for :func:`match_views`.

Importing this package is cheap: OpenCV, onnxruntime and torch load on first use.

Example
-------
>>> from nbcalib.matching import match_images                    # doctest: +SKIP
>>> m = match_images(camera_grey, lidar_intensity, matcher="auto")  # doctest: +SKIP
>>> uv_camera, uv_lidar, confidence = m.matched()                 # doctest: +SKIP
"""

from __future__ import annotations

from nbcalib._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    "nbcalib.matching",
    {
        "config": ("MatchConfig", "LEARNED_MATCHER_NAMES"),
        "find": ("PairMatches", "find_correspondences", "reference_matches"),
        "correspondences": (
            "Correspondences",
            "correspondences_from_matches",
            "lift_lidar_pixels",
            "lift_matches",
            "pool_correspondences",
        ),
        "multiview": ("MultiViewMatches", "ViewMatches", "match_views"),
        "match": (
            "match_images",
            "available_matchers",
            "camera_scale_for",
            "pixels_per_radian",
            "resolve_matcher",
            "rotate_image",
            "unrotate_points",
            "MATCHERS",
        ),
        "matches": ("Matches", "read_matches_json", "write_matches_json"),
        "draw": ("draw_matches",),
        "onnx_matcher": (
            "LEARNED_MATCHERS",
            "OnnxMatcher",
            "default_model_dir",
            "model_dir",
            "exported_matchers",
        ),
        "normalize": ("NORMALIZATIONS", "normalize_image", "fill_holes"),
        "views": (
            "LidarView",
            "heading_rotations",
            "prior_rotations",
            "render_view",
            "scaled_camera",
            "view_scale",
        ),
    },
)
