"""Messages name settings as the API does; the command line reads them as its flags
(nbcalib.wording, commands/_options.flag_names). Both ways, for errors, advice and log lines."""

from __future__ import annotations

import logging

import pytest

from nbcalib import cli
from nbcalib.commands._options import flag_names, flag_spelling
from nbcalib.errors import InputError
from nbcalib.preprocess.inputs import InputSpec
from nbcalib.report.verdict import advice
from nbcalib.wording import say, spelling, translator


def test_the_translator_writes_flags_for_known_names_only():
    spell = translator({"refine.max_outer": "--max-outer", "inputs.every": "--every"})
    assert spell("more iterations (refine.max_outer=20)") == "more iterations (--max-outer 20)"
    assert spell("give inputs.every/inputs.every") == "give --every/--every"
    # unknown names, file names, dotted module paths and longer names stay as they are
    for text in (
        "refine.bins",
        "see report.html",
        "nbcalib.refine.max_outer",
        "refine.max_outer_x",
        "x-refine.max_outer",
    ):
        assert spell(text) == text


def test_every_option_of_the_command_line_has_its_api_name():
    names = flag_names()
    assert names["inputs.every"] == "--every"
    assert names["matching.guess_pairs"] == "--guess-pairs"
    assert names["refine.trust_rotation_deg"] == "--trust-rotation"
    assert names["run.init"] == "--init"
    assert names["inputs.points"] == "--points"
    assert len(set(names.values())) == len(names)  # one name per flag


def test_an_input_error_names_the_setting_for_the_api_and_the_flag_for_the_command_line():
    with pytest.raises(InputError, match=r"give inputs\.every or inputs\.pair_count, not both"):
        InputSpec(every=2, pair_count=3)
    with spelling(flag_spelling()):
        with pytest.raises(InputError, match="give --every or --pair-count, not both"):
            InputSpec(every=2, pair_count=3)
    with pytest.raises(InputError, match=r"inputs\.every"):  # the spelling is back
        InputSpec(every=2, pair_count=3)


def test_the_command_line_reads_its_flags(tmp_path, capsys):
    bag = tmp_path / "a.bag"
    bag.write_bytes(b"")
    status = cli.main(["preprocess", str(bag), "--every", "2", "--pair-count", "3", "w"])
    err = capsys.readouterr().err
    assert status == 2
    assert "give --every or --pair-count, not both" in err and "inputs." not in err
    with pytest.raises(InputError, match=r"inputs\.every"):  # an API call after a command
        InputSpec(every=2, pair_count=3)


class _Q:
    names = ("a",)
    n_views = 1


def test_advice_names_settings_both_ways():
    api = advice("not_converged", _Q())
    assert "refine.max_outer=20" in api and "run.force" in api and "--" not in api
    with spelling(flag_spelling()):
        flags = advice("not_converged", _Q())
    assert "--max-outer 20" in flags and "--force" in flags and "refine." not in flags


def test_the_command_lines_log_lines_read_flags():
    cli._log_to_stderr(logging.INFO)
    handler = next(h for h in logging.getLogger("nbcalib").handlers if h.nbcalib_cli)
    record = logging.LogRecord("nbcalib.x", logging.INFO, __file__, 1, "set %s", ("x",), None)
    record.msg = "try matching.camera_scale=%s"
    with spelling(flag_spelling()):
        assert handler.format(record) == "try --camera-scale x"
    assert say("matching.camera_scale") == "matching.camera_scale"
