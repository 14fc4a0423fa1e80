"""Matching leaves a first run's warm-up a core (nbcalib.warmup.running)."""

from __future__ import annotations

import subprocess
import sys

from nbcalib import warmup
from nbcalib.matching import match


def test_matching_uses_one_core_fewer_while_the_warmup_runs(monkeypatch):
    monkeypatch.setattr(match.os, "cpu_count", lambda: 4)
    monkeypatch.setattr(warmup, "_process", None)
    assert not warmup.running()
    assert match._threads(None) == 4
    assert match._threads(3) == 3  # the user's number wins
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        monkeypatch.setattr(warmup, "_process", sleeper)
        assert warmup.running()
        assert match._threads(None) == 3
        assert match._threads(4) == 4
    finally:
        sleeper.kill()
        sleeper.wait()
    assert not warmup.running()  # finished: every core again
    assert match._threads(None) == 4


def test_one_core_is_never_zero_threads(monkeypatch):
    monkeypatch.setattr(match.os, "cpu_count", lambda: 1)
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        monkeypatch.setattr(warmup, "_process", sleeper)
        assert match._threads(None) == 1
    finally:
        sleeper.kill()
        sleeper.wait()
