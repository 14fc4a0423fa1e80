"""The teaching notebooks run top to bottom (as scripts, on small data)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))

pytest.importorskip("matplotlib")


def test_notebooks_found():
    assert len(NOTEBOOKS) >= 7


@pytest.mark.slow
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_runs(notebook, tmp_path):
    env = dict(os.environ, NBCALIB_NOTEBOOK_QUICK="1", MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true")
    # the same path on every machine: no exported matcher, so the SIFT fallback (fast)
    env["NBCALIB_MODEL_DIR"] = str(tmp_path / "no_models")
    repo = str(Path(__file__).parents[1])
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [repo, env.get("PYTHONPATH")]))
    proc = subprocess.run(
        [sys.executable, str(notebook)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_percent_format(notebook):
    text = notebook.read_text()
    assert text.startswith("# ---\n# jupyter:"), "jupytext header missing"
    assert "# %% [markdown]" in text and "\n# %%\n" in text
