"""The teaching notebooks run top to bottom in a Jupyter kernel and teach what they say.

Each notebook runs as a learner runs it: opened by jupytext, executed cell by cell in a real
IPython kernel (nbclient) in a temporary directory, with ``NBCALIB_NOTEBOOK_QUICK=1`` (small
data). Then, in the same kernel, the notebook's check (``tests/notebook_checks.py``) asserts
on the values it leaves, as RussTedrake/manipulation tests its notebooks; and here, the saved
outputs are checked for what a learner would meet in JupyterLab: a still image where each 3-D
view is, no object reprs such as ``<... object at 0x...>``, nothing on standard error (no
error-coloured blocks for normal progress).

To look at what the notebooks show: ``NBCALIB_NOTEBOOK_SAVE=DIR`` keeps each executed notebook
as ``DIR/<name>.ipynb`` (open it in JupyterLab, no kernel needed), and
``NBCALIB_NOTEBOOK_FIGURES=DIR`` writes every image it showed as PNGs.
"""

from __future__ import annotations

import base64
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from notebook_checks import CHECKS

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("[0-9][0-9]_*.py"))
TESTS = Path(__file__).parent

pytest.importorskip("matplotlib")

#: What stderr may say here: run_notebook hides the learned matchers (a warning, not progress)
EXPECTED_WARNING = re.compile(r"no learned matcher exported in .*: using the SIFT fallback")
#: An object's default repr, as a notebook shows a value nobody meant to show.
OBJECT_REPR = re.compile(r"<[\w.]+(?: object)? at 0x[0-9a-f]+>")


@pytest.fixture(scope="module")
def kernel(tmp_path_factory):
    """One IPython kernel of this Python for all the notebooks, in quick mode, no learned matcher.

    As in a lab where one kernel ran the notebook before: its imports and the numba kernels
    it loaded carry over (which saves most of a kernel's start per notebook), while each
    notebook starts from an empty namespace (``%reset``), so a notebook that forgets an import
    still fails. The learned matchers are hidden (the SIFT fallback: the same path on every
    machine, and fast).
    """
    pytest.importorskip("nbclient")
    from ipykernel.kernelspec import write_kernel_spec
    from jupyter_client.manager import KernelManager

    base = tmp_path_factory.mktemp("kernel")
    write_kernel_spec(base / "jupyter" / "kernels" / "nbcalib-test")
    empty = base / "no_models"
    empty.mkdir()
    env = {**os.environ, "NBCALIB_NOTEBOOK_QUICK": "1", "NBCALIB_MODEL_DIR": str(empty)}
    env["JUPYTER_PATH"] = str(base / "jupyter")
    for name in ("MPLBACKEND", "NBCALIB_3D"):  # the kernel's own (inline) backend; the default
        env.pop(name, None)
    os.environ["JUPYTER_PATH"] = env["JUPYTER_PATH"]  # where the manager finds the spec
    try:
        manager = KernelManager(kernel_name="nbcalib-test")
        manager.start_kernel(env=env, cwd=str(base))
    finally:
        os.environ.pop("JUPYTER_PATH")
    hide = (
        "from pathlib import Path\n"
        "from nbcalib.matching import onnx_matcher\n"
        f"onnx_matcher.packaged_model_dir = lambda folder=Path({str(empty)!r}): folder\n"
    )
    yield manager, hide
    manager.shutdown_kernel(now=True)


def run_notebook(notebook: Path, work: Path, kernel):
    """Run ``notebook`` in the kernel in ``work``, then its check; return the notebook.

    Before the notebook, a cell outside it empties the namespace and moves to ``work``; after
    it, the check runs on the namespace the notebook left.
    """
    jupytext = pytest.importorskip("jupytext")
    from nbclient import NotebookClient
    from nbformat.v4 import new_code_cell

    manager, hide = kernel
    if not manager.is_alive():  # an earlier notebook killed it
        manager.restart_kernel(now=True)
    work.mkdir()
    nb = jupytext.read(notebook)
    client = NotebookClient(nb, km=manager, timeout=900)
    setup = new_code_cell(
        "%reset -f\n"
        "import os, matplotlib.pyplot\n"
        f"os.chdir({str(work)!r})\n"
        "matplotlib.pyplot.close('all')\n"
        "matplotlib.rcParams['figure.dpi'] = 30\n" + hide + "del os, matplotlib, Path, onnx_matcher"
    )
    nb.cells.insert(0, setup)  # nbclient stores each cell's outputs at its index
    client.reset_execution_trackers()
    try:
        with client.setup_kernel():
            for index, cell in enumerate(nb.cells):
                client.execute_cell(cell, index, execution_count=client.code_cells_executed + 1)
            nb.cells.pop(0)
            n_figures = len(_images(nb))
            check = new_code_cell(
                f"import sys; sys.path.insert(0, {str(TESTS)!r})\n"
                "import notebook_checks\n"
                f"ns = {{**globals(), '_figures': [None] * {n_figures}}}\n"
                f"notebook_checks.CHECKS[{notebook.stem!r}](ns)"
            )
            nb.cells.append(check)
            client.execute_cell(check, len(nb.cells) - 1)
            nb.cells.pop()
    finally:
        keep(notebook.stem, nb)  # also a notebook that failed, to look at
    return nb


