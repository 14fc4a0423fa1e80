"""Camera image files: bit depth kept, RGB order in memory, grey weights, errors, real images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from nbcalib.errors import InputError
from nbcalib.io.image import read_image, rgb_to_grey, to_float_grey, write_png


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_grey_png_round_trip_keeps_bit_depth(tmp_path, rng, dtype):
    image = rng.integers(0, np.iinfo(dtype).max, (37, 53), endpoint=True).astype(dtype)
    write_png(tmp_path / "g.png", image)
    for grey in (True, False):
        back = read_image(tmp_path / "g.png", grey=grey)
        assert back.dtype == dtype and np.array_equal(back, image)
    assert list(tmp_path.iterdir()) == [tmp_path / "g.png"]  # no temporary file left


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_colour_png_is_rgb_in_memory(tmp_path, rng, dtype):
    image = rng.integers(0, np.iinfo(dtype).max, (20, 30, 3), endpoint=True).astype(dtype)
    write_png(tmp_path / "c.png", image)
    assert np.array_equal(read_image(tmp_path / "c.png", grey=False), image)
    on_disk = cv2.imread(str(tmp_path / "c.png"), cv2.IMREAD_UNCHANGED)  # OpenCV: BGR
    assert np.array_equal(on_disk[..., ::-1], image)


def test_grey_uses_opencv_weights_on_rgb(tmp_path):
    # pure red, green, blue, white: 0.299 R + 0.587 G + 0.114 B, rounded
    image = np.zeros((1, 4, 3), np.uint8)
    image[0, 0, 0] = image[0, 1, 1] = image[0, 2, 2] = 255
    image[0, 3] = 255
    write_png(tmp_path / "rgb.png", image)
    assert read_image(tmp_path / "rgb.png").tolist() == [[76, 150, 29, 255]]
    assert rgb_to_grey(image).tolist() == [[76, 150, 29, 255]]


def test_rgba_png_drops_alpha(tmp_path, rng):
    image = rng.integers(0, 256, (10, 12, 4)).astype(np.uint8)
    write_png(tmp_path / "a.png", image)
    assert np.array_equal(read_image(tmp_path / "a.png", grey=False), image[..., :3])
    assert np.array_equal(read_image(tmp_path / "a.png"), rgb_to_grey(image[..., :3]))


def test_to_float_grey_scales_by_bit_depth():
    assert np.array_equal(to_float_grey(np.array([[0, 51, 255]], np.uint8)), [[0.0, 0.2, 1.0]])
    assert np.array_equal(to_float_grey(np.array([[0, 65535]], np.uint16)), [[0.0, 1.0]])
    colour = np.zeros((1, 1, 3), np.uint8)
    colour[0, 0, 0] = 255
    assert to_float_grey(colour)[0, 0] == 76 / 255
    assert to_float_grey(np.array([[0.25]], np.float32)).dtype == np.float64
    with pytest.raises(ValueError, match="uint8, uint16 or float"):
        to_float_grey(np.zeros((2, 2), np.int32))


def test_image_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="file not found") as info:
        read_image(tmp_path / "missing.png")
    assert "missing.png" in str(info.value)
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(InputError, match="empty file"):
        read_image(tmp_path / "empty.png")
    (tmp_path / "junk.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\x00" * 40)
    with pytest.raises(InputError, match="cannot decode") as info:
        read_image(tmp_path / "junk.png")
    assert "junk.png" in str(info.value)
    cv2.imwrite(str(tmp_path / "float.tiff"), np.zeros((4, 4), np.float32))
    with pytest.raises(InputError, match="unsupported pixel type float32"):
        read_image(tmp_path / "float.tiff")


def test_write_png_rejects_programming_errors(tmp_path):
    with pytest.raises(ValueError, match="uint8 or uint16"):
        write_png(tmp_path / "x.png", np.zeros((2, 2), np.float64))
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        write_png(tmp_path / "x.png", np.zeros((2, 2, 2), np.uint8))
    assert not list(tmp_path.iterdir())


def test_real_kitti_image(real_data):
    path = real_data / "kitti_raw_2011_09_26" / "0000000000" / "image_02.png"
    grey = read_image(path)
    colour = read_image(path, grey=False)
    assert grey.shape == (375, 1242) and grey.dtype == np.uint8
    assert colour.shape == (375, 1242, 3)
    assert np.array_equal(colour[..., ::-1], cv2.imread(str(path)))  # RGB in memory
    # grey as cv_bridge makes mono8 (cvtColor), not libpng's IMREAD_GRAYSCALE (off by one here)
    assert np.array_equal(grey, cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2GRAY))


def test_real_pjlab_images(real_data):
    for folder in ("auto_calib", "manual_calib_0"):
        grey = read_image(real_data / "pjlab" / folder / "image.png")
        assert grey.shape == (1200, 1920)
        assert 0.1 < to_float_grey(grey).mean() < 0.9
