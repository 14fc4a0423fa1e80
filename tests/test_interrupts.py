"""A full disk at every write, and an interrupt in every stage that writes (issue 48).

Each stage of a finished job (automatic, through matching) is run again and stopped: by
``ENOSPC`` at each file it writes in turn, and by Ctrl-C or SIGTERM while it works. Every time:
one line and exit 2 (130, 143); no temporary file left; ``calib.json`` whole, and any result it
holds the one from before; and ``nbcalib run WORKDIR`` then ends at the uninterrupted job's
result to the last digit. (The lock, and SIGTERM sent as a real signal during fine registration:
``tests/test_workdir_lock.py``.)
"""

from __future__ import annotations

import errno
import json
import shutil

import pytest

from nbcalib.cli import Terminated, main
from tests.test_bad_input import _plain, base  # noqa: F401 (a fixture)

#: The automatic job: SIFT matches, the guess, a short fine registration, the report.
JOB = ["--matcher", "sift", "--max-outer", "2", "--pyramid-levels", "0"]


#: Each stage run again on a finished work directory (preprocess: into a new one), with the
#: job's options.
STAGES = {
    "preprocess": lambda inputs, work: ["preprocess", *_plain(inputs), str(work)],
    "preprocess-again": lambda inputs, work: ["preprocess", *_plain(inputs), str(work), "--force"],
    "find-matches": lambda inputs, work: ["find-matches", str(work), "--force", *JOB[:2]],
    "initial-guess": lambda inputs, work: ["initial-guess", str(work), "--force"],
    "calibrate": lambda inputs, work: ["calibrate", str(work), "--force", *JOB[2:]],
    "report": lambda inputs, work: ["report", str(work)],
}

#: The function each stage spends its time in, where an interrupt is raised.
WORK = {
    "preprocess": ("nbcalib.preprocess.prepare", "prepare_pair"),
    "find-matches": ("nbcalib.matching.find", "find_correspondences"),
    "initial-guess": ("nbcalib.initial_guess.estimate", "estimate_initial_guess"),
    "calibrate": ("nbcalib.registration.refine", "refine"),
    "report": ("nbcalib.report.quality", "assess"),
}


@pytest.fixture(scope="module")
def job(base):  # noqa: F811
    """A finished automatic job, run once without a stop."""
    finished = base["root"] / "automatic"
    if not finished.exists():
        assert main(["-q", "run", *_plain(base["inputs"]), str(finished), *JOB]) == 0
    return {"inputs": base["inputs"], "finished": finished, "result": _result(finished)}


def _result(work):
    path = work / "calib.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text()).get("results", {}).get("T_lidar_camera")


def _copy(job, stage, tmp_path):
    work = tmp_path / "work"
    if stage != "preprocess":
        shutil.copytree(job["finished"], work)
    return work


def _contents(work) -> dict:
    return {p.relative_to(work): p.read_bytes() for p in sorted(work.rglob("*")) if p.is_file()}


def _resume(job, stage, work, capsys):
    """Run the job again after a stop: ``run WORKDIR`` (after preprocessing: the job's command,
    which goes on from what was kept)."""
    capsys.readouterr()
    if not stage.startswith("preprocess"):
        assert main(["-q", "run", str(work)]) == 0, capsys.readouterr().err
    else:  # a preprocess command alone knows nothing of the job: the job's own command
        assert main(["-q", "run", *_plain(job["inputs"]), str(work), *JOB]) == 0
    assert _result(work) == job["result"], work  # to the last digit


def _check_stopped(job, work, before, err: list[str]):
    assert len(err) == 1 and "Traceback" not in err[0], err
    files = [p.name for p in work.rglob("*")] if work.exists() else []
    assert not [name for name in files if name.endswith(".tmp")], files
    if (work / "calib.json").is_file():
        calib = json.loads((work / "calib.json").read_text())  # whole
        found = calib.get("results", {}).get("T_lidar_camera")
        assert found in (None, before), "a result that is not the one from before"


def _count_writes(job, stage, tmp_path, monkeypatch) -> int:
    from nbcalib.io import _files

    work = _copy(job, stage, tmp_path / "count")
    writes = []
    real = _files.os.fsync
    monkeypatch.setattr(_files.os, "fsync", lambda fd: writes.append(fd) or real(fd))
    assert main(["-q", *STAGES[stage](job["inputs"], work)]) == 0
    monkeypatch.undo()
    return len(writes)


