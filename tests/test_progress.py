"""Progress displays: a bar on a terminal, throttled step lines in a log, nothing when quiet."""

from __future__ import annotations

import io
import logging
from types import SimpleNamespace

import numpy as np
import pytest

import nbcalib.progress as progress_module
from nbcalib.cli import main
from nbcalib.progress import Progress


class _Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def _lines(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "nbcalib.progress"]


@pytest.fixture
def clock(monkeypatch):
    """A clock of the progress module that moves only when told (``clock.now += seconds``)."""
    fake = SimpleNamespace(now=100.0)
    fake.monotonic = lambda: fake.now
    monkeypatch.setattr(progress_module, "time", fake)
    return fake


def test_not_a_terminal_writes_throttled_lines_through_logging(caplog, clock):
    caplog.set_level(logging.INFO, logger="nbcalib")
    stream = io.StringIO()
    with Progress(20, "integrate", stream=stream, interval=5.0) as bar:
        assert bar.mode == "lines"
        for k in range(20):
            clock.now += 1.0
            bar.update(what=f"scan {k}")
    lines = _lines(caplog)
    # a line every 5 s (after 5, 10 and 15 steps), then the last one (once)
    assert [line.split(",")[0] for line in lines] == [
        "integrate: 5/20 scan 4",
        "integrate: 10/20 scan 9",
        "integrate: 15/20 scan 14",
        "integrate: 20/20 scan 19",
    ]
    assert lines[1] == "integrate: 10/20 scan 9, 10.0 s, 10 s left"
    assert lines[-1] == "integrate: 20/20 scan 19, in 20.0 s"
    assert stream.getvalue() == "" and not any("\r" in line for line in lines)


def test_a_quick_display_leaves_no_line(caplog, clock):
    caplog.set_level(logging.INFO, logger="nbcalib")
    with Progress(None, "refine", stream=io.StringIO()) as bar:
        for _ in range(1000):
            bar.update()
        clock.now += 4.9
    assert _lines(caplog) == []


@pytest.fixture
def every_step(monkeypatch):
    """A step line for every step, and the last line however quick the display."""
    monkeypatch.setattr(progress_module, "LINE_INTERVAL", 0.0)


def test_a_failure_writes_no_last_line(caplog, every_step):
    caplog.set_level(logging.INFO, logger="nbcalib")
    with pytest.raises(RuntimeError), Progress(3, "x", stream=io.StringIO()) as bar:
        bar.update()
        raise RuntimeError
    assert [line.split(",")[0] for line in _lines(caplog)] == ["x: 1/3"]


@pytest.mark.parametrize("level", [logging.WARNING, logging.NOTSET])
def test_quiet_shows_nothing(caplog, monkeypatch, level):
    """``-q`` (the nbcalib logger at WARNING), or a library user who configured no logging."""
    caplog.set_level(logging.WARNING)  # the root logger, as without any logging set up
    caplog.set_level(level, logger="nbcalib")
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    with Progress(3, "synth") as bar:
        assert bar.mode == "off"
        for _ in range(3):
            bar.update()
    assert terminal.getvalue() == "" and _lines(caplog) == []


def test_disabled_shows_nothing(caplog):
    caplog.set_level(logging.INFO, logger="nbcalib")
    terminal = _Terminal()
    with Progress(3, "synth", enabled=False, stream=terminal) as bar:
        bar.update(3)
    assert terminal.getvalue() == "" and _lines(caplog) == []


def test_a_terminal_gets_a_bar_and_log_lines_do_not_run_into_it(caplog, monkeypatch, clock):
    caplog.set_level(logging.INFO, logger="nbcalib")
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    handler = logging.StreamHandler(terminal)
    logger = logging.getLogger("nbcalib")
    logger.addHandler(handler)
    try:
        with Progress(4, "synth") as bar:
            assert bar.mode == "bar"
            for k in range(4):
                clock.now += 2.0
                bar.update(what=f"scan {k}")
                if k == 1:
                    logging.getLogger("nbcalib.pipeline").info("hello")
        assert handler.filters == []  # the bar's eraser leaves with the bar
    finally:
        logger.removeHandler(handler)
    text = terminal.getvalue()
    assert text.startswith("\rsynth [....................] 0/4")
    assert "\rsynth [##########..........] 2/4 scan 1, 4.0 s, 4 s left" in text
    assert "\r" + " " * 20 in text and "\rhello\n" in text  # erased before the log line
    last = text.rsplit("\r", 1)[1]  # padded with blanks over the longer line before
    assert (
        last.endswith("\n") and last.rstrip() == "synth [####################] 4/4 scan 3, in 8.0 s"
    )
    assert _lines(caplog) == []  # a bar instead of step lines


