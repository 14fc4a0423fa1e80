"""nbcalib: target-less, single-shot, automatic LiDAR-camera extrinsic calibration.

Importing the package is cheap: submodules (and numba) load on first use, and no kernel is
compiled until it is first called.

Stages of the method and where they live:

- conventions and rigid transforms: :mod:`nbcalib.transforms` (``docs/conventions.md``)
- camera models: :mod:`nbcalib.camera`
- ``calib.json`` and other files: :mod:`nbcalib.io`
- dense clouds, LiDAR images, work directories: :mod:`nbcalib.preprocess`; the LiDAR
  odometry (continuous-time ICP, deskewing) for a moving LiDAR: :mod:`nbcalib.odometry`
- fine registration (NID): :mod:`nbcalib.registration`
- numba kernels: :mod:`nbcalib.kernels`, with slow references in :mod:`nbcalib.reference`
- the whole pipeline from Python: :func:`nbcalib.calibrate` (:mod:`nbcalib.api`); from the
  shell: ``nbcalib run`` and ``nbcalib demo``
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
}
_EXPORTS = {
    "create_camera": "camera",
    "CameraModel": "camera",
    "calibrate": "api",
    "CalibrationResult": "api",
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