def _outputs(nb):
    """(cell, output) of every code cell's outputs."""
    return [(cell, out) for cell in nb.cells if cell.cell_type == "code" for out in cell.outputs]


def _images(nb) -> list:
    return [out for _, out in _outputs(nb) if "image/png" in out.get("data", {})]


def keep(stem: str, nb) -> None:
    """Keep the executed notebook and its images where ``NBCALIB_NOTEBOOK_SAVE`` and
    ``NBCALIB_NOTEBOOK_FIGURES`` say (when set)."""
    import nbformat

    folder = os.environ.get("NBCALIB_NOTEBOOK_SAVE")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        nbformat.write(nb, Path(folder) / f"{stem}.ipynb")
    folder = os.environ.get("NBCALIB_NOTEBOOK_FIGURES")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        for k, out in enumerate(_images(nb)):
            png = base64.b64decode(out["data"]["image/png"])
            (Path(folder) / f"{stem}_{k:02d}.png").write_bytes(png)


def check_outputs(nb) -> None:
    """What a learner meets in the saved notebook: 3-D views as images, no reprs, no stderr."""
    from nbcalib.teaching import egl_available

    try:
        import pyvista  # noqa: F401

        renders = egl_available() or sys.platform != "linux"
    except ImportError:
        renders = False
    problems = []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        where = f"cell {cell.source[:50]!r}"
        for out in cell.outputs:
            if out.output_type == "error":
                problems.append(f"{where}: {out.ename}")
            elif out.output_type == "stream":
                said = [line for line in out.text.splitlines() if not EXPECTED_WARNING.match(line)]
                if out.name != "stdout" and said:
                    problems.append(f"{where}: standard error: {said[:3]!r}")
            else:
                text = out.get("data", {}).get("text/plain", "")
                if OBJECT_REPR.search(text):
                    problems.append(f"{where}: shows {text[:80]!r}")
                if "application/vnd.jupyter.widget-view+json" in out.get("data", {}):
                    problems.append(f"{where}: a widget, gone with the kernel")
        if renders and re.search(r"^\s*\w+ = show\(pl\b", cell.source, re.M):
            views = [
                out
                for out in cell.outputs
                if "image/png" in out.get("data", {})
                and out.get("metadata", {}).get("nbcalib", {}).get("view") == "3-D"
            ]
            if len(views) != 1:
                problems.append(f"{where}: {len(views)} images of its 3-D view, not 1")
    assert not problems, "\n".join(problems)


# ============================================================================ the tests


def test_notebooks_found():
    assert len(NOTEBOOKS) >= 7
    assert {p.stem for p in NOTEBOOKS} == set(CHECKS), "every notebook needs a check"


@pytest.mark.slow
@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_teaches(notebook, tmp_path, kernel):
    nb = run_notebook(notebook, tmp_path / "work", kernel)
    check_outputs(nb)


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_percent_format(notebook):
    text = notebook.read_text()
    assert text.startswith("# ---\n# jupyter:"), "jupytext header missing"
    assert "# %% [markdown]" in text and "\n# %%\n" in text
    # paired with an .ipynb beside it (the learner's copy with outputs, ignored by git)
    assert "#     formats: ipynb,py:percent\n" in text


def test_saving_a_notebook_in_jupyterlab_changes_no_script(tmp_path):
    """JupyterLab saves through jupytext's contents manager: the script comes back unchanged
    (no version header, no git diff), and the .ipynb with the outputs is written beside it."""
    pytest.importorskip("jupytext")
    from jupytext.sync_contentsmanager import TextFileContentsManager

    for notebook in NOTEBOOKS:
        (tmp_path / notebook.name).write_text(notebook.read_text())
    manager = TextFileContentsManager(root_dir=str(tmp_path))
    for notebook in NOTEBOOKS:
        model = manager.get(notebook.name, content=True, type="notebook")
        manager.save(model, notebook.name)
        assert (tmp_path / notebook.name).read_text() == notebook.read_text(), notebook.name
        assert (tmp_path / notebook.name).with_suffix(".ipynb").is_file(), notebook.name