def test_a_quick_bar_is_erased(caplog):
    caplog.set_level(logging.INFO, logger="nbcalib")
    terminal = _Terminal()
    with Progress(2, "integrate", stream=terminal) as bar:
        bar.update(2)
    text = terminal.getvalue()
    assert text.startswith("\rintegrate [") and text.endswith("\r") and "\n" not in text
    assert text.rsplit("\r", 2)[1].strip() == ""


def test_bytes(caplog, clock, every_step):
    caplog.set_level(logging.INFO, logger="nbcalib")
    with Progress(None, "sha256", unit="B", stream=io.StringIO()) as bar:
        clock.now += 2.0
        bar.update(3_000_000, "scan.bin")
    assert _lines(caplog) == [
        "sha256: 3.0 MB scan.bin, 2.0 s, 2 MB/s",
        "sha256: 3.0 MB scan.bin, in 2.0 s",
    ]


def test_integrate_progress_true_is_a_display_not_carriage_returns(caplog, capsys, every_step):
    """The user test's finding: preprocess wrote ``\\r`` frames into a log."""
    from nbcalib.preprocess.accumulate import integrate_static

    caplog.set_level(logging.INFO, logger="nbcalib")
    rng = np.random.default_rng(0)
    scans = [rng.uniform(1.0, 5.0, size=(100, 3)) for _ in range(4)]
    integrate_static(scans, voxel_size=0.05, progress=True)
    assert "\r" not in capsys.readouterr().err
    lines = _lines(caplog)
    assert [line.split(",")[0] for line in lines[:-1]] == [
        f"integrate: {k}/4 scans" for k in (1, 2, 3)
    ]
    assert lines[-1].startswith("integrate: 4/4 scans, in ")


SYNTH = ["--pairs", "1", "--lidar", "spinning16", "--duration", "0.2", "--image-size", "32x24"]


