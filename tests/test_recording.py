"""The guess from many frames of one recording (nbcalib.matching.recording)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.initial_guess import synthetic_correspondences
from nbcalib.initial_guess.config import InitialGuessConfig
from nbcalib.matching import recording
from nbcalib.matching.config import MatchConfig
from nbcalib.matching.correspondences import Correspondences
from nbcalib.synthetic import default_T_camera_lidar
from nbcalib.transforms import invert_T, make_T, pose_error, rotation_angle_deg, so3_exp

CAMERA = example_camera("pinhole", 640, 480)
#: the camera 5 cm from the LiDAR: rotation-only votes see little parallax at 2-40 m
TRUTH = make_T(default_T_camera_lidar("spinning", 2)[:3, :3], [0.03, -0.04, 0.02])


def frame_correspondences(name: str, seed: int, n_inliers: int, outliers: float):
    c = synthetic_correspondences(CAMERA, TRUTH, seed, n_inliers=n_inliers,
                                  outlier_fraction=outliers)  # fmt: skip
    n = len(c.uv_camera)
    return Correspondences(
        c.uv_camera, c.points_lidar, np.full((n, 2), np.nan), np.arange(n), np.zeros(n, int),
        (name,), n, np.ones(n),
    )  # fmt: skip


@dataclass
class _View:  # what the vote reads of a screened view
    R_camera_lidar: np.ndarray
    ransac_inliers: int
    correspondences: Correspondences


def test_the_vote_finds_the_rotation_the_frames_share():
    """Each frame's own best view is a wrong rotation; only the shared one adds up."""
    rng = np.random.default_rng(0)
    screens = []
    for k in range(6):
        corr = frame_correspondences(f"f{k}", k, 8, 0.9)  # 8 right among 80
        wrong = so3_exp(rng.normal(size=3)) @ TRUTH[:3, :3]
        right = so3_exp(np.radians([0.5, -0.3, 0.2])) @ TRUTH[:3, :3]
        screens.append([_View(wrong, 12, corr), _View(right, 6, corr)])
    votes = recording.vote_rotations(CAMERA, screens, threshold=5.0, count=2)
    assert rotation_angle_deg(votes[0].R_camera_lidar.T @ TRUTH[:3, :3]) < 1.0
    assert votes[0].support >= 6 * 6 and len(votes[0].per_frame) == 6
    assert rotation_angle_deg(votes[1].R_camera_lidar.T @ votes[0].R_camera_lidar) >= 10.0
    assert votes[1].support < votes[0].support / 2


class _Found:  # what match_recording reads of match_views' result
    def __init__(self, corr):
        self.correspondences = corr
        self.views = []


def _fake(monkeypatch, frames: dict, *, failing_attempts=(), calls=None):
    """screen_frame and _match_view replaced by synthetic correspondences per frame.

    ``frames``: name -> (inliers, outlier fraction) each view of it gives; attempts whose
    views' resolution is in ``failing_attempts`` give outliers only.
    """
    calls = [] if calls is None else calls

    def screen(camera, pair, cfg, **kwargs):
        n, out = frames[pair.name]
        corr = frame_correspondences(pair.name, hash(pair.name) % 1000, n, out)
        return [_View(TRUTH[:3, :3], n, corr)]

    def match_view(camera, pair, cfg, T, **kwargs):
        calls.append((pair.name, cfg.pixels_per_degree))
        n, out = frames[pair.name]
        if cfg.pixels_per_degree in failing_attempts:
            n, out = 0, 0.5
        seed = len(calls)
        corr = frame_correspondences(pair.name, seed, n, out) if n else Correspondences.empty(
            [pair.name])  # fmt: skip
        if not n:
            junk = frame_correspondences(pair.name, seed, 40, 0.0)
            corr = replace(junk, points_lidar=junk.points_lidar[::-1].copy())
        return _Found(corr)

    monkeypatch.setattr(recording, "screen_frame", screen)
    monkeypatch.setattr(recording, "_match_view", match_view)
    return calls


@dataclass
class _Pair:
    name: str
    lidar_index: np.ndarray = None

    def __post_init__(self):
        self.lidar_index = np.full((4, 4), -1, np.int32)


