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

import importlib

_EXPORTS = {
    "MatchConfig": "config",
    "PairMatches": "find",
    "find_correspondences": "find",
    "reference_matches": "find",
    "Correspondences": "correspondences",
    "correspondences_from_matches": "correspondences",
    "lift_lidar_pixels": "correspondences",
    "lift_matches": "correspondences",
    "pool_correspondences": "correspondences",
    "MultiViewMatches": "multiview",
    "ViewMatches": "multiview",
    "match_views": "multiview",
    "match_images": "match",
    "available_matchers": "match",
    "camera_scale_for": "match",
    "pixels_per_radian": "match",
    "resolve_matcher": "match",
    "rotate_image": "match",
    "unrotate_points": "match",
    "MATCHERS": "match",
    "Matches": "matches",
    "read_matches_json": "matches",
    "write_matches_json": "matches",
    "draw_matches": "draw",
    "LEARNED_MATCHERS": "onnx_matcher",
    "LEARNED_MATCHER_NAMES": "config",
    "OnnxMatcher": "onnx_matcher",
    "default_model_dir": "onnx_matcher",
    "model_dir": "onnx_matcher",
    "exported_matchers": "onnx_matcher",
    "NORMALIZATIONS": "normalize",
    "normalize_image": "normalize",
    "fill_holes": "normalize",
    "LidarView": "views",
    "heading_rotations": "views",
    "prior_rotations": "views",
    "render_view": "views",
    "scaled_camera": "views",
    "view_scale": "views",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"nbcalib.matching.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'nbcalib.matching' has no attribute {name!r}")


def __dir__():
    return __all__
