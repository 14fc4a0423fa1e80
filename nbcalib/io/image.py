"""Camera image files: read as stored (8 or 16 bit), grey or colour, and write PNG atomically.

Colour order in memory is **RGB** everywhere in nbcalib (readers convert from OpenCV's BGR,
:func:`write_png` converts back). Colour becomes grey with OpenCV's weights
(``0.299 R + 0.587 G + 0.114 B``, rounded, as ``cv2.cvtColor``), which is what the reference gets
from ``cv_bridge`` with ``mono8``. Computations use :func:`to_float_grey`: float64 in [0, 1].
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbcalib.errors import InputError

#: Suffixes OpenCV reads that nbcalib accepts for camera images.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")


def read_image(path, *, grey: bool = True) -> np.ndarray:
    """Read an image file with its stored bit depth.

    Parameters
    ----------
    path : str or os.PathLike
        Any format OpenCV decodes (PNG, JPEG, TIFF, ...), 8 or 16 bit.
    grey : bool
        Convert colour to grey with OpenCV's weights (alpha is ignored).

    Returns
    -------
    ndarray of shape (H, W) or (H, W, 3), uint8 or uint16
        Grey, or colour in **RGB** order when ``grey=False`` and the file is colour (alpha
        dropped). A grey file stays (H, W) either way.

    Raises
    ------
    InputError
        Missing, empty or undecodable file, or a bit depth other than 8/16; names the file.
    """
    import cv2

    path = Path(path)
    try:
        data = np.fromfile(path, dtype=np.uint8)  # not cv2.imread: it ignores errors silently
    except FileNotFoundError:
        raise InputError("file not found", path=path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected an image file", path=path) from None
    if data.size == 0:
        raise InputError("empty file", path=path)
    try:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error:  # a corrupt header OpenCV refuses (sizes beyond its limits)
        image = None
    if image is None:
        raise InputError("cannot decode as an image (corrupt or unknown format)", path=path)
    if image.dtype not in (np.uint8, np.uint16):
        raise InputError(f"unsupported pixel type {image.dtype}; expected 8 or 16 bit", path=path)
    return _from_bgr(image, grey=grey)


def _from_bgr(image: np.ndarray, *, grey: bool) -> np.ndarray:
    """OpenCV channel order (grey, BGR, BGRA) to nbcalib's (grey or RGB)."""
    import cv2

    if image.ndim == 3 and image.shape[2] == 1:
        image = image[:, :, 0]
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    code = {
        (3, True): cv2.COLOR_BGR2GRAY,
        (4, True): cv2.COLOR_BGRA2GRAY,
        (3, False): cv2.COLOR_BGR2RGB,
        (4, False): cv2.COLOR_BGRA2RGB,
    }[(image.shape[2], grey)]
    return cv2.cvtColor(image, code)


def rgb_to_grey(image: np.ndarray) -> np.ndarray:
    """Grey from an RGB (or RGBA) image with OpenCV's weights; grey input is returned as is.

    Parameters
    ----------
    image : ndarray of shape (H, W), (H, W, 3) or (H, W, 4), uint8 or uint16
        RGB order.

    Returns
    -------
    ndarray of shape (H, W), same dtype
    """
    import cv2

    image = np.asarray(image)
    if image.ndim == 2:
        return image
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got {image.shape}")
    code = cv2.COLOR_RGB2GRAY if image.shape[2] == 3 else cv2.COLOR_RGBA2GRAY
    return cv2.cvtColor(np.ascontiguousarray(image), code)


def to_float_grey(image: np.ndarray) -> np.ndarray:
    """Grey float image in [0, 1] for computations.

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        uint8 (divided by 255), uint16 (divided by 65535), or float (taken as already in [0, 1]);
        colour input is RGB and is made grey first with OpenCV's weights (:func:`rgb_to_grey`).

    Returns
    -------
    ndarray of shape (H, W), float64
    """
    image = np.asarray(image)
    if image.ndim == 3:
        if image.dtype.kind == "f":
            raise ValueError("colour float images are not supported; convert to grey first")
        image = rgb_to_grey(image)
    if image.ndim != 2:
        raise ValueError(f"expected an (H, W) or (H, W, 3) image, got {image.shape}")
    if image.dtype == np.uint8:
        return image.astype(np.float64) / 255.0
    if image.dtype == np.uint16:
        return image.astype(np.float64) / 65535.0
    if image.dtype.kind == "f":
        return image.astype(np.float64)
    raise ValueError(f"expected a uint8, uint16 or float image, got {image.dtype}")


def write_png(path, image: np.ndarray) -> None:
    """Write a PNG atomically (temporary file, then rename).

    Parameters
    ----------
    path : str or os.PathLike
        Target file (replaced if it exists).
    image : ndarray of shape (H, W), (H, W, 3) or (H, W, 4), uint8 or uint16
        Grey, **RGB** or RGBA (converted to OpenCV's BGR order for the file).
    """
    import cv2

    from nbcalib.io._files import write_bytes_atomic

    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"PNG images must be uint8 or uint16, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGBA2BGRA)
    elif image.ndim != 2:
        raise ValueError(f"expected an (H, W), (H, W, 3) or (H, W, 4) image, got {image.shape}")
    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(image))
    if not ok:  # pragma: no cover - OpenCV encodes every uint8/uint16 image as PNG
        raise RuntimeError(f"OpenCV could not encode a {image.shape} {image.dtype} image as PNG")
    write_bytes_atomic(path, [encoded.tobytes()])
