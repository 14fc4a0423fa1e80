"""The command line's contract: --help everywhere, exit statuses, one-line errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from nbcalib.cli import build_parser, main


def _command_names():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    return sorted(sub.choices)


COMMANDS = _command_names()


def test_top_level_help(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for name in COMMANDS:
        assert name in out
    assert "examples:" in out


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_has_help_with_examples(name, capsys):
    with pytest.raises(SystemExit) as exc:
        main([name, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and f"nbcalib {name}" in out


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2
    assert "usage:" in capsys.readouterr().out


def test_unknown_command_is_a_one_line_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "invalid choice" in err


def test_user_error_exit_2_without_traceback(capsys):
    assert main(["selfcheck", "--width", "3"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "--width" in err


def test_selfcheck_passes(capsys):
    assert main(["selfcheck", "--step", "32"]) == 0
    assert "7/7 camera models ok" in capsys.readouterr().out


def test_console_script_runs():
    """`python -m nbcalib` is the same program as the installed `nbcalib` script."""
    out = subprocess.run(
        [sys.executable, "-m", "nbcalib", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.startswith("nbcalib ")


def test_building_the_parser_loads_no_heavy_module():
    """`nbcalib data list` or `--help` must not pay for numba, SciPy, OpenCV or onnxruntime."""
    code = (
        "import sys; from nbcalib.cli import build_parser; build_parser(); "
        "print(','.join(m for m in ('numba', 'scipy', 'cv2', 'onnxruntime', 'matplotlib') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_a_file_where_a_folder_should_be_is_a_user_error(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    assert main(["synth", str(tmp_path / "file" / "out"), "--pairs", "1"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "file" in err and "not a folder" in err


def test_no_retries_switches_the_matching_retries_off():
    import argparse

    from nbcalib.commands._options import MATCHING, add_options, build_config

    parser = argparse.ArgumentParser()
    add_options(parser, MATCHING)
    default = build_config(parser.parse_args([]))
    assert default.matching.retry_pixels_per_degree == (10.0, 15.0)
    off = build_config(parser.parse_args(["--no-retries"]))
    assert off.matching.retry_pixels_per_degree == ()


def test_optional_numbers_take_none_on_the_command_line_and_in_files(capsys):
    import argparse

    from nbcalib.commands._options import REFINE, add_options, build_config

    parser = argparse.ArgumentParser()
    add_options(parser, REFINE)
    assert build_config(parser.parse_args([])).refine.points_per_pixel == 0.25
    every = build_config(parser.parse_args(["--points-per-pixel", "none"]))
    assert every.refine.points_per_pixel is None
    assert (
        build_config(parser.parse_args(["--points-per-pixel", "0.1"])).refine.points_per_pixel
        == 0.1
    )
    from_file = build_config(parser.parse_args([]), file_values={"refine.points_per_pixel": "none"})
    assert from_file.refine.points_per_pixel is None  # TOML has no null
    with pytest.raises(SystemExit):
        parser.parse_args(["--points-per-pixel", "many"])
    assert "expected a number or none, got 'many'" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # a plain number takes no "none"
        parser.parse_args(["--bins", "none"])
    assert "expected an integer, got 'none'" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, dest, value",
    [
        (["calibrate", "w", "--init", "-0.1,0.2,0.3,0,0,0,1"], "init", "-0.1,0.2,0.3,0,0,0,1"),
        (["run", "w", "--prior", "-0.5,0.5,-0.5,0.5,0,0,1"], "prior", "-0.5,0.5,-0.5,0.5,0,0,1"),
        (
            ["preprocess", "a.npy", "b.png", "w", "--distortion", "-0.12,0.16,0,0,0"],
            "distortion",
            "-0.12,0.16,0,0,0",
        ),
        (
            ["preprocess", "a.npy", "b.png", "w", "--intrinsics", "-1e3,1e3,320,240"],
            "intrinsics",
            "-1e3,1e3,320,240",
        ),
        (["run", "w", "--image-times", "-.5,1.5"], "image_times", "-.5,1.5"),
        (
            ["synth", "o", "--T-lidar-camera", "-0.1,0,0,0,0,0,1"],
            "T_lidar_camera",
            "-0.1,0,0,0,0,0,1",
        ),
    ],
)
def test_list_values_may_start_with_a_minus_in_the_space_separated_form(argv, dest, value):
    from nbcalib.cli import _parse, join_negative_values

    args = _parse(build_parser(), join_negative_values(argv))
    assert getattr(args, dest) == value


def test_positional_arguments_may_follow_options():
    from nbcalib.cli import _parse

    args = _parse(build_parser(), ["preprocess", "a.pcd", "--image", "b.png", "work"])
    assert args.inputs == ["a.pcd", "work"] and args.image == "b.png"


@pytest.mark.parametrize("name", COMMANDS)
def test_help_shows_no_empty_or_switch_defaults(name, capsys):
    with pytest.raises(SystemExit):
        main([name, "--help"])
    out = capsys.readouterr().out
    for empty in ("(default: None)", "(default: True)", "(default: False)", "(default: [])"):
        assert empty not in out
