"""The first-run warm-up: a tiny job through the stages, started only on a cold cache."""

from __future__ import annotations

from nbcalib import warmup, warmup_job


def test_no_process_when_the_cache_is_warm_or_switched_off(monkeypatch):
    started = []
    monkeypatch.setattr(warmup.subprocess, "Popen", lambda *a, **k: started.append(a))
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: True)
    assert warmup.start() is None
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: False)
    monkeypatch.setenv("NBCALIB_NO_WARMUP", "1")
    assert warmup.start() is None
    assert not started
    monkeypatch.delenv("NBCALIB_NO_WARMUP")
    warmup.start()
    assert started and started[0][0][1:] == ["-m", "nbcalib.warmup_job"]


def test_the_tiny_job_runs_through_every_stage_and_leaves_the_cache_warm():
    warmup_job.tiny_job()  # raises if any stage fails on it
    assert warmup.cache_is_warm()


def test_no_process_where_the_cache_cannot_be_kept(monkeypatch, tmp_path):
    started = []
    monkeypatch.setattr(warmup.subprocess, "Popen", lambda *a, **k: started.append(a))
    monkeypatch.delenv("NBCALIB_NO_WARMUP", raising=False)
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: False)
    monkeypatch.setattr(warmup, "_cache_writable", lambda: False)
    assert warmup.start() is None and not started


def test_a_cache_under_numba_cache_dir_counts(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert not warmup.cache_is_warm()
    marker = tmp_path / "work" / "nbcalib" / "kernels" / "nid._joint_hist_smooth_impl-158.py311.nbi"
    marker.parent.mkdir(parents=True)
    marker.write_bytes(b"")
    assert warmup.cache_is_warm()


def test_a_first_run_says_that_kernels_compile(monkeypatch, caplog):
    import logging

    caplog.set_level(logging.INFO, logger="nbcalib")
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: False)
    assert warmup.compiling_note()
    assert caplog.messages == [warmup.COMPILING_NOTE]
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: True)
    assert not warmup.compiling_note() and caplog.messages == [warmup.COMPILING_NOTE]
