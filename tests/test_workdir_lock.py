"""One job at a time in a work directory (issue 48): the lock, as a user meets it on the CLI.

A second job on a work directory in use exits 2 at once at every stage that writes, naming the
process that holds it and since when, and changes nothing; a lock left by a killed job is taken
over with a one-line note; read-only commands run beside a job.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from nbcalib.cli import main
from nbcalib.io.ground_truth import write_ground_truth
from nbcalib.io.workdir_lock import LOCK_FILE, holder, workdir_lock
from tests.test_bad_input import (  # noqa: F401 (base: a fixture)
    INIT,
    T_TRUE,
    _plain,
    base,
    hold_lock,
)


def _digest(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


@pytest.fixture
def work(base, tmp_path):  # noqa: F811
    """A finished work directory of our own."""
    out = tmp_path / "work"
    shutil.copytree(base["finished"], out)
    return out


def _stop(proc: subprocess.Popen, sig=signal.SIGTERM) -> None:
    proc.send_signal(sig)
    proc.wait(timeout=30)


def test_a_second_job_is_refused_at_every_stage_that_writes(work, base, capsys):  # noqa: F811
    proc = hold_lock(work)
    try:
        before = _digest(work)
        for argv in (
            ["preprocess", *_plain(base["inputs"]), str(work)],
            ["find-matches", str(work), "--force"],
            ["initial-guess", str(work), "--force"],
            ["calibrate", str(work), f"--init={INIT}", "--force"],
            ["report", str(work)],
            ["run", str(work), "--force", "--no-matching", f"--init={INIT}"],
        ):
            status = main(["-q", *argv])
            err = capsys.readouterr().err.strip().splitlines()
            assert status == 2, (argv, err)
            assert len(err) == 1 and "Traceback" not in err[0], err
            assert str(work) in err[0] and "in use by" in err[0], err
            assert f"process {proc.pid}" in err[0] and "since" in err[0], err
            assert _digest(work) == before, argv  # nothing written
    finally:
        _stop(proc)


def test_read_only_commands_run_beside_a_job(work, tmp_path, capsys):
    gt = tmp_path / "ground_truth.json"
    write_ground_truth(gt, T_TRUE)
    proc = hold_lock(work)
    try:
        assert main(["-q", "evaluate", str(work), "--ground-truth", str(gt)]) == 0
        assert main(["-q", "export", str(work), "--out", str(tmp_path / "out")]) == 0
    finally:
        _stop(proc)
    capsys.readouterr()


def test_a_lock_left_by_a_killed_job_is_taken_over(work, caplog):
    proc = hold_lock(work)
    _stop(proc, signal.SIGKILL)  # killed: the lock file still names it
    assert holder(work)["pid"] == proc.pid
    assert main(["-q", "report", str(work)]) == 0
    notes = [r.getMessage() for r in caplog.records if "took over the lock" in r.getMessage()]
    assert len(notes) == 1 and f"process {proc.pid}" in notes[0], notes
    assert holder(work) is None  # released cleanly: the file is empty


def test_the_lock_is_released_and_one_process_may_take_it_again(tmp_path):
    path = tmp_path / "w"
    with workdir_lock(path):
        assert holder(path)["pid"] == os.getpid()
        with workdir_lock(path):  # a stage inside a job
            assert holder(path)["pid"] == os.getpid()
        assert holder(path)["pid"] == os.getpid()
    assert holder(path) is None
    assert not path.exists()  # made for the job, nothing written: not left behind
    path.mkdir()
    (path / "calib.json").write_text("{}")
    with workdir_lock(path):
        pass
    assert sorted(p.name for p in path.iterdir()) == [LOCK_FILE, "calib.json"]
    assert json.loads((path / "calib.json").read_text()) == {}


def _until(proc: subprocess.Popen, text: str) -> list[str]:
    """stderr lines of ``proc`` up to the first one holding ``text``."""
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if text in line:
            return lines
    raise AssertionError(f"{text!r} never came: {''.join(lines)[-2000:]}")


def test_sigterm_ends_a_job_in_one_line_and_run_resumes_to_the_same_result(base, tmp_path):  # noqa: F811
    """SIGTERM during fine registration: exit 143, one line; ``run WORKDIR`` then finishes
    with the result of a run that was never stopped, to the last digit."""
    argv = [*_plain(base["inputs"]), "--no-matching", f"--init={INIT}", "--pyramid-levels", "0"]
    whole = tmp_path / "whole"
    assert main(["-q", "run", *argv, str(whole)]) == 0
    stopped = tmp_path / "stopped"
    cmd = [sys.executable, "-m", "nbcalib", "-v", "run", *argv, str(stopped)]
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
    _until(proc, "outer 1 ")
    proc.send_signal(signal.SIGTERM)
    rest = proc.stderr.read().strip().splitlines()
    assert proc.wait(timeout=60) == 143
    assert rest[-1] == "nbcalib run: terminated", rest[-3:]
    assert not any("Traceback" in line for line in rest)
    assert holder(stopped) is None  # the lock released
    calib = json.loads((stopped / "calib.json").read_text())
    assert "T_lidar_camera" not in calib.get("results", {})  # no result that looks finished
    assert main(["-q", "run", str(stopped)]) == 0  # resumes: calibrate and report
    done = [json.loads((w / "calib.json").read_text())["results"] for w in (whole, stopped)]
    assert done[0]["T_lidar_camera"] == done[1]["T_lidar_camera"]


@pytest.mark.parametrize("stage", ["run"])
def test_a_full_disk(stage, base, tmp_path, monkeypatch, capsys):  # noqa: F811
    """ENOSPC at the first file ``run`` writes: exit 2, one line naming the file, nothing
    half-written; the previous result and record as they were. (Every write of every stage:
    ``tests/test_interrupts.py``.)"""
    import errno

    from nbcalib.io import _files

    work = tmp_path / "work"
    if stage != "preprocess":
        shutil.copytree(base["finished"], work)
    before = _digest(work) if work.exists() else {}

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(_files.os, "fsync", full)
    argv = {
        "preprocess": ["preprocess", *_plain(base["inputs"]), str(work)],
        "calibrate": ["calibrate", str(work), f"--init={INIT}", "--force"],
        "report": ["report", str(work)],
        "run": ["run", str(work), "--from", "calibrate", "--no-matching", f"--init={INIT}"],
    }[stage]
    status = main(["-q", *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2, err
    assert len(err) == 1 and "no space left on device" in err[0], err
    assert str(work) in err[0] and ".tmp" not in err[0], err
    after = _digest(work) if work.exists() else {}
    assert not [name for name in after if name.endswith(".tmp")], after
    assert after.get("calib.json") == before.get("calib.json")  # as it was, or none