def test_frames_are_matched_until_their_pose_stops_moving(monkeypatch):
    frames = {f"f{k}": (60, 0.7) for k in range(8)}
    calls = _fake(monkeypatch, frames)
    pairs = [_Pair(name) for name in frames]
    cfg = MatchConfig(guess_pairs=2, refine_view=False, matcher="sift")
    found = recording.match_recording(CAMERA, pairs, cfg, InitialGuessConfig())
    assert found.guess.found and found.attempt == 0
    dt, dr = pose_error(invert_T(found.guess.T_camera_lidar), invert_T(TRUTH))
    assert dt < 0.05 and dr < 0.2
    assert 3 <= len(found.found) < 8, "stops once a frame more moves the pose little"
    assert len(calls) == len(found.found) and set(found.agreeing) <= set(found.found)
    assert found.screened < 8, "the screen stops once the vote is clear"
    # 0: every frame
    calls.clear()
    every = recording.match_recording(CAMERA, pairs, replace(cfg, guess_pairs=0),
                                      InitialGuessConfig())  # fmt: skip
    assert len(every.found) == 8


def test_a_recording_whose_views_find_nothing_tries_the_finer_views(monkeypatch):
    frames = {f"f{k}": (60, 0.7) for k in range(4)}
    calls = _fake(monkeypatch, frames, failing_attempts=(None,))
    pairs = [_Pair(name) for name in frames]
    cfg = MatchConfig(refine_view=False, matcher="sift")
    found = recording.match_recording(CAMERA, pairs, cfg, InitialGuessConfig())
    assert found.attempt == 1 and found.guess.found
    assert {ppd for _, ppd in calls} == {None, cfg.frames_pixels_per_degree}
    settings = recording.attempt_settings(cfg)
    assert settings[1].inpaint_deg == cfg.frames_inpaint_deg and not settings[1].lift_inpainted
    assert "attempt" not in found.summary() and "agree on the pose" in found.summary()


def test_frames_that_never_agree_give_the_best_attempt(monkeypatch):
    frames = {f"f{k}": (60, 0.7) for k in range(3)}
    _fake(monkeypatch, frames, failing_attempts=(None, MatchConfig().frames_pixels_per_degree))
    found = recording.match_recording(
        CAMERA, [_Pair(n) for n in frames], MatchConfig(refine_view=False, matcher="sift"),
        InitialGuessConfig(),
    )  # fmt: skip
    assert found.guess is None or not found.guess.found
    assert "no pose" in found.summary()


@pytest.mark.slow
def test_a_synthetic_recording_is_matched_through_the_cli(tmp_path):
    """Three Livox x pinhole pairs through ``run --until initial-guess``: the frames' guess."""
    import json

    from nbcalib.cli import main

    data, work = tmp_path / "data", tmp_path / "work"
    synth = ["synth", str(data), "--lidar", "livox", "--camera", "pinhole", "--pairs", "3",
             "--duration", "0.5", "--image-size", "480x360", "--seed", "4"]  # fmt: skip
    assert main(["-q", *synth]) == 0
    pcds = sorted(str(p) for p in data.glob("pair_*.pcd"))
    images = sorted(str(p) for p in data.glob("pair_*.png"))
    assert len(pcds) == 3
    run = ["-q", "run", *pcds, "--images", *images, "--camera", str(data / "camera.yaml"),
           "--until", "initial-guess", str(work)]  # fmt: skip
    assert main(run) == 0
    calib = json.loads((work / "calib.json").read_text())
    info = json.loads((work / f"{calib['meta']['bag_names'][0]}_matches.json").read_text())
    assert info["nbcalib"]["mode"] in ("recording", "skipped")
    from nbcalib.io.ground_truth import read_ground_truth
    from nbcalib.workdir import WorkDir

    guess = WorkDir(work).read_calib().get_T_camera_lidar("init_T_lidar_camera_auto")
    dt, dr = pose_error(invert_T(guess), invert_T(read_ground_truth(data / "ground_truth.json")))
    assert dt < 0.1 and dr < 1.0
