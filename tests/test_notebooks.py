"""The teaching notebooks run top to bottom and teach what they say (on small data).

Each notebook runs in this process (``runpy``, as ``__main__``) in a temporary directory with
``NBCALIB_NOTEBOOK_QUICK=1``; then a check of its own asserts on the values the notebook leaves
in its namespace (as RussTedrake/manipulation tests its notebooks), so a notebook that runs but
teaches something wrong fails, and names itself.

Bounds are the notebook text's own numbers where it states one, else about 2-3x what the quick
mode gives; the comments give the measured values.
"""

from __future__ import annotations

import math
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import hide_learned_models

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))

pytest.importorskip("matplotlib")


def run_notebook(notebook: Path, tmp_path: Path, monkeypatch) -> dict:
    """Run ``notebook`` as a script in ``tmp_path/work``; return its global namespace."""
    import matplotlib.pyplot as plt

    monkeypatch.setenv("NBCALIB_NOTEBOOK_QUICK", "1")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.setenv("PYVISTA_OFF_SCREEN", "true")
    # the same path on every machine: no learned matcher, so the SIFT fallback (fast)
    hide_learned_models(monkeypatch, tmp_path / "no_models")
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    try:
        return runpy.run_path(str(notebook), run_name="__main__")
    finally:
        plt.close("all")
        if "pyvista" in sys.modules:
            sys.modules["pyvista"].close_all()


# ============================================================================ the checks


def _bend_px(grid: np.ndarray) -> float:
    """Largest distance (px) of a dot from the straight line through its row or column of dots.

    ``grid`` (n, n, 2) holds the projected directions of notebook 1's grid, NaN where a
    direction misses the image.
    """
    worst = 0.0
    for lines in (grid, grid.transpose(1, 0, 2)):
        for line in lines:
            dots = line[np.isfinite(line).all(axis=1)]
            if len(dots) < 3:
                continue
            dots = dots - dots.mean(axis=0)
            normal = np.linalg.svd(dots, full_matrices=False)[2][-1]
            worst = max(worst, float(np.abs(dots @ normal).max()))
    return worst


def check_camera_models(ns):
    # u = fx x / z + cx, v = fy y / z + cy: the text's formula, to the last bit
    uv, valid = ns["uv_points"], ns["valid_points"]
    np.testing.assert_array_equal(uv[:3], [[319.5, 239.5], [569.5, 239.5], [319.5, 189.5]])
    assert valid.tolist() == [True, True, True, False], "the point behind the camera is invalid"

    models = list(ns["CAMERA_MODELS"])
    assert len(models) == 7, "the seven models of the reference toolbox"
    for model in models:
        with_ray, pixels = ns["pixels_unprojected"][model]
        assert with_ray == pixels, f"{model}: every pixel unprojects to a ray"
        # "numerical noise": measured at most 1.1e-13 px (2 ulp of a 300 px coordinate)
        assert ns["round_trip_px"][model] <= 3e-13, model
        # the text: "agrees to within about 1e-7 pixels per metre"; measured at most 3.7e-8
        assert ns["jacobian_error"][model] <= 1e-7, model

    # straight lines of directions stay straight only for the pinhole camera
    bend = {model: _bend_px(ns["grid_uv"][model]) for model in models}
    assert bend["pinhole"] <= 1e-9, bend  # measured 1e-13 px
    for model in models[1:]:
        assert bend[model] >= 5.0, bend  # measured 16 px (plumb_bob) to 98 px (fisheye)

    # the wide-angle models squeeze a larger field of view into the image than the pinhole kinds
    fov, share = ns["fov_deg"], ns["in_image_fraction"]
    narrow, wide = ("pinhole", "plumb_bob", "rational_polynomial"), ("fisheye", "atan", "omnidir")
    assert max(fov[m] for m in narrow) < 180.0, fov  # measured 96-118 degrees
    assert min(fov[m] for m in wide) > max(fov[m] for m in narrow), fov  # atan 148 > 118
    assert min(share[m] for m in wide) > max(share[m] for m in narrow), share  # 0.46 > 0.29
    assert fov["equirectangular"] == 360.0 and share["equirectangular"] == 1.0


