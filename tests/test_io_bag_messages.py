"""ROS image messages: every raw encoding, Bayer and YUV against OpenCV, compressed PNG/JPEG,
and bad messages."""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.bag_messages import decode_compressed_image, decode_image
from nbcalib.io.image import rgb_to_grey


def _image_msg(pixels: np.ndarray, encoding: str, *, pad=0, big=False):
    h = pixels.shape[0]
    rows = pixels.reshape(h, -1)
    dtype = rows.dtype.newbyteorder(">" if big else "<")
    raw = rows.astype(dtype).view(np.uint8).reshape(h, -1)
    raw = np.concatenate([raw, np.zeros((h, pad), np.uint8)], axis=1)
    return SimpleNamespace(
        height=h,
        width=pixels.shape[1],
        encoding=encoding,
        is_bigendian=int(big),
        step=raw.shape[1],
        data=raw.reshape(-1),
    )


def test_image_encodings(rng):
    rgb = rng.integers(0, 256, (6, 8, 3)).astype(np.uint8)
    grey = rgb_to_grey(rgb)
    alpha = rng.integers(0, 256, (6, 8, 1)).astype(np.uint8)
    cases = {
        "rgb8": rgb,
        "bgr8": rgb[..., ::-1],
        "8UC3": rgb[..., ::-1],
        "rgba8": np.concatenate([rgb, alpha], axis=2),
        "bgra8": np.concatenate([rgb[..., ::-1], alpha], axis=2),
    }
    for encoding, pixels in cases.items():
        msg = _image_msg(np.ascontiguousarray(pixels), encoding, pad=5)
        assert np.array_equal(decode_image(msg, grey=False), rgb), encoding
        assert np.array_equal(decode_image(msg), grey), encoding
    mono = rng.integers(0, 65536, (5, 7)).astype(np.uint16)
    for encoding in ("mono16", "16UC1"):
        for big in (False, True):
            out = decode_image(_image_msg(mono, encoding, pad=2, big=big))
            assert out.dtype == np.uint16 and np.array_equal(out, mono)
    assert np.array_equal(decode_image(_image_msg(grey, "mono8", pad=3)), grey)


def test_bayer_and_yuv_match_opencv(rng):
    raw = rng.integers(0, 256, (8, 10)).astype(np.uint8)
    out = decode_image(_image_msg(raw, "bayer_rggb8"), grey=False)
    assert np.array_equal(out, cv2.cvtColor(raw, cv2.COLOR_BayerBG2RGB))  # OpenCV's legacy name
    yuv = rng.integers(0, 256, (4, 6, 2)).astype(np.uint8)
    out = decode_image(_image_msg(yuv, "yuv422"))
    assert np.array_equal(out, cv2.cvtColor(yuv, cv2.COLOR_YUV2GRAY_UYVY))


def test_bad_image_messages():
    with pytest.raises(InputError, match="unsupported image encoding '32FC1'"):
        decode_image(_image_msg(np.zeros((2, 2), np.float32), "32FC1"), source="b.bag /depth")
    msg = _image_msg(np.zeros((4, 4), np.uint8), "mono8")
    msg.data = msg.data[:10]
    with pytest.raises(InputError, match="does not hold 4 x 4 pixels"):
        decode_image(msg)
    with pytest.raises(InputError, match="cannot decode compressed image"):
        decode_compressed_image(SimpleNamespace(format="jpeg", data=np.zeros(20, np.uint8)))


def test_compressed_image_png_16bit_and_jpeg(rng):
    mono16 = rng.integers(0, 65536, (9, 11)).astype(np.uint16)
    png = cv2.imencode(".png", mono16)[1].reshape(-1)
    assert np.array_equal(decode_compressed_image(SimpleNamespace(format="png", data=png)), mono16)
    rgb = np.zeros((16, 16, 3), np.uint8)
    rgb[..., 0] = 200  # red
    jpg = cv2.imencode(".jpg", rgb[..., ::-1])[1].reshape(-1)
    out = decode_compressed_image(SimpleNamespace(format="jpeg", data=jpg), grey=False)
    assert np.abs(out.astype(int) - rgb).max() <= 3