def test_synth_command_in_a_log(tmp_path, capsys, every_step):
    assert main(["synth", str(tmp_path / "s"), *SYNTH]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err
    steps = [line.split(",")[0] for line in err.splitlines()]
    assert steps == [
        "synth: 1/4 pair 1/1: image",
        "synth: 2/4 pair 1/1: scans",
        "synth: 3/4 pair 1/1: scans",
        "synth: 4/4 pair 1/1: written",  # the last line, once: "in ... s"
    ]


@pytest.mark.parametrize("where", ["before", "after"])
def test_synth_command_quiet(tmp_path, capsys, every_step, where):
    argv = ["synth", str(tmp_path / "s"), *SYNTH]
    argv = ["-q", *argv] if where == "before" else [*argv, "-q"]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "nbcalib synth: 1 pair(s)" in captured.out


def test_assess_and_refine_show_their_steps(caplog, every_step):
    from nbcalib.registration.refine import RefineConfig, refine
    from nbcalib.report import assess
    from tests.test_report import make_pair

    caplog.set_level(logging.INFO, logger="nbcalib")
    pair = make_pair(1, n=2000, name="a")
    assess([pair], np.eye(4), progress=True)
    steps = [line.split(",")[0] for line in _lines(caplog)]
    # a pair's Hessian, six curves, then (a single pair) four restarts around the result
    assert steps[:2] == ["quality: 1/11 Hessian of a", "quality: 2/11 NID curve tx"]
    assert steps[6:8] == ["quality: 7/11 NID curve rz", "quality: 8/11 restart 1 of 4"]
    assert steps[-1] == "quality: 11/11 restart 4 of 4"
    caplog.clear()
    config = RefineConfig(pyramid_levels=0, max_outer=2, optimizer="lbfgs")
    result = refine([pair], np.eye(4), config, progress=True)
    lines = _lines(caplog)
    assert len(lines) == len(result.history) + 1
    assert lines[0].startswith("refine: 1 outer iterations (level 0, NID ")


# ------------------------------------------------------------------ in a notebook, from the API


@pytest.fixture
def notebook(monkeypatch):
    """A Jupyter kernel as the progress module sees it: the texts each display showed, in order."""
    import IPython.display

    shown = []

    class Handle:
        def __init__(self, texts):
            self.texts = texts

        def update(self, bundle, raw=False):
            assert raw
            self.texts.append(bundle["text/plain"])

    def display(bundle, raw=False, display_id=False):
        assert raw and display_id
        shown.append([bundle["text/plain"]])
        return Handle(shown[-1])

    monkeypatch.setattr(progress_module, "in_jupyter", lambda: True)
    monkeypatch.setattr(IPython.display, "display", display)
    return shown


def test_a_notebook_gets_a_bar_updated_in_place(caplog, clock, notebook):
    caplog.set_level(logging.INFO, logger="nbcalib")
    with Progress(10, "refine", stream=io.StringIO(), interval=5.0) as bar:
        assert bar.mode == "notebook"
        assert notebook == [["refine [....................] 0/10"]]  # at once
        for k in range(10):
            clock.now += 1.0
            bar.update(what=f"step {k}")
    (texts,) = notebook  # one display, updated in place
    assert texts[1] == "refine [##..................] 1/10 step 0, 1.0 s, 9 s left"
    assert len(texts) == 1 + 10 + 1  # at once, each update (1 s apart, >= 0.5 s), the end
    assert texts[-1] == "refine [####################] 10/10 step 9, in 10.0 s"
    assert _lines(caplog) == []  # no log lines beside it


def test_a_quick_display_in_a_notebook_leaves_nothing(caplog, clock, notebook):
    caplog.set_level(logging.INFO, logger="nbcalib")
    with Progress(3, "quality", stream=io.StringIO()) as bar:
        clock.now += 0.2
        bar.update()
    assert notebook == [["quality [....................] 0/3", ""]]


def test_quiet_means_no_display_in_a_notebook_either(caplog, notebook):
    caplog.set_level(logging.WARNING, logger="nbcalib")
    assert Progress(3, "quality").mode == "off" and notebook == []


def unconfigured(monkeypatch) -> logging.Logger:
    """Logging as a library user who configured nothing finds it: no level, no handler on the
    way. Called in the test itself: pytest attaches its capture handlers to the root logger and
    to loggers that do not propagate when the test starts (pytest >= 9.2), and they must go."""
    logger = logging.getLogger("nbcalib")
    monkeypatch.setattr(logger, "level", logging.NOTSET)
    monkeypatch.setattr(logger, "handlers", [])
    monkeypatch.setattr(logger, "propagate", False)
    return logger


def _say(text):
    logging.getLogger("nbcalib.pipeline").info(text)


def test_the_api_prints_its_lines_in_a_notebook(monkeypatch, notebook, capsys):
    logger = unconfigured(monkeypatch)
    with progress_module.api_output():
        assert logger.level == logging.INFO
        _say("[1/5] preprocess")
    out, err = capsys.readouterr()
    assert out == "[1/5] preprocess\n" and err == ""  # text, not a stderr block
    assert logger.level == logging.NOTSET and logger.handlers == []


def test_the_api_draws_on_a_terminal_and_is_silent_in_a_pipe(monkeypatch, capsys):
    unconfigured(monkeypatch)
    with progress_module.api_output():
        _say("into a pipe")
    assert capsys.readouterr() == ("", "")  # not a terminal: as Python's logging, nothing
    with progress_module.api_output(progress=True):
        _say("asked for")
    assert capsys.readouterr() == ("", "asked for\n")
    monkeypatch.setattr(progress_module, "_isatty", lambda stream: True)
    with progress_module.api_output():
        _say("on a terminal")
    assert capsys.readouterr() == ("", "on a terminal\n")


def test_the_api_leaves_a_configured_log_alone(monkeypatch, notebook, capsys):
    logger = unconfigured(monkeypatch)
    lines = []
    handler = logging.Handler()
    handler.emit = lambda record: lines.append(record.getMessage())
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    with progress_module.api_output():
        _say("to the log")
    assert lines == ["to the log"] and capsys.readouterr() == ("", "")
    with progress_module.api_output(progress=False):
        _say("quiet")
        assert Progress(3, "x").mode == "off"
    assert lines == ["to the log"] and logger.level == logging.INFO
    with progress_module.api_output(log=lines.append):
        _say("forwarded")
    assert lines[-2:] == ["forwarded", "forwarded"]  # to the callable, and to the log as before