def check_synthetic_rig(ns):
    from nbcalib.synthetic import default_T_camera_lidar

    config, seq = ns["config"], ns["seq"]
    assert seq.config is config
    # the ground truth is the one the rig was built with, a rigid transform, 5-30 cm offset
    np.testing.assert_array_equal(
        seq.T_camera_lidar, default_T_camera_lidar("spinning", config.seed)
    )
    R = seq.T_camera_lidar[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) > 0
    assert 0.05 <= np.linalg.norm(seq.T_lidar_camera[:3, 3]) <= 0.30

    # a 64-beam spinning LiDAR, 0.1 s scans; a plumb_bob camera, one grey image at time 0
    assert seq.lidar.name == "spinning64" and seq.lidar.beams == 64
    period = seq.lidar.scan_period
    assert period == 0.1
    assert seq.camera.model == "plumb_bob"
    width, height = config.image_size
    assert (seq.camera.width, seq.camera.height) == (width, height)
    assert seq.image.shape == (height, width) and seq.image.dtype == np.uint8
    assert len(seq.scans) == round(config.duration / period)  # 3 in quick mode, 10 in 1 s
    assert seq.image_stamp == seq.scans[0].stamp == 0.0
    for k, scan in enumerate(seq.scans):
        assert len(scan) > 0, f"scan {k} is empty"
        assert math.isclose(scan.stamp, k * period), scan.stamp
        assert np.all(np.diff(scan.times) >= 0), f"scan {k}: per-point times out of order"
        assert scan.times.min() >= 0.0 and scan.times.max() < period
        assert np.unique(scan.rings).size == 64, "a scan is 64 rings"

    # the points through the true extrinsic land on what the camera saw there
    points, uv, valid = ns["points"], ns["uv"], ns["valid"]
    assert len(points) == sum(len(s) for s in seq.scans)
    assert valid.sum() > 0  # measured 43 830 of 191 096
    col, row = np.floor(uv[valid] + 0.5).astype(int).T
    prim = np.concatenate([s.prim for s in seq.scans])[valid]
    same_surface = np.mean(prim == seq.rendered.prim[row, col])
    assert same_surface >= 0.93, same_surface  # measured 0.974 (the rest: hidden, edges)
    # ... and near the surface point the camera saw at that pixel's centre
    p_camera = points[valid] @ R.T + seq.T_camera_lidar[:3, 3]
    seen = seq.rendered.bearings[row, col] * seq.rendered.range[row, col][:, None]
    gap = np.median(np.linalg.norm(p_camera - seen, axis=1))
    assert gap <= 0.016, gap  # measured 7.8 mm; 17 mm with the pose 0.25 deg off, 22 mm 2 cm off


def check_dense_clouds(ns):
    seq, times = ns["seq"], ns["times"]
    assert len(ns["scans"]) == len(times) == round(seq.config.duration / 0.1)  # 5 in quick mode
    for t in times:
        assert t.min() >= 0.0 and t.max() < 0.1, "per-point times over 0.1 s each"

    # the estimated trajectory stays close to the truth
    trans_err, rot_err = ns["trans_err"], ns["rot_err"]
    assert len(trans_err) == len(times)
    assert trans_err.max() <= 0.03, trans_err  # measured at most 1.35 cm
    assert rot_err.max() <= 0.6, rot_err  # measured at most 0.265 deg

    # deskewed: about as thin as with the true trajectory; naive: thicker
    thickness = ns["thickness"]
    naive = thickness["naive (no motion model)"]
    icp = thickness["continuous-time ICP"]
    truth = thickness["true trajectory"]
    assert icp <= 1.10 * truth, thickness  # measured 8.0 mm vs 7.8 mm (+3 %)
    assert naive >= 1.25 * icp, thickness  # measured 14.1 mm vs 8.0 mm (1.76x)


def check_lidar_image(ns):
    from nbcalib.preprocess.lidar_image import PINHOLE_MAX_FOV_DEG, intensity_to_uint8
    from nbcalib.reference.zbuffer import render_zbuffer

    fov, virtual, renders, clouds = ns["fov_deg"], ns["virtual"], ns["renders"], ns["clouds"]
    # all around: about 180 degrees; the rosette: between the axes of its elliptic field of view
    assert abs(fov["spinning64"] - 180.0) <= 1.0, fov  # measured 180.0
    livox_axes = ns["seq"].lidar.fov_deg  # the last sequence made is the Livox one
    assert min(livox_axes) <= fov["livox"] <= max(livox_axes), fov  # 70.4 <= 75.9 <= 77.2

    for lidar, (camera, T_vcam_lidar) in virtual.items():
        # the field-of-view rule picks the virtual camera
        pinhole = fov[lidar] < PINHOLE_MAX_FOV_DEG
        assert camera.model == ("pinhole" if pinhole else "equirectangular"), lidar
        size = (1024, 1024) if pinhole else (1920, 960)
        assert (camera.width, camera.height) == size, lidar
        if pinhole:  # looking along the LiDAR's x axis
            np.testing.assert_array_equal(T_vcam_lidar[:3, :3] @ [1.0, 0.0, 0.0], [0, 0, 1])

        # the index map is the z-buffer of the slow reference, to the bit
        points = clouds[lidar][0]
        image = renders[lidar]
        best, index, _, _ = render_zbuffer(
            camera.model_id, camera.params, T_vcam_lidar, points, camera.width, camera.height
        )
        np.testing.assert_array_equal(image.index, index, err_msg=lidar)
        np.testing.assert_array_equal(image.depth, np.sqrt(best).astype(np.float32))
        # every filled pixel shows one point of its own, with that point's equalised intensity
        filled = image.filled
        assert filled.any(), lidar
        assert np.unique(image.index[filled]).size == filled.sum(), lidar
        expected = intensity_to_uint8(ns["equalised"][lidar])[image.index[filled]]
        np.testing.assert_array_equal(image.intensity[filled], expected)
        assert not image.intensity[~filled].any()

        # rank equalisation spreads the intensities uniformly over [0, 1]
        values = ns["equalised"][lidar]
        assert values.min() >= 0.0 and values.max() <= 1.0
        counts = np.histogram(values, bins=10, range=(0.0, 1.0))[0]
        flatness = np.abs(counts / counts.mean() - 1.0).max()
        assert flatness <= 0.06, counts  # measured 2.4 % (256 levels in 10 bins)

    # a pixel names a point, and the point projects back onto that pixel
    u, v, index, uv = ns["u"], ns["v"], ns["index"], ns["uv"]
    assert ns["image"] is renders["livox"] and index == renders["livox"].index[v, u] >= 0
    np.testing.assert_array_equal(ns["p"], clouds["livox"][0][index])
    np.testing.assert_array_equal(np.floor(uv + 0.5), [u, v])

    # the camera image uses its full grey range after equalisation
    assert ns["camera_image"].min() == 0 and ns["camera_image"].max() == 255


