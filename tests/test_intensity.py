"""Intensity normalisation: point-intensity equalisation and camera-image equalisation."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.preprocess.intensity import (
    _equalize_values,
    equalize_image,
    equalize_point_intensities,
)


def _reference_levels(x):
    """The reference toolbox's mapping: rank i of N -> floor(256 i / N) / 256 (no ties here)."""
    levels = np.empty(len(x))
    levels[np.argsort(x)] = np.floor(256 * np.arange(len(x)) / len(x)) / 256
    return levels


@pytest.mark.parametrize("n", [1, 2, 7, 256, 1000, 4097])
def test_without_ties_equals_the_reference(n, rng):
    x = rng.permutation(n).astype(np.float64) + rng.random(n) * 0.5
    out = equalize_point_intensities(x)
    assert out.dtype == np.float64 and out.shape == (n,)
    assert np.array_equal(out, _reference_levels(x))


def test_ties_share_one_level_at_the_mid_rank(rng):
    x = np.array([5.0, 1.0, 5.0, 5.0, 3.0, 1.0, 9.0, 5.0])
    out = equalize_point_intensities(x)
    # sorted: 1 1 3 5 5 5 5 9; ranks of 1: 0..1, 3: 2, 5: 3..6, 9: 7
    n = len(x)
    mid = {1.0: 0.5, 3.0: 2.0, 5.0: 4.5, 9.0: 7.0}
    expected = [np.floor(256 * mid[v] / n) / 256 for v in x]
    assert np.array_equal(out, expected)
    # equal raw values -> equal levels; order-preserving; independent of the point order
    ints = rng.integers(0, 40, size=5000).astype(np.uint8)
    levels = equalize_point_intensities(ints)
    for v in np.unique(ints):
        assert np.unique(levels[ints == v]).size == 1
    order = np.argsort(ints, kind="stable")
    assert np.all(np.diff(levels[order]) >= 0)
    perm = rng.permutation(len(ints))
    assert np.array_equal(equalize_point_intensities(ints[perm]), levels[perm])


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.float32, np.float64])
def test_whole_numbers_counted_by_value_equal_the_sorted_path(dtype, rng):
    """Whole-number intensities take np.bincount (_value_counts), others np.unique: the same
    levels as the sorted path on the same values, ties and gaps in the values included."""
    from nbcalib.preprocess import intensity

    x = rng.choice([0, 3, 7, 8, 200, 255], size=20_000).astype(dtype)
    levels = equalize_point_intensities(x)
    counted, _ = intensity._value_counts(x)
    assert counted.max() == 255  # counted by value, not ranked by a sort
    sorted_path = equalize_point_intensities(x.astype(np.float64) + 0.25)  # not whole: np.unique
    assert np.array_equal(levels, sorted_path)
    halves = x.astype(np.float64) / 2  # 1.5, 3.5, 127.5: not whole numbers, so sorted
    assert np.array_equal(equalize_point_intensities(halves), levels)


def test_levels_are_in_range_and_spread(rng):
    x = rng.exponential(size=100_000)
    out = equalize_point_intensities(x)
    assert out.min() == 0.0 and out.max() == 255 / 256
    assert np.all(out * 256 == np.round(out * 256))
    counts = np.bincount((out * 256).astype(int), minlength=256)
    assert counts.min() >= 390 and counts.max() <= 391  # uniform: 100000 / 256 = 390.6


def test_edge_cases():
    assert equalize_point_intensities(np.zeros(0)).shape == (0,)
    # one tie group over ranks 0..9: mid-rank 4.5 -> floor(256 * 4.5 / 10) = 115
    assert np.array_equal(equalize_point_intensities(np.full(10, 7.0)), np.full(10, 115 / 256))
    with pytest.raises(ValueError, match="finite"):
        equalize_point_intensities(np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="shape"):
        equalize_point_intensities(np.zeros((2, 2)))


def _images(rng):
    yield rng.integers(0, 256, size=(48, 64), dtype=np.uint8)
    yield rng.integers(40, 90, size=(480, 640), dtype=np.uint8)  # narrow range
    skewed = (rng.beta(0.5, 5, size=(300, 200)) * 255).astype(np.uint8)
    yield skewed
    gaps = (rng.integers(0, 8, size=(50, 50)) * 31).astype(np.uint8)  # 8 values with gaps
    yield gaps
    two = np.zeros((10, 10), np.uint8)
    two[:3] = 200
    yield two


def test_uint8_generic_path_equals_opencv(rng):
    import cv2

    for image in _images(rng):
        assert np.array_equal(_equalize_values(image), cv2.equalizeHist(image))
        assert np.array_equal(equalize_image(image), cv2.equalizeHist(image))


def test_16_bit_and_float_images_equalise_like_their_8_bit_version(rng):
    import cv2

    for image in _images(rng):
        expected = cv2.equalizeHist(image)
        # a monotone change of the grey scale does not change the equalised image
        assert np.array_equal(equalize_image(image.astype(np.uint16) * 256 + 3), expected)
        assert np.array_equal(equalize_image(image / 255.0), expected)
        assert np.array_equal(equalize_image(np.sqrt(image / 255.0).astype(np.float32)), expected)


def test_image_edge_cases(rng):
    import cv2

    constant = np.full((5, 5), 77, np.uint8)
    assert np.array_equal(equalize_image(constant), cv2.equalizeHist(constant))
    assert np.array_equal(equalize_image(np.full((5, 5), 257 * 77, np.uint16)), constant)
    assert np.array_equal(equalize_image(np.full((5, 5), 77 / 255)), constant)
    rgb = rng.integers(0, 256, size=(20, 30, 3), dtype=np.uint8)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    assert np.array_equal(equalize_image(rgb), cv2.equalizeHist(grey))
    with pytest.raises(ValueError, match="non-finite"):
        equalize_image(np.array([[0.1, np.nan]]))
    with pytest.raises(ValueError, match="uint8"):
        equalize_image(np.zeros((3, 3), np.int32))
    with pytest.raises(ValueError, match="empty"):
        equalize_image(np.zeros((0, 3), np.uint8))
