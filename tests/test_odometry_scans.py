"""Scans in: per-point times (synthesised from the azimuth, normalised) and the points used."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from odometry_scene import SCAN_PERIOD, pattern
from tolerances import TOL

from nbcalib.kernels import ct_icp
from nbcalib.odometry.scans import normalized_scan_times, synthesize_times_from_azimuth
from nbcalib.reference import integrate as ref

# ---------------------------------------------------------------------------------------------
# Per-point times
# ---------------------------------------------------------------------------------------------


def test_synthesize_times_from_azimuth():
    az = np.radians([180.0 - 1e-9, 90.0, 0.0, -90.0, -179.0])
    points = np.column_stack([np.cos(az), np.sin(az), np.zeros(5)]) * 10.0
    t = synthesize_times_from_azimuth(points, 10.0)  # clockwise from behind
    assert_allclose(t, [0.0, 0.025, 0.05, 0.075, 0.1 * 359 / 360], atol=1e-9)
    t_ccw = synthesize_times_from_azimuth(points, 10.0, clockwise=False)
    assert_allclose(t_ccw[1:4], [0.075, 0.05, 0.025], atol=1e-9)
    assert np.all((t >= 0) & (t < 0.1))
    d, times = pattern()
    assert_allclose(synthesize_times_from_azimuth(d, 1 / SCAN_PERIOD), times, atol=1e-9)


@pytest.mark.parametrize("with_times", [False, True])
@pytest.mark.parametrize("clockwise", [True, False])
def test_select_points_matches_reference(rng, with_times, clockwise):
    points = rng.uniform(-20, 20, (3000, 3))
    points[:100] *= 0.01  # within min_distance
    points[100:110, 1] = np.nan
    points[110, 2] = np.inf
    intensity = rng.uniform(0, 1, 3000)
    intensity[120] = np.nan
    times = rng.uniform(5.0, 5.1, 3000) if with_times else None
    if with_times:
        times[130] = np.nan
    got = ct_icp._select_points(
        points,
        intensity,
        times if with_times else np.zeros(0),
        with_times,
        10.0,
        clockwise,
        np.radians(170.0),
        1.0,
        True,
    )
    want = ref.select_points(points, intensity, times, 10.0, clockwise, 170.0, 1.0)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    assert got[3] == want[3] == 3000 - 12 - (1 if with_times else 0)
    assert_allclose(got[2], want[2], **TOL["kernel_vs_reference"])
    assert_allclose(got[4], want[4], **TOL["kernel_vs_reference"])


def test_normalized_scan_times():
    s, duration = normalized_scan_times([5.0, 5.05, 5.1])
    assert_allclose(s, [0.0, 0.5, 1.0])
    assert duration == pytest.approx(0.1)
    s, duration = normalized_scan_times([2.0, 2.0])
    assert np.array_equal(s, [0.0, 0.0]) and duration == 0.0
