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


def test_notebooks_have_no_outputs():
    for nb in (ROOT / "notebooks").glob("*.ipynb"):
        cells = json.loads(nb.read_text())["cells"]
        assert not any(c.get("outputs") for c in cells if c["cell_type"] == "code"), nb.name
