"""nbcalib: target-less, single-shot, automatic LiDAR-camera extrinsic calibration.

Importing the package is cheap: submodules (and numba) load on first use, and no kernel is
compiled until it is first called.

The pipeline and where each stage of the method lives:

- the pipeline: :class:`nbcalib.pipeline.Calibrator` (``run()`` reads like the paper's method
  section), its config tree :mod:`nbcalib.config`, the products it hands from stage to stage
  :mod:`nbcalib.products`, the work directory that saves them :mod:`nbcalib.workdir`
- preprocessing (III-C): inputs, dense clouds, equalisation, the virtual camera's LiDAR images:
  :mod:`nbcalib.preprocess`; the LiDAR odometry (continuous-time ICP, deskewing) for a moving
  LiDAR: :mod:`nbcalib.odometry`
- matching (III-D): camera image x camera-shaped LiDAR views -> 2D-3D correspondences:
  :mod:`nbcalib.matching`
- initial guess (III-D): rotation-only RANSAC, robust LM, manual picks: :mod:`nbcalib.initial_guess`
- fine registration (III-E): hidden-point removal, NID: :mod:`nbcalib.registration`
- quality (uncertainty, verdict, HTML report): :mod:`nbcalib.report`
- foundations: :mod:`nbcalib.transforms` (``docs/conventions.md``), :mod:`nbcalib.camera`,
  files :mod:`nbcalib.io`, numba kernels :mod:`nbcalib.kernels` with slow references in
  :mod:`nbcalib.reference`, synthetic data :mod:`nbcalib.synthetic`
- from Python: :func:`nbcalib.calibrate` (:mod:`nbcalib.api`); from the shell: ``nbcalib run``,
  ``nbcalib demo`` and one command per stage (:mod:`nbcalib.commands`)
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_SUBMODULES = {
    "camera",
    "transforms",
    "reference",
    "io",
    "kernels",
    "cli",
    "metrics",
    "preprocess",
    "odometry",
    "registration",
    "api",
    "config",
    "pipeline",
    "products",
    "workdir",
    "matching",
    "initial_guess",
    "report",
    "synthetic",
}
_EXPORTS = {
    "create_camera": "camera",
    "CameraModel": "camera",
    "calibrate": "api",
    "CalibrationResult": "api",
    "Calibrator": "pipeline",
    "CalibrationConfig": "config",
}

__all__ = sorted([*_SUBMODULES, *_EXPORTS, "__version__"])


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f"nbcalib.{name}")
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"nbcalib.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'nbcalib' has no attribute {name!r}")


def __dir__():
    return __all__