def check_initial_guess(ns):
    # 100 true correspondences among 500 (80 % outliers)
    c, guess = ns["c"], ns["guess"]
    assert len(c.uv_camera) == 500 and c.is_inlier.sum() == 100
    assert guess.success
    # the reprojection errors separate inliers from outliers: the threshold falls between them
    assert guess.errors[c.is_inlier].max() < guess.threshold  # measured 2.9 px < 5 px
    assert guess.errors[~c.is_inlier].min() > guess.threshold  # measured 23.9 px > 5 px
    np.testing.assert_array_equal(guess.inliers, c.is_inlier)
    assert guess.rms_px <= 3.0, guess.rms_px  # measured 1.32 px (1 px noise per axis)
    err = ns["known_error"]
    assert err["translation_error_m"] <= 0.006, err  # measured 2.0 mm
    assert err["rotation_error_deg"] <= 0.075, err  # measured 0.025 deg

    # the polish: from 1.3 m off along the weak axis, the translation RANSAC finds the truth
    s = ns["s"]
    assert ns["pulled_error"] == {"translation_error_m": 1.3, "rotation_error_deg": 0.0}
    assert ns["n"] >= 0.9 * s.is_inlier.sum(), ns["n"]  # measured 80 of 80
    ransac = ns["ransac_error"]
    assert ransac["translation_error_m"] <= 0.07, ransac  # measured 2.87 cm
    assert ransac["rotation_error_deg"] == 0.0  # a translation-only search
    for polish, err in ns["polish_error"].items():
        # the text: "both estimates end within a centimetre"; measured 7.96 mm and 9.26 mm
        assert err["translation_error_m"] <= 0.01, (polish, err)
        assert err["rotation_error_deg"] <= 0.06, (polish, err)  # measured 0.024, 0.021 deg

    # the views: the best is the one with the most RANSAC support, its pool gives the matches
    found = ns["found"]
    assert 1 <= len(found.views) <= 6  # views without LiDAR points in them are left out
    support = [view.ransac_inliers for view in found.views]
    assert found.best == int(np.argmax(support)) and found.best in found.pooled, support
    pooled = sum(len(found.views[k].correspondences.uv_camera) for k in found.pooled)
    assert len(ns["corr"].uv_camera) == pooled  # measured 77
    # the success flag says when the SIFT guess failed: a success is within a degree or two
    chain, err = ns["chain_guess"], ns["chain_error"]
    assert (chain is None) == (len(ns["corr"].uv_camera) < 3)
    if chain is not None and chain.success:
        assert err["rotation_error_deg"] <= 2.0 and err["translation_error_m"] <= 0.1, err
    # (measured with SIFT: success False, 168 deg off)


