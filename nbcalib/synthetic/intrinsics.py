"""Intrinsics handed to the calibrator that differ from the camera that rendered the image.

Real intrinsics are often a little off (a quick checkerboard, a datasheet, a fisheye fitted at
another temperature), and a target-less calibrator trusts what it is given. In the lab of
issue 47, ``nbcalib synth --given-focal-scale 1.015 --given-center-shift 5,-3`` renders the
image with the true camera and writes :meth:`GivenIntrinsics.apply` of it as the camera the
user has (``camera.yaml``, the bags' ``camera_info``); ``ground_truth.json`` keeps both.

The offset is the same for every model with a focal length and a principal point (pinhole,
plumb_bob, rational_polynomial, fisheye, atan, omnidir; ``xi`` of omnidir is left as it is):
``fx, fy`` times ``focal_scale``, ``cx, cy`` plus ``center_shift`` pixels, every distortion
coefficient times ``distortion_scale``. An equirectangular camera's intrinsics are its image
size: it has nothing to get wrong, and is refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nbcalib.camera import CameraModel, offset_intrinsics

__all__ = ["GivenIntrinsics"]


@dataclass(frozen=True)
class GivenIntrinsics:
    """How the intrinsics the calibrator is given differ from the true ones.

    Attributes
    ----------
    focal_scale : float
        ``fx`` and ``fy`` given = true times this (> 0; 1: exact).
    center_shift : tuple of float
        ``(dx, dy)`` pixels added to the true ``cx, cy``.
    distortion_scale : float
        Every distortion coefficient given = true times this (1: exact).
    """

    focal_scale: float = 1.0
    center_shift: tuple[float, float] = (0.0, 0.0)
    distortion_scale: float = 1.0

    def __post_init__(self):
        shift = tuple(float(v) for v in self.center_shift)
        object.__setattr__(self, "center_shift", shift)
        values = (self.focal_scale, *shift, self.distortion_scale)
        if len(shift) != 2 or not all(math.isfinite(v) for v in values):
            raise ValueError(f"expected finite numbers and a shift (dx, dy), got {self}")
        if not self.focal_scale > 0:
            raise ValueError(f"focal_scale must be > 0, got {self.focal_scale}")

    @property
    def exact(self) -> bool:
        """The given intrinsics are the true ones."""
        return self == GivenIntrinsics()

    @staticmethod
    def check(model: str) -> None:
        """Refuse a camera model whose intrinsics cannot be given wrong (ValueError)."""
        if model == "equirectangular":
            raise ValueError(
                "an equirectangular camera's intrinsics are its image size: nothing to offset"
            )

    def apply(self, camera: CameraModel) -> CameraModel:
        """The camera the user is given, from the ``camera`` that rendered the image."""
        self.check(camera.model)
        return offset_intrinsics(
            camera,
            focal_scale=self.focal_scale,
            center_shift=self.center_shift,
            distortion_scale=self.distortion_scale,
        )

    def to_dict(self) -> dict:
        """``{"focal_scale", "center_shift", "distortion_scale"}``, JSON-ready."""
        return {
            "focal_scale": float(self.focal_scale),
            "center_shift": [float(v) for v in self.center_shift],
            "distortion_scale": float(self.distortion_scale),
        }