def test_jupyterlab_opens_the_scripts_as_notebooks():
    """The lab setting the package installs: a .py opens as a notebook (links between them too)."""
    import json

    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib

    root = Path(__file__).parents[1]
    shipped = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["hatch"]["build"]
    shared = shipped["targets"]["wheel"]["shared-data"]
    source, target = next(iter(shared.items()))
    assert target == "etc/jupyter/labconfig/default_setting_overrides.d/nbcalib.json"
    settings = json.loads((root / source).read_text())
    viewers = settings["@jupyterlab/docmanager-extension:plugin"]["defaultViewers"]
    assert viewers == {"python": "Jupytext Notebook"}


def test_no_notebook_is_stored_with_outputs():
    """The notebooks are percent scripts; a committed .ipynb would carry outputs and drift.

    Local .ipynb copies (``jupytext --to ipynb``) are ignored by git, so only tracked files
    count; outside a git checkout, every .ipynb under notebooks/.
    """
    import subprocess

    root = Path(__file__).parents[1]
    try:
        listed = subprocess.run(
            ["git", "ls-files", "notebooks"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.split()
    except (OSError, subprocess.CalledProcessError):
        listed = [str(p.relative_to(root)) for p in (root / "notebooks").rglob("*")]
    stored = [name for name in listed if name.endswith(".ipynb")]
    assert not stored, stored


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_opens_as_a_notebook(notebook):
    """jupytext reads it into cells: a numbered title first, a check list last, no outputs."""
    jupytext = pytest.importorskip("jupytext")
    nb = jupytext.read(notebook)
    cells = nb.cells
    assert cells[0].cell_type == "markdown"
    number = int(notebook.stem[:2])
    assert cells[0].source.startswith(f"# {number}. "), cells[0].source[:40]
    assert cells[-1].cell_type == "markdown" and "## What we checked" in cells[-1].source
    assert sum(c.cell_type == "code" for c in cells) >= 4
    assert all(not c.get("outputs") for c in cells if c.cell_type == "code")
    if number < len(NOTEBOOKS) - 1:  # each points to the next
        following = NOTEBOOKS[number + 1].stem
        assert f"[{following}]({following}.py)" in notebook.read_text(), following


def test_teaching_3d_views_without_pyvista(monkeypatch, capsys):
    from nbcalib import teaching

    monkeypatch.setitem(sys.modules, "pyvista", None)  # import fails
    assert teaching.plotter() is None
    assert "pip install 'nbcalib[notebooks]'" in capsys.readouterr().out


def test_teaching_off_screen(monkeypatch):
    from nbcalib import teaching

    monkeypatch.setenv("NBCALIB_NOTEBOOK_QUICK", "1")
    assert teaching.is_quick() and teaching.off_screen()
    monkeypatch.delenv("NBCALIB_NOTEBOOK_QUICK")
    monkeypatch.delenv("PYVISTA_OFF_SCREEN", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setenv("DISPLAY", ":0")
    assert not teaching.is_quick() and not teaching.off_screen()  # a desktop: a window
    monkeypatch.delenv("DISPLAY")
    assert teaching.off_screen()  # a script on a server: a still image
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(teaching, "in_jupyter", lambda: True)
    assert teaching.off_screen()  # a notebook, even on a desktop: a still image first


def test_teaching_live_views_where_the_kernel_can_serve_one(monkeypatch):
    import importlib.util

    from nbcalib import teaching

    for name in ("NBCALIB_3D", "NBCALIB_NOTEBOOK_QUICK", "PYVISTA_OFF_SCREEN", "SSH_CONNECTION"):
        monkeypatch.delenv(name, raising=False)
    for name in ("PYVISTA_TRAME_SERVER_PROXY_PREFIX", "JUPYTERHUB_SERVICE_PREFIX"):
        monkeypatch.delenv(name, raising=False)
    installed = {"trame", "jupyter_server_proxy"}
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name: object() if name in installed else None
    )
    assert not teaching.live_views()  # not in a kernel
    monkeypatch.setattr(teaching, "in_jupyter", lambda: True)
    assert teaching.live_views()  # a lab on this machine
    monkeypatch.setenv("SSH_CONNECTION", "10.0.0.1 50000 10.0.0.2 22")
    assert not teaching.live_views()  # a lab behind an SSH tunnel: the kernel's port is not seen
    monkeypatch.setenv("PYVISTA_TRAME_SERVER_PROXY_PREFIX", "/proxy/")
    assert teaching.live_views()  # ... unless the view goes through the Jupyter server
    installed.discard("jupyter_server_proxy")
    assert not teaching.live_views()  # which needs jupyter-server-proxy
    monkeypatch.setenv("NBCALIB_3D", "live")
    assert teaching.live_views()
    monkeypatch.setenv("NBCALIB_3D", "image")
    monkeypatch.delenv("SSH_CONNECTION")
    installed.add("jupyter_server_proxy")
    assert not teaching.live_views()
    monkeypatch.delenv("NBCALIB_3D")
    monkeypatch.setenv("NBCALIB_NOTEBOOK_QUICK", "1")
    assert not teaching.live_views()  # the tests: still images only
    monkeypatch.delenv("NBCALIB_NOTEBOOK_QUICK")
    installed.discard("trame")
    assert not teaching.live_views()


@pytest.mark.parametrize("live", [False, True])
def test_teaching_in_jupyter_shows_a_still_image_then_the_live_view(monkeypatch, live):
    """In a kernel: the still image at once (kept in the saved notebook), then the live view
    with a text a saved notebook can show instead of a dead widget."""
    pv = pytest.importorskip("pyvista")
    import IPython.display

    from nbcalib import teaching

    monkeypatch.delenv("NBCALIB_NOTEBOOK_QUICK", raising=False)
    monkeypatch.delenv("PYVISTA_OFF_SCREEN", raising=False)
    monkeypatch.setenv("NBCALIB_3D", "live" if live else "image")
    monkeypatch.setattr(teaching, "in_jupyter", lambda: True)
    if not teaching.has_display() and not teaching.egl_available():
        pytest.skip("no display and no EGL")
    shown = []
    monkeypatch.setattr(IPython.display, "display", lambda *a, **kw: shown.append((a, kw)))

    class Widget:
        def _repr_mimebundle_(self):
            view = {"model_id": "1"}
            return {"application/vnd.jupyter.widget-view+json": view, "text/plain": "W"}

    monkeypatch.setattr(pv.Plotter, "show", lambda self, **kw: Widget())
    pl = teaching.plotter(window_size=(80, 60))
    pl.add_points(np.random.default_rng(0).normal(size=(50, 3)), color="red", point_size=8)
    image = teaching.show(pl, "a view")
    assert image.shape == (60, 80, 3)
    (figure,), kw = shown[0]
    assert kw["metadata"]["nbcalib"] == {"view": "3-D", "title": "a view"}
    import matplotlib.pyplot as plt

    assert figure.number not in plt.get_fignums()  # shown once, by the display above
    if live:
        (bundle,), kw = shown[1]
        assert kw == {"raw": True} and bundle["text/plain"] == teaching.LIVE_VIEW_TEXT
        assert "application/vnd.jupyter.widget-view+json" in bundle
    assert len(shown) == 1 + live


def test_teaching_renders_off_screen(monkeypatch):
    """A pyvista view renders off screen through EGL into a still figure (CI must manage it)."""
    import matplotlib.pyplot as plt

    from nbcalib import teaching

    if not os.environ.get("CI"):
        pytest.importorskip("pyvista")
    monkeypatch.setenv("NBCALIB_NOTEBOOK_QUICK", "1")
    pl = teaching.plotter(window_size=(160, 120))
    assert pl is not None, "no pyvista, or no EGL"
    pl.add_points(np.random.default_rng(0).normal(size=(500, 3)), color="red", point_size=8)
    before = len(plt.get_fignums())
    try:
        image = teaching.show(pl, "points")
        assert image.shape == (120, 160, 3) and image.dtype == np.uint8
        assert image.std() > 5  # not blank: red points on the background
        assert len(plt.get_fignums()) == before + 1  # shown as a still figure
    finally:
        plt.close("all")


def test_teaching_runs_a_command_as_typed_and_leaves_the_logger(capsys, tmp_path):
    import logging

    from nbcalib import teaching

    logger = logging.getLogger("nbcalib")
    before = (list(logger.handlers), logger.level)
    status, out = teaching.nbcalib_command("evaluate", tmp_path / "no such", "--ground-truth", "x")
    printed = capsys.readouterr()
    assert status == 2 and out == ""
    assert printed.out.startswith("$ nbcalib evaluate ") and "--ground-truth x" in printed.out
    assert "(exit status 2)" in printed.out and "work directory not found" in printed.err
    assert (list(logger.handlers), logger.level) == before


def test_teaching_finds_the_real_data(monkeypatch, tmp_path):
    from nbcalib import teaching

    monkeypatch.setenv("NBCALIB_REAL_DATA", str(tmp_path))
    assert teaching.real_data_dir() == tmp_path
    monkeypatch.delenv("NBCALIB_REAL_DATA")
    beside = Path(teaching.__file__).resolve().parents[2] / "shared" / "data" / "real"
    monkeypatch.chdir(tmp_path)  # a working folder of no project: the one beside the package
    assert teaching.real_data_dir() == beside


def test_teaching_says_when_kernels_will_compile(monkeypatch, capsys):
    from nbcalib import teaching, warmup

    monkeypatch.setattr(warmup, "cache_is_warm", lambda: False)
    assert teaching.first_run_note()
    assert "numba compiles nbcalib's kernels" in capsys.readouterr().out
    monkeypatch.setattr(warmup, "cache_is_warm", lambda: True)
    assert not teaching.first_run_note() and capsys.readouterr().out == ""