def check_fine_registration(ns):
    pair, visible, T_true, T_off = ns["pair"], ns["visible"], ns["T_true"], ns["T_off"]
    # hidden-point removal drops points the camera has in its image but cannot see
    p_camera = pair.points_lidar @ T_true[:3, :3].T + T_true[:3, 3]
    in_image = np.flatnonzero(pair.camera.project(p_camera, in_image=True)[1])
    assert np.isin(visible, in_image).all()
    assert len(visible) < len(in_image), (len(visible), len(in_image))  # measured 69 665 < 70 209

    # the joint histogram is sharper at the truth, and the NID lower, than 2 degrees off
    nid = ns["nid"]
    assert nid["true pose"] < nid["rotated by 2 degrees"], nid  # measured 0.9108 < 0.9274

    def joint_entropy(T):
        h = ns["joint_histogram"](T).ravel()
        p = h[h > 0] / h.sum()
        return float(-(p * np.log(p)).sum())

    assert joint_entropy(T_true) < joint_entropy(T_off)

    # along each axis the NID is a valley with its minimum at (or one step next to) zero
    curves = ns["axis_nid"]
    centre = curves.shape[1] // 2
    assert np.all(curves[:, centre] < curves[:, 0]) and np.all(curves[:, centre] < curves[:, -1])
    lowest = curves.argmin(axis=1)
    assert np.all(np.abs(lowest - centre) <= 1), lowest  # measured: z one step (+2 cm) off

    # refine from 7 cm / 1.5 degrees off: a lower NID, closer to the truth
    start, result, err = ns["start_error"], ns["result"], ns["result_error"]
    assert math.isclose(start["translation_error_m"], 0.07, rel_tol=1e-3), start
    assert math.isclose(start["rotation_error_deg"], 1.5, rel_tol=1e-6), start
    assert result.converged
    cost = ns["cost"]
    assert cost.value(result.T_camera_lidar) < cost.value(ns["T_init"])  # 0.9103 < 0.9268
    assert err["rotation_error_deg"] <= 0.9, err  # measured 0.37 deg
    # one pair constrains translation weakly: measured 5.9 cm (of 7), no worse than the start
    assert err["translation_error_m"] <= start["translation_error_m"], err


def check_quality_report(ns):
    start, err, q = ns["start_error"], ns["err"], ns["q"]
    # the start is ~5 cm, ~1 degree off (measured 5.08 cm, 0.996 deg)
    assert 0.045 <= start["translation_error_m"] <= 0.055, start
    assert 0.9 <= start["rotation_error_deg"] <= 1.1, start
    assert err["translation_error_m"] <= 0.04, err  # measured 1.72 cm
    assert err["rotation_error_deg"] <= 0.6, err  # measured 0.229 deg

    # a good result: ok, no reasons, converged, six clear valleys centred on the result
    assert q.verdict == "ok" and q.reasons == [], q.reasons
    assert q.converged is True
    centre = q.curve_values.shape[1] // 2
    np.testing.assert_array_equal(q.curve_values.argmin(axis=1), [centre] * 6)

    # the uncertainty: finite, within the limits that let the verdict be ok, of the order of the
    # true error, and the notebook's inside/outside sentence is what the numbers say
    u = q.uncertainty
    t_cm, r_deg = u["translation_total_cm"], u["rotation_total_deg"]
    assert 0 < t_cm <= 100 * q.config.max_translation_uncertainty, u  # measured 2.05 cm
    assert 0 < r_deg <= q.config.max_rotation_uncertainty_deg, u  # measured 0.290 deg
    err_cm, err_deg = 100 * err["translation_error_m"], err["rotation_error_deg"]
    assert err_cm <= 3 * t_cm and err_deg <= 3 * r_deg, (err, u)  # measured 0.84x, 0.79x
    assert ns["covered"] == (err_cm <= t_cm and err_deg <= r_deg)

    # the wrong image: suspect, because the cost is flat
    bad = ns["bad"].quality
    assert bad.verdict == "suspect" and bad.reasons
    assert any(reason.startswith("flat cost") for reason in bad.reasons), bad.reasons
    rise = np.ptp(bad.curve_values, axis=1) / np.ptp(q.curve_values, axis=1)
    assert np.all(rise <= 0.3), rise  # measured at most 0.12 of the good result's rise


CHECKS = {
    "01_camera_models": check_camera_models,
    "02_synthetic_rig": check_synthetic_rig,
    "03_dense_clouds": check_dense_clouds,
    "04_lidar_image": check_lidar_image,
    "05_initial_guess": check_initial_guess,
    "06_fine_registration": check_fine_registration,
    "07_quality_report": check_quality_report,
}


# ============================================================================ the tests


def test_notebooks_found():
    assert len(NOTEBOOKS) >= 7
    assert {p.stem for p in NOTEBOOKS} == set(CHECKS), "every notebook needs a check"


@pytest.mark.slow
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_teaches(notebook, tmp_path, monkeypatch):
    namespace = run_notebook(notebook, tmp_path, monkeypatch)
    CHECKS[notebook.stem](namespace)


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_percent_format(notebook):
    text = notebook.read_text()
    assert text.startswith("# ---\n# jupyter:"), "jupytext header missing"
    assert "# %% [markdown]" in text and "\n# %%\n" in text