@pytest.mark.parametrize("stage", list(STAGES))
def test_a_full_disk_at_every_write(stage, job, tmp_path, monkeypatch, capsys):
    """ENOSPC at the 1st, 2nd, ... file the stage writes: one line naming the file, exit 2,
    nothing half-written, the result from before or none; then ``run WORKDIR`` finishes."""
    from nbcalib.io import _files

    count = _count_writes(job, stage, tmp_path, monkeypatch)
    assert count >= 2, count  # the products and calib.json at least
    for k in range(1, count + 1):
        work = _copy(job, stage, tmp_path / str(k))
        before, files = _result(work), _contents(work)
        seen = []

        def full(fd, k=k, seen=seen):
            seen.append(fd)
            if len(seen) == k:
                raise OSError(errno.ENOSPC, "No space left on device")

        monkeypatch.setattr(_files.os, "fsync", full)
        status = main(["-q", *STAGES[stage](job["inputs"], work)])
        monkeypatch.undo()
        err = capsys.readouterr().err.strip().splitlines()
        assert status == 2, (k, err)
        assert "no space left on device" in err[0] and str(work) in err[0], (k, err)
        assert ".tmp" not in err[0], err
        _check_stopped(job, work, before, err)
        if stage == "preprocess-again":  # a rerun is staged: the job as it was, every byte
            assert _contents(work) == files, k
        if k in (1, count):  # the first and the last write: the job finishes afterwards
            _resume(job, stage, work, capsys)


@pytest.mark.parametrize(
    ("stage", "signal"),
    [
        ("preprocess", "ctrl-c"),
        ("find-matches", "sigterm"),
        ("initial-guess", "ctrl-c"),
        ("calibrate", "ctrl-c"),
        ("report", "sigterm"),
    ],
)
def test_an_interrupt_in_every_stage(stage, signal, job, tmp_path, monkeypatch, capsys):
    """A new job stopped by Ctrl-C (130) or SIGTERM (143, raised as its handler raises it)
    while a stage works: one line; nothing of that stage left; ``run WORKDIR`` goes on from the
    last finished stage and ends at the uninterrupted job's result."""
    import importlib

    work = tmp_path / "work"
    module, name = WORK[stage]

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt if signal == "ctrl-c" else Terminated()

    monkeypatch.setattr(importlib.import_module(module), name, interrupted)
    status = main(["-q", "run", *_plain(job["inputs"]), str(work), *JOB])
    monkeypatch.undo()
    err = capsys.readouterr().err.strip().splitlines()
    expected = (130, "interrupted") if signal == "ctrl-c" else (143, "terminated")
    assert status == expected[0], err
    assert err == [f"nbcalib run: {expected[1]}"], err
    _check_stopped(job, work, job["result"], err)  # calibrate's result if it finished
    if stage == "preprocess":
        assert not work.exists()  # made by the job, nothing finished: not left behind
        assert main(["-q", "run", *_plain(job["inputs"]), str(work), *JOB]) == 0
    else:
        made = json.loads((work / "calib.json").read_text())["nbcalib"]["made"]
        assert stage not in made, made  # the stopped stage left no record
        assert main(["-q", "run", str(work)]) == 0, capsys.readouterr().err
    assert _result(work) == job["result"]  # to the last digit


@pytest.mark.parametrize("signal", ["ctrl-c", "sigterm"])
def test_an_interrupted_rerun_of_preprocessing_keeps_the_job(signal, job, tmp_path, monkeypatch):
    """``preprocess --force`` over a finished job, stopped while it works: the job, its result
    and its report as they were, every byte (the rerun is staged until complete)."""
    import importlib

    work = _copy(job, "preprocess-again", tmp_path)
    files = _contents(work)
    module, name = WORK["preprocess"]

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt if signal == "ctrl-c" else Terminated()

    monkeypatch.setattr(importlib.import_module(module), name, interrupted)
    status = main(["-q", *STAGES["preprocess-again"](job["inputs"], work)])
    assert status == (130 if signal == "ctrl-c" else 143)
    assert _contents(work) == files
