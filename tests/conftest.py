"""Shared fixtures: seeded random generators, headless plotting, the real-data folder."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

#: ../shared/data/real relative to the project root (absent for package users: tests skip)
REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"


@pytest.fixture
def rng():
    """A fresh, seeded generator per test, so tests are independent and repeatable."""
    return np.random.default_rng(12345)


@pytest.fixture
def real_data() -> Path:
    """Path to the real LiDAR-camera data; skips the test when it is not present."""
    if not REAL_DATA.is_dir():
        pytest.skip(f"real data not present at {REAL_DATA}")
    return REAL_DATA


def hide_learned_models(monkeypatch, empty: Path) -> Path:
    """No learned matcher anywhere: ``empty`` as the model directory, the shipped ones hidden.

    The path of an install without onnxruntime models (``auto`` falls back to SIFT).
    """
    from nbcalib.matching import onnx_matcher

    empty.mkdir(exist_ok=True)
    monkeypatch.setenv("NBCALIB_MODEL_DIR", str(empty))
    monkeypatch.setattr(onnx_matcher, "packaged_model_dir", lambda: empty)
    return empty


@pytest.fixture
def no_learned_models(tmp_path, monkeypatch):
    """:func:`hide_learned_models` into ``tmp_path / "no-models"``."""
    return hide_learned_models(monkeypatch, tmp_path / "no-models")


def _kept_nbcalib_logging():
    """Leave the ``nbcalib`` logger as it was found (its handlers and level)."""
    import logging

    logger = logging.getLogger("nbcalib")
    handlers, level = list(logger.handlers), logger.level
    yield
    for handler in list(logger.handlers):
        if handler not in handlers:
            logger.removeHandler(handler)
    logger.setLevel(level)


@pytest.fixture(autouse=True)
def _restore_nbcalib_logging():
    """Each test starts with the ``nbcalib`` logger as the last left it was, and ends so.

    ``nbcalib.cli.main`` gives the logger a stderr handler and a level per command line;
    the handler of one test's ``main`` would otherwise outlive that test's captured stderr.
    """
    yield from _kept_nbcalib_logging()


@pytest.fixture(autouse=True, scope="module")
def _restore_nbcalib_logging_per_module():
    """The same around each test module: a module-scoped fixture that runs ``main`` (outside
    any one test) does not leave its handler to the modules after it, whichever order the
    modules run in (``pytest -n 2`` gives each worker its own order)."""
    yield from _kept_nbcalib_logging()
