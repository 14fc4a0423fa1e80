"""Image normalisations that narrow the gap between LiDAR intensity and camera brightness.

A LiDAR image shows reflectivity, a camera image shows reflected sunlight: the same edges, but
often with the opposite sign (dark tarmac is bright paint for the LiDAR, and the other way
round) and with different textures. Learned matchers trained on photographs find no correct
match on an intensity-inverted copy of an image, and hundreds on its gradient magnitude. These
functions turn both images into something more alike before matching; docs/BENCHMARKS.md
("Matching") measures which choice works.

- ``none``: the image as given.
- ``equalize``: global histogram equalisation (what preprocessing stores already).
- ``clahe``: contrast-limited adaptive histogram equalisation.
- ``invert``: ``255 - image`` (a control: sign flips are what breaks the matchers).
- ``gradient``: the magnitude of the Sobel gradient of the slightly blurred image, scaled so
  that its 99th percentile is 255: the sign of an edge no longer matters.

LiDAR images are sparse: :func:`fill_holes` first gives empty pixels the value of the nearest
filled pixel within a small radius, so that holes do not become edges.
"""

from __future__ import annotations

import numpy as np

from nbcalib.matching.config import NORMALIZATIONS

__all__ = ["NORMALIZATIONS", "fill_holes", "normalize_image"]


def _check(image) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"image must be (H, W) uint8, got {image.dtype} {image.shape}")
    return np.ascontiguousarray(image)


def fill_holes(image: np.ndarray, filled: np.ndarray | None = None, *, radius: int = 2):
    """Give each empty pixel the value of a filled pixel at most ``radius`` pixels away.

    Repeated 3 x 3 grey dilations, each writing only into pixels still empty: an empty pixel
    takes the largest value among the filled pixels of its neighbourhood, one ring at a time.
    Pixels farther than ``radius`` from any filled pixel stay 0.

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8
        A LiDAR image.
    filled : ndarray of shape (H, W), bool, optional
        Which pixels show a point (default: ``image > 0``, the stored LiDAR images' convention).
    radius : int, optional
        How far to fill, pixels (Chebyshev distance).

    Returns
    -------
    ndarray of shape (H, W), uint8
    """
    import cv2

    image = _check(image)
    known = image > 0 if filled is None else np.asarray(filled, dtype=bool)
    if known.shape != image.shape:
        raise ValueError(f"filled must have shape {image.shape}, got {known.shape}")
    if radius < 0:
        raise ValueError(f"radius must be >= 0, got {radius}")
    out = np.where(known, image, 0).astype(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(int(radius)):
        if known.all():
            break
        grown = cv2.dilate(out, kernel)
        reached = cv2.dilate(known.astype(np.uint8), kernel).astype(bool)
        new = reached & ~known
        out[new] = grown[new]
        known = known | new
    return out


def normalize_image(image: np.ndarray, method: str = "none") -> np.ndarray:
    """One of :data:`NORMALIZATIONS` (module docstring).

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8
        Grey image.
    method : str
        Normalisation name.

    Returns
    -------
    ndarray of shape (H, W), uint8
    """
    import cv2

    image = _check(image)
    if method == "none":
        return image
    if method == "equalize":
        return cv2.equalizeHist(image)
    if method == "clahe":
        return cv2.createCLAHE(clipLimit=2.0, tileGridSize=(8, 8)).apply(image)
    if method == "invert":
        return (255 - image).astype(np.uint8)
    if method == "gradient":
        smooth = cv2.GaussianBlur(image.astype(np.float32), (0, 0), 1.0)
        gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
        magnitude = np.sqrt(gx * gx + gy * gy)
        top = float(np.percentile(magnitude, 99.0))
        if top <= 0.0:
            return np.zeros_like(image)
        return np.clip(magnitude * (255.0 / top), 0, 255).astype(np.uint8)
    raise ValueError(f"unknown normalisation {method!r}; one of {NORMALIZATIONS}")
