"""The verdict of a job of many frames: distinct views, a frame left out (nbcalib.report)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbcalib.report import assess, rejudge
from nbcalib.report.uncertainty import leave_one_out, views
from nbcalib.report.verdict import ONE_VIEW
from nbcalib.transforms import se3_exp
from tests.test_report import make_pair


def test_images_of_one_view_share_a_label_and_other_views_do_not():
    rng = np.random.default_rng(0)
    a = np.clip(rng.normal(128, 40, (120, 160)), 0, 255).astype(np.uint8)
    b = np.clip(rng.normal(128, 40, (120, 160)), 0, 255).astype(np.uint8)
    noisy = np.clip(a + rng.normal(0, 5, a.shape), 0, 255).astype(np.uint8)
    assert views([a, noisy, b, a]).tolist() == [0, 0, 1, 0]
    assert views([a]).tolist() == [0]


def test_a_slow_drive_past_one_scene_is_one_scene():
    """Neighbours alike, ends not: a chain of alike frames is one scene (single linkage)."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(2)
    wide = gaussian_filter(rng.normal(0, 1, (120, 900)), 20)  # a street of smooth texture
    wide = 128 + 60 * wide / wide.std()
    frames = [np.clip(wide[:, k : k + 160], 0, 255).astype(np.uint8) for k in range(0, 700, 5)]
    thumbs_end = views([frames[0], frames[-1]])
    assert thumbs_end.tolist() == [0, 1]  # the ends alone: two scenes
    assert set(views(frames).tolist()) == {0}


def test_leave_one_out_is_the_minimum_of_the_other_pairs():
    """Quadratic pairs: the Newton step is the exact minimum of the sum without the pair."""
    rng = np.random.default_rng(1)
    minima = rng.normal(0, 0.01, (4, 6))
    hessians = []
    for _ in range(4):
        A = rng.normal(size=(6, 6))
        hessians.append(A @ A.T + 6 * np.eye(6))
    H = np.array(hessians)
    gradients = np.einsum("kij,kj->ki", H, -minima)  # each pair's gradient at delta = 0
    spans = np.full(6, 1.0)
    out = leave_one_out(gradients, H, spans)
    for k in range(4):
        rest = [j for j in range(4) if j != k]
        expected = np.linalg.solve(H[rest].sum(0), np.einsum("kij,kj->i", H[rest], minima[rest]))
        np.testing.assert_allclose(out[k], expected, atol=1e-10)


@pytest.fixture(scope="module")
def three_views():
    return [make_pair(seed, name=f"f{seed}") for seed in (1, 2, 3)]


def test_independent_views_are_judged_by_their_agreement_not_by_the_start(three_views):
    """Three views that agree at the truth: a far start is not a reason (each one pair's is)."""
    T_init = se3_exp(np.array([0.3, 0.0, 0.1, 0.0, 0.0, 0.05]))
    q = assess(three_views, np.eye(4), T_init=T_init)
    assert q.n_views == 3 and q.leave_one_out.shape == (3, 6)
    assert not any("far apart" in r for r in q.reasons), q.reasons
    assert q.verdict == "ok", q.reasons
    single = assess(three_views[:1], np.eye(4), T_init=T_init)
    assert any("far apart" in r for r in single.reasons)


def test_a_frame_without_which_the_result_moves_is_named(three_views):
    """f2 is sharp and holds the result where it wants; the other two want it 6 cm away."""
    q = assess(three_views, np.eye(4))
    H = q.pair_hessians_raw.copy()
    H[1] *= 50.0
    d = np.array([0.05, -0.03, 0.0, 0.0, 0.0, 0.0])
    g = np.array([H[0] @ d, np.zeros(6), H[2] @ d])
    g[1] = -(g[0] + g[2])  # the result is the joint minimum: the gradients sum to zero
    judged = rejudge(replace(q, pair_gradients=g, pair_hessians_raw=H), q.config)
    assert any(r.startswith("the result rests on") and "f2" in r for r in judged.reasons), (
        judged.reasons
    )
    assert any("decides the result alone" in step for step in judged.next_steps)


def test_frames_of_one_view_are_one_shot(three_views):
    """The same image three times: restarts as for a single pair, and advice to move."""
    same = [replace(three_views[0], name=f"copy{k}") for k in range(3)]
    q = assess(same, np.eye(4))
    assert q.n_views == 1 and len(q.restart_offsets) == q.config.restarts
    flat = rejudge(q, replace(q.config, max_translation_uncertainty=1e-6))
    assert ONE_VIEW in flat.next_steps
