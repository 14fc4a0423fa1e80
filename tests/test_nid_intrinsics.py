"""The NID's derivative with respect to the camera's intrinsics (issue 47).

The kernels' extra columns against the slow reference (which builds them from the camera's own
``intrinsics_jacobian``), the costs' gradients against central differences of their values at
every camera model with a focal length and at a pyramid level, and the pose's columns unchanged.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.kernels import nid as k
from nbcalib.reference import nid as ref
from nbcalib.registration.nid import GroupedNIDCost, MultiNIDCost, NIDCost, offset_params
from nbcalib.registration.pair import downscale_camera
from nbcalib.transforms import se3_exp
from tests.test_nid import nasty_points, textured_scene
from tests.tolerances import TOL

FOCAL_MODELS = [m for m in CAMERA_MODELS if m != "equirectangular"]


@pytest.mark.parametrize("model", ["plumb_bob", "fisheye", "omnidir", "atan"])
@pytest.mark.parametrize("n_intr", [1, 3])
def test_intrinsics_columns_match_the_reference(model, n_intr, rng):
    cam = example_camera(model, 160, 120)
    pts = nasty_points(cam, rng, n=800)
    point_bins = rng.integers(0, 8, len(pts)).astype(np.uint8)
    image_bins = rng.integers(0, 8, (cam.height, cam.width)).astype(np.uint8)
    T = se3_exp(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.01]))
    step = 0.5
    expected = ref.joint_histogram_smooth_derivative(
        cam, T, pts, point_bins, image_bins, 8, n_intr=n_intr, center_step=step
    )
    assert expected.shape == (8, 8, 6 + n_intr)
    for kernel in (k._joint_hist_smooth, k._joint_hist_smooth_parallel):
        args = (cam.model_id, cam.params, T, pts.T.copy(), point_bins, image_bins, 8, 8)
        hist, dhist, _ = kernel(*args, k.N_CHUNKS, True, n_intr, step)
        plain, dplain, _ = kernel(*args, k.N_CHUNKS, True, 0, 1.0)
        scale = np.abs(expected).max()
        tol = TOL["nid_derivative_vs_reference_scaled"]
        assert_allclose(dhist / scale, expected / scale, **tol)
        # the histogram and the pose's columns are those of the kernel without intrinsics
        assert np.array_equal(hist, plain)
        assert np.array_equal(dhist[..., :6], dplain)


def _inner_scene(cam, rng, n=3000):
    image, pts, inten = textured_scene(cam, rng, n=n)
    uv, _ = cam.project(pts)
    w, h = cam.width, cam.height
    inner = (uv[:, 0] > 12) & (uv[:, 0] < w - 13) & (uv[:, 1] > 12) & (uv[:, 1] < h - 13)
    return image, pts[inner], inten[inner]


def _numeric(value, x, h):
    out = np.empty(x.size)
    for j in range(x.size):
        e = np.zeros(x.size)
        e[j] = h[j]
        out[j] = (value(x + e) - value(x - e)) / (2 * h[j])
    return out


@pytest.mark.parametrize("model", FOCAL_MODELS)
def test_gradient_in_the_intrinsics_matches_finite_differences(model, rng):
    cam = example_camera(model, 320, 240)
    image, pts, inten = _inner_scene(cam, rng)
    T0 = se3_exp(np.array([0.002, -0.003, 0.001, 0.001, -0.0015, 0.0005]))
    groups = (pts[:, 0] > 0).astype(int) + 2 * (pts[:, 1] > 0)
    for cost in (
        NIDCost(cam, image, pts, inten),
        GroupedNIDCost(cam, image, pts, inten, groups),
    ):
        x0 = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.004, 1.5, -2.0])

        def value(x, cost=cost):
            return cost.value(se3_exp(x[:6]) @ T0, intrinsics=x[6:])

        _, grad = cost.value_and_grad(T0, intrinsics=x0[6:])
        assert grad.shape == (9,)
        numeric = _numeric(value, x0, np.array([1e-6] * 6 + [1e-7, 1e-4, 1e-4]))
        assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())
        _, focal_only = cost.value_and_grad(T0, intrinsics=x0[6:7])
        assert focal_only.shape == (7,)


def test_a_pyramid_level_takes_the_principal_point_in_full_resolution_pixels(rng):
    full = example_camera("plumb_bob", 320, 240)
    image, pts, inten = _inner_scene(full, rng)
    cam = downscale_camera(full, 1)
    small = image.reshape(120, 2, 160, 2).mean(axis=(1, 3))
    cost = NIDCost(cam, small, pts, inten, level=1)
    x0 = np.array([0.003, 2.0, -1.0])
    _, grad = cost.value_and_grad(np.eye(4), intrinsics=x0)
    steps = np.array([1e-7, 1e-4, 1e-4])
    numeric = _numeric(lambda x: cost.value(np.eye(4), intrinsics=x), x0, steps)
    assert_allclose(grad[6:], numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())
    # a shift of 2 full-resolution pixels is one pixel at level 1
    params, n_intr, step = offset_params(cam, x0, level=1)
    assert (n_intr, step) == (3, 0.5)
    assert_allclose(params[2:4], cam.params[2:4] + np.array([1.0, -0.5]))
    assert_allclose(params[:2], cam.params[:2] * np.exp(0.003))


def test_no_offset_is_the_camera_as_it_is(rng):
    cam = example_camera("fisheye", 160, 120)
    image, pts, inten = _inner_scene(cam, rng, n=1000)
    cost = MultiNIDCost([NIDCost(cam, image, pts, inten)])
    v, g = cost.value_and_grad(np.eye(4))
    v0, g0 = cost.value_and_grad(np.eye(4), intrinsics=[0.0])
    assert v == v0 and np.array_equal(g, g0[:6])
    with pytest.raises(ValueError, match="1 or 3"):
        cost.value(np.eye(4), intrinsics=[0.0, 1.0])
    with pytest.raises(ValueError, match="equirectangular"):
        offset_params(example_camera("equirectangular", 160, 80), [0.0])
