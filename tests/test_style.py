"""Project-wide rules that are cheap to check mechanically."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _python_files():
    return [p for p in (ROOT / "nbcalib").rglob("*.py")] + list((ROOT / "tests").rglob("*.py"))


def test_no_unsafe_fastmath():
    """All-flags fast-math lets LLVM assume no inf/NaN, which z-buffers and validity checks use."""
    pattern = re.compile(r"fastmath\s*=\s*" + "True")
    hits = [
        str(p)
        for p in _python_files()
        if p.name != "test_style.py" and pattern.search(p.read_text())
    ]
    assert not hits, f"all-flags fastmath in {hits}"


def test_numba_options_only_in_jit_module():
    """Kernels use nbcalib.kernels._jit.jit / jit_parallel; numba's decorators nowhere else."""
    pattern = re.compile(r"numba\.n?jit\b|from numba import[^\n]*\bn?jit\b|@n?jit\(")
    offenders = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "nbcalib").rglob("*.py")
        if p.name != "_jit.py" and pattern.search(p.read_text())
    ]
    assert not offenders, offenders


def test_kernels_live_under_kernels():
    """Every numba kernel is in nbcalib/kernels/: nothing else imports the JIT helpers or prange."""
    pattern = re.compile(r"nbcalib\.kernels\._jit import|from numba import[^\n]*\bprange\b")
    offenders = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "nbcalib").rglob("*.py")
        if "kernels" not in p.relative_to(ROOT).parts and pattern.search(p.read_text())
    ]
    assert not offenders, offenders


def test_import_is_cheap_and_compiles_nothing():
    """`import nbcalib` loads neither numba nor any heavy optional dependency."""
    code = (
        "import sys, time; t = time.perf_counter(); import nbcalib; dt = time.perf_counter() - t;"
        "heavy = [m for m in ('numba', 'scipy', 'cv2', 'rosbags', 'onnxruntime', 'pyvista',"
        " 'matplotlib') if m in sys.modules]; print(dt, heavy)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    dt, heavy = out.stdout.split(" ", 1)
    assert heavy.strip() == "[]", heavy
    assert float(dt) < 1.0


def _committed_ipynb():
    """The .ipynb files git tracks (every one under notebooks/ when git is not available)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--", "*.ipynb"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        )
    except (OSError, subprocess.CalledProcessError):
        found = (ROOT / "notebooks").rglob("*.ipynb")
        return sorted(p for p in found if ".ipynb_checkpoints" not in p.parts)
    return [ROOT / name for name in out.stdout.split("\0") if name]


def test_committed_ipynb_have_no_outputs():
    """The notebooks are committed as jupytext scripts (below), normally with no .ipynb at all;
    a committed .ipynb must at least carry no outputs (they bloat diffs and go stale)."""
    for nb in _committed_ipynb():
        cells = json.loads(nb.read_text())["cells"]
        code = [c for c in cells if c["cell_type"] == "code"]
        assert not any(c.get("outputs") or c.get("execution_count") for c in code), nb.name


#: header of a jupytext script: YAML in comments between two ``# ---`` lines
_JUPYTEXT_HEADER = re.compile(r"\A# ---\n(?:# .*\n)+?# ---\n")


def test_notebooks_are_jupytext_percent_scripts():
    """Each notebooks/*.py is a jupytext percent script that jupytext reads and writes back
    unchanged (cell for cell), opens with a markdown cell, and carries no pasted outputs."""
    import jupytext

    notebooks = sorted((ROOT / "notebooks").glob("*.py"))
    assert len(notebooks) >= 7, notebooks
    for path in notebooks:
        text = path.read_text()
        header = _JUPYTEXT_HEADER.match(text)
        # paired with the .ipynb JupyterLab writes beside it (tests/test_notebooks.py)
        assert header and "#     formats: ipynb,py:percent\n" in header.group(0), path.name
        compile(text, str(path), "exec")
        nb = jupytext.reads(text, fmt="py:percent")
        markers = re.findall(r"^# %%.*$", text, flags=re.MULTILINE)
        assert len(nb.cells) == len(markers) >= 2, path.name
        assert nb.cells[0].cell_type == "markdown", path.name
        written = jupytext.writes(nb, fmt="py:percent")
        assert _JUPYTEXT_HEADER.sub("", written) == _JUPYTEXT_HEADER.sub("", text), path.name
        # outputs pasted back as comments (nbconvert's "# In[3]:" / "# Out[3]:" markers)
        assert not re.search(r"^# (In|Out) ?\[\d*\]:", text, flags=re.MULTILINE), path.name
