"""The LiDAR index map as the reference toolbox stores it: int32 in a 4-channel 8-bit PNG.

``<name>_lidar_indices.png`` holds, per pixel of the LiDAR image, the row of the point it shows
in ``<name>.ply`` (-1 where empty), as the raw little-endian bytes of each int32 read as B, G,
R, A. It decodes with ``cv2.imread(path, cv2.IMREAD_UNCHANGED).view('<i4')[..., 0]``
(:func:`decode_index_map`); an empty pixel is -1, all four bytes 0xFF.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbcalib.errors import InputError

__all__ = ["decode_index_map", "encode_index_map", "read_index_map", "write_index_map"]

_INDEX_DTYPE = np.dtype("<i4")


def encode_index_map(index) -> np.ndarray:
    """Bytes of an int32 index map as an (H, W, 4) uint8 image (OpenCV's B, G, R, A order).

    Parameters
    ----------
    index : array_like of shape (H, W), integer
        Point indices, -1 where empty; every value must fit int32.

    Returns
    -------
    ndarray of shape (H, W, 4), uint8
        Channel ``k`` holds byte ``k`` of the little-endian int32; pass it to ``cv2.imwrite`` /
        ``cv2.imencode`` as is (OpenCV treats 4 channels as BGRA).
    """
    index = np.asarray(index)
    if index.ndim != 2 or index.dtype.kind not in "iu":
        raise ValueError(f"index must be an (H, W) integer array, got {index.dtype} {index.shape}")
    info = np.iinfo(np.int32)
    if index.size and (index.min() < -1 or index.max() > info.max):
        raise ValueError("index values must be -1 or in [0, 2**31 - 1]")
    little = np.ascontiguousarray(index, dtype=_INDEX_DTYPE)
    return little.view(np.uint8).reshape(*index.shape, 4)


def decode_index_map(image) -> np.ndarray:
    """Inverse of :func:`encode_index_map`: (H, W, 4) uint8 (B, G, R, A) to (H, W) int32."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 4 or image.dtype != np.uint8:
        raise ValueError(f"expected an (H, W, 4) uint8 image, got {image.dtype} {image.shape}")
    values = np.ascontiguousarray(image).view(_INDEX_DTYPE)[..., 0]
    return values.astype(np.int32)


def write_index_map(path, index) -> None:
    """Write an index map as the reference's 4-channel 8-bit PNG, atomically."""
    import cv2

    from nbcalib.io._files import write_bytes_atomic

    ok, encoded = cv2.imencode(".png", encode_index_map(index))
    if not ok:  # pragma: no cover - OpenCV encodes every (H, W, 4) uint8 image
        raise RuntimeError("OpenCV could not encode the index map as PNG")
    write_bytes_atomic(path, [encoded.tobytes()])


def read_index_map(path) -> np.ndarray:
    """Read ``<name>_lidar_indices.png``.

    Returns
    -------
    ndarray of shape (H, W), int32
        Point indices, -1 where empty.

    Raises
    ------
    InputError
        Missing or undecodable file, not a 4-channel 8-bit image, or values below -1.
    """
    import cv2

    path = Path(path)
    image = cv2.imdecode(_read_file_bytes(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError("cannot decode as an image (corrupt or unknown format)", path)
    if image.ndim != 3 or image.shape[2] != 4 or image.dtype != np.uint8:
        channels = 1 if image.ndim == 2 else image.shape[2]
        raise InputError(
            f"not an index map: expected a 4-channel 8-bit PNG, got {channels} channel(s) of "
            f"{image.dtype}",
            path,
        )
    index = decode_index_map(image)
    if index.size and index.min() < -1:
        raise InputError(f"not an index map: holds the value {index.min()} (< -1)", path)
    return index


def _read_file_bytes(path: Path) -> np.ndarray:
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path) from None
    if data.size == 0:
        raise InputError("empty file", path)
    return data
