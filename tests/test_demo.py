"""`nbcalib demo`: a seeded synthetic scene through every stage, judged against the truth."""

from __future__ import annotations

import json

import pytest

from nbcalib.cli import main


def test_demo_help_has_examples(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["demo", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "--matcher sift" in out


@pytest.mark.slow
def test_demo_without_learned_models_is_honest(tmp_path, no_learned_models, capsys):
    """No learned matcher at all (SIFT only): the demo must finish, print the evaluate line and
    the targets verdict, and say when it started from a perturbed ground truth."""
    assert main(["demo", str(tmp_path / "demo")]) == 0
    out = capsys.readouterr().out
    assert "matcher sift" in out
    line = next(x for x in out.splitlines() if x.startswith('{"translation_error_m"'))
    errors = json.loads(line)
    assert errors["stage"] == "T_lidar_camera"
    summary = json.loads((tmp_path / "demo" / "demo_summary.json").read_text())
    # the perturbed-truth start (and the hint to use the shipped learned matcher) is said
    # exactly when the SIFT guess is unusable
    assert ("GROUND TRUTH PERTURBED" in out) == (not summary["guess_usable"])
    assert ("ships with nbcalib" in out) == (not summary["guess_usable"])
    met = errors["translation_error_m"] <= 0.01 and errors["rotation_error_deg"] <= 0.1
    assert ("NOT within the synthetic targets" in out) == (not met)
    # fine registration from 5 cm / 1 degree must at least get much closer
    assert errors["translation_error_m"] < 0.03 and errors["rotation_error_deg"] < 0.5


@pytest.mark.slow
def test_demo_on_a_fresh_install_is_automatic(tmp_path, monkeypatch, capsys):
    """Nothing exported, no torch: the shipped XFeat + LighterGlue gives the demo's guess, which
    is usable, so fine registration starts from it (not from a perturbed truth) and meets the
    synthetic targets."""
    empty = tmp_path / "models"
    empty.mkdir()
    monkeypatch.setenv("NBCALIB_MODEL_DIR", str(empty))
    assert main(["demo", str(tmp_path / "demo")]) == 0
    out = capsys.readouterr().out
    assert "matcher xfeat-lighterglue" in out
    summary = json.loads((tmp_path / "demo" / "demo_summary.json").read_text())
    assert summary["guess_usable"] and summary["start_T_lidar_camera"] is None
    assert "GROUND TRUTH PERTURBED" not in out
    line = next(x for x in out.splitlines() if x.startswith('{"translation_error_m"'))
    errors = json.loads(line)
    assert errors["translation_error_m"] <= 0.01 and errors["rotation_error_deg"] <= 0.1


def test_demo_rejects_zero_pairs(tmp_path, capsys):
    assert main(["demo", str(tmp_path / "demo"), "--pairs", "0"]) != 0
    err = capsys.readouterr().err
    assert "--pairs must be >= 1" in err and "Traceback" not in err
    assert not (tmp_path / "demo" / "synth").exists()
