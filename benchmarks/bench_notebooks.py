"""The teaching notebooks as a learner meets them: run in a kernel, then opened in JupyterLab.

Phase ``run``: each notebook is opened by jupytext and executed cell by cell in a real IPython
kernel (nbclient), in ``OUT/notebooks`` (a copy of ``notebooks/``, so its ``work/`` folders
land there), the learner's data sizes (or ``--quick``: the tests' small ones). For every cell:
its wall time and its longest silence, the longest time with no new output (a line, a figure,
a progress bar moving), from the cell's start to its end. The executed notebook is saved beside
its script as ``OUT/notebooks/NN_name.ipynb``, as JupyterLab saves a paired notebook.

Phase ``lab``: JupyterLab (``jupyter lab``, headless, no kernel it may start: the saved copies
are looked at as a reader without the kernel would) in ``OUT/notebooks``, driven by Chromium
(playwright, ``--browser`` or Debian's ``/usr/bin/chromium``). Each saved ``.ipynb`` is opened;
the images JupyterLab draws are counted against the image outputs the file holds, and the page
is searched for object reprs and dead widgets; a screenshot of its first screen and of each 3-D
view goes to ``OUT/screens``. Then, from ``00_frames_and_transforms.py`` opened with a double
click's default viewer, the "Next" link of each notebook is clicked: each must open the next
notebook as a notebook (not in the text editor).

    python benchmarks/bench_notebooks.py --out nb_run                 # both phases, full mode
    python benchmarks/bench_notebooks.py --out nb_run --phase run 06 07
    python benchmarks/bench_notebooks.py --out nb_run --phase lab     # the saved copies again
    python benchmarks/bench_notebooks.py --out nb_run --phase run --cold  # each: an empty cache

Needs ``pip install -e ".[notebooks,dev]"``; the lab phase also ``pip install playwright`` and a
Chromium (``apt install chromium``). One job at a time, on an idle machine. Prints Markdown
tables; the last line is one JSON object with every figure; exits 1 when a check fails.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.py"))
OUTPUTS = {"stream", "display_data", "execute_result", "update_display_data", "error"}
OBJECT_REPR = re.compile(r"<[\w.]+(?: object)? at 0x[0-9a-f]+>")


# ============================================================================ run


def run_notebook(script: Path, kernel: str) -> dict:
    """Execute ``script`` (jupytext) in a kernel in its folder; save the .ipynb beside it."""
    import jupytext
    import nbformat
    from nbclient import NotebookClient

    class Timed(NotebookClient):
        """Notes when each output message of a cell arrives."""

        def process_message(self, msg, cell, cell_index):
            if msg["msg_type"] in OUTPUTS:
                self.arrivals.append(time.monotonic())
            return super().process_message(msg, cell, cell_index)

    nb = jupytext.read(script)
    client = Timed(
        nb, timeout=3600, kernel_name=kernel, resources={"metadata": {"path": str(script.parent)}}
    )
    cells, error = [], None
    t0 = time.monotonic()
    client.reset_execution_trackers()
    with client.setup_kernel():
        for index, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            client.arrivals = []
            start = time.monotonic()
            try:
                client.execute_cell(cell, index, execution_count=client.code_cells_executed + 1)
            except Exception as exc:  # the notebook failed: keep what it did, say where
                error = f"cell {index}: {type(exc).__name__}: {str(exc).strip()[-300:]}"
            end = time.monotonic()
            times = [start, *[t for t in client.arrivals if start <= t <= end], end]
            silence = max(b - a for a, b in itertools.pairwise(times))
            first = cell.source.strip().splitlines()[0] if cell.source.strip() else ""
            cells.append(
                {
                    "index": index,
                    "seconds": end - start,
                    "silence": silence,
                    "to_first_output": times[1] - start,  # the cell's end when it shows nothing
                    "calls_calibrate": "nbcalib.calibrate(" in cell.source,
                    "first": first[:60],
                }
            )
            if error:
                break
    nbformat.write(nb, script.with_suffix(".ipynb"))
    # each image output in order: is it a 3-D view (nbcalib.teaching.show marks them)?
    views = [
        out.get("metadata", {}).get("nbcalib", {}).get("view") == "3-D"
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.outputs
        if "image/png" in out.get("data", {})
    ]
    return {
        "seconds": time.monotonic() - t0,
        "cells": cells,
        "images": len(views),
        "views": views,
        "error": error,
        "stderr": [
            out.text[:200]
            for cell in nb.cells
            if cell.cell_type == "code"
            for out in cell.outputs
            if out.output_type == "stream" and out.name == "stderr"
        ],
        "reprs": [
            OBJECT_REPR.search(out["data"]["text/plain"]).group(0)
            for cell in nb.cells
            if cell.cell_type == "code"
            for out in cell.outputs
            if OBJECT_REPR.search(out.get("data", {}).get("text/plain", ""))
        ],
    }


def phase_run(folder: Path, scripts: list[Path], quick: bool, cold: bool) -> dict:
    from ipykernel.kernelspec import write_kernel_spec

    kernels = Path(tempfile.mkdtemp(prefix="nbcalib_kernels_"))
    write_kernel_spec(kernels / "kernels" / "nbcalib-bench")  # this Python, whatever else
    os.environ["JUPYTER_PATH"] = str(kernels)
    os.environ.pop("NBCALIB_NOTEBOOK_QUICK", None)
    os.environ.pop("MPLBACKEND", None)
    if quick:
        os.environ["NBCALIB_NOTEBOOK_QUICK"] = "1"
    results = {}
    print("| notebook | wall | longest silence (cell) | images | stderr, reprs |")
    print("|---|---|---|---|---|")
    for source in scripts:
        script = folder / source.name
        if cold:  # each notebook as the first thing run on a fresh install
            os.environ["NUMBA_CACHE_DIR"] = tempfile.mkdtemp(prefix="nbcalib_numba_")
        result = run_notebook(script, "nbcalib-bench")
        results[source.stem] = result
        worst = max(result["cells"], key=lambda c: c["silence"])
        flags = f"{len(result['stderr'])}, {len(result['reprs'])}"
        api = [c["to_first_output"] for c in result["cells"] if c["calls_calibrate"]]
        if api:
            flags += f"; nbcalib.calibrate shows progress after {max(api):.2f} s"
        if result["error"]:
            flags += f"; FAILED {result['error']}"
        print(
            f"| {source.stem} | {result['seconds']:.1f} s | {worst['silence']:.1f} s "
            f"(`{worst['first']}`) | {result['images']} | {flags} |",
            flush=True,
        )
    shutil.rmtree(kernels, ignore_errors=True)
    return results


# ============================================================================ lab


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_lab(folder: Path, config: Path) -> tuple[subprocess.Popen, str]:
    """JupyterLab in ``folder``: no token prompt, no kernels, every cell drawn (no windowing)."""
    overrides = config / "labconfig" / "default_setting_overrides.json"
    overrides.parent.mkdir(parents=True, exist_ok=True)
    # every cell in the page (JupyterLab draws only the visible ones by default), no dialogs
    overrides.write_text(
        json.dumps(
            {
                "@jupyterlab/notebook-extension:tracker": {"windowingMode": "none"},
                "@jupyterlab/apputils-extension:notification": {"fetchNews": "false"},
            }
        )
    )
    token, port = secrets.token_hex(16), _free_port()
    env = dict(os.environ, JUPYTER_CONFIG_PATH=str(config))
    lab = subprocess.Popen(
        [
            sys.executable, "-m", "jupyter", "lab", "--no-browser", f"--port={port}",
            f"--ServerApp.token={token}", f"--ServerApp.root_dir={folder}",
            # no kernel to start: the saved notebooks are read as a reader without one would
            "--KernelSpecManager.allowed_kernelspecs=no-kernel-here",
            "--KernelSpecManager.ensure_native_kernel=False",
            "--allow-root",  # a container's root (the lab serves only this machine's browser)
        ],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    url = f"http://127.0.0.1:{port}"
    for _ in range(120):
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                break
        except OSError:
            time.sleep(0.5)
    # ?reset: a fresh workspace each time, not the tabs the last page left open
    return lab, f"{url}/lab/tree/{{path}}?reset&token={token}"


def _dismiss_kernel_dialog(page, wait: float = 10.0) -> None:
    """Answer 'No Kernel' to each 'select a kernel' dialog (there is none to select)."""
    button = page.locator(".jp-Dialog button:has-text('No Kernel')")
    deadline = time.monotonic() + wait
    while time.monotonic() < deadline:
        if button.count():
            try:
                button.first.click(timeout=2000)
            except Exception:  # gone meanwhile
                pass
            deadline = min(deadline, time.monotonic() + 2.0)  # another may follow at once
        page.wait_for_timeout(250)


def _open(page, url: str) -> None:
    page.goto(url)
    page.locator(".jp-NotebookPanel:visible .jp-Notebook .jp-Cell").first.wait_for(timeout=60000)
    _dismiss_kernel_dialog(page)
    page.wait_for_timeout(1500)


def check_saved(page, template: str, stem: str, views: list[bool], screens: Path) -> dict:
    """Open the saved ``stem.ipynb``; count what JupyterLab draws; screenshots."""
    images = len(views)
    _open(page, template.format(path=f"{stem}.ipynb"))
    panel = page.locator(".jp-NotebookPanel:visible").last
    drawn = panel.locator(".jp-OutputArea-output img")
    # images load lazily as data URLs: wait until each is decoded
    page.wait_for_function(
        "n => [...document.querySelectorAll('.jp-NotebookPanel:not(.lm-mod-hidden) "
        ".jp-OutputArea-output img')].filter(i => i.complete && i.naturalWidth > 0).length >= n",
        arg=images,
        timeout=60000,
    )
    text = panel.inner_text()
    page.screenshot(path=str(screens / f"{stem}.png"))
    shots = 0
    if drawn.count() == images:  # in the file's order: the 3-D views are the marked ones
        for k in (k for k, view in enumerate(views) if view):
            drawn.nth(k).scroll_into_view_if_needed()
            page.wait_for_timeout(300)
            page.screenshot(path=str(screens / f"{stem}_3d_{shots}.png"))
            shots += 1
    return {
        "drawn": drawn.count(),
        "views_3d": shots,
        "reprs": OBJECT_REPR.findall(text),
        "dead_widgets": text.count("Error displaying widget") + text.count("Loading widget"),
    }


def walk_links(page, template: str, stems: list[str]) -> list[dict]:
    """From notebook 00's script, click each "Next" link; each must open as a notebook."""
    steps = []
    _open(page, template.format(path=f"{stems[0]}.py"))
    for current, following in itertools.pairwise(stems):
        panel = page.locator(".jp-NotebookPanel:not(.lm-mod-hidden)").last
        link = panel.locator(f".jp-MarkdownOutput a:has-text('{following}')").last
        link.scroll_into_view_if_needed()
        link.click()
        # the next one as a notebook: a notebook panel whose tab is the next script
        tab = page.locator(f".lm-TabBar-tab.jp-mod-current:has-text('{following}.py')")
        tab.wait_for(timeout=30000)
        notebook = page.locator(".jp-NotebookPanel:not(.lm-mod-hidden) .jp-Notebook .jp-Cell")
        try:
            notebook.first.wait_for(timeout=30000)
        except Exception:  # opened, but not as a notebook (the text editor)
            editor = page.locator(".jp-FileEditor:not(.lm-mod-hidden)").count()
            steps.append({"from": current, "to": following, "title": None, "editor": editor})
            break
        _dismiss_kernel_dialog(page)
        title = page.locator(".jp-NotebookPanel:not(.lm-mod-hidden) .jp-MarkdownOutput h1").first
        steps.append({"from": current, "to": following, "title": title.inner_text()[:60]})
        page.wait_for_timeout(500)
    return steps


def phase_lab(folder: Path, results: dict, out: Path, browser: str | None) -> dict:
    from playwright.sync_api import sync_playwright

    screens = out / "screens"
    screens.mkdir(exist_ok=True)
    config = Path(tempfile.mkdtemp(prefix="nbcalib_lab_"))
    lab, template = start_lab(folder, config)
    checked, steps = {}, []
    try:
        with sync_playwright() as p:
            executable = browser or shutil.which("chromium") or shutil.which("chromium-browser")
            chromium = p.chromium.launch(executable_path=executable, headless=True)
            page = chromium.new_page(viewport={"width": 1400, "height": 1000})
            print("\n| saved notebook, opened with no kernel | images in the file | drawn |"
                  " 3-D views | reprs, dead widgets |\n|---|---|---|---|---|")  # fmt: skip
            for stem, result in results.items():
                seen = check_saved(page, template, stem, result["views"], screens)
                checked[stem] = seen
                print(
                    f"| {stem} | {result['images']} | {seen['drawn']} | {seen['views_3d']} | "
                    f"{len(seen['reprs'])}, {seen['dead_widgets']} |",
                    flush=True,
                )
            stems = [nb.stem for nb in NOTEBOOKS]
            steps = walk_links(chromium.new_page(viewport={"width": 1400, "height": 1000}),
                               template, stems)  # fmt: skip
            print("\n| link clicked | opened as a notebook, its title |\n|---|---|")
            for step in steps:
                opened = step["title"] or "NOT as a notebook" + (" (text editor)" * step["editor"])
                print(f"| {step['from']} -> {step['to']} | {opened} |")
            chromium.close()
    finally:
        lab.terminate()
        lab.wait(timeout=30)
        shutil.rmtree(config, ignore_errors=True)
    return {"saved": checked, "links": steps}


# ============================================================================ main


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__.splitlines()[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("only", nargs="*", help="name prefixes of the notebooks to run")
    parser.add_argument("--out", type=Path, required=True, help="folder for everything written")
    parser.add_argument("--phase", choices=["run", "lab", "all"], default="all")
    parser.add_argument("--quick", action="store_true", help="the tests' quick mode")
    parser.add_argument("--cold", action="store_true", help="each notebook: an empty numba cache")
    parser.add_argument("--browser", help="Chromium's executable (default: chromium on PATH)")
    args = parser.parse_args(argv)
    scripts = NOTEBOOKS
    if args.only:
        scripts = [nb for nb in scripts if nb.stem.startswith(tuple(args.only))]
    folder = args.out / "notebooks"
    folder.mkdir(parents=True, exist_ok=True)
    for script in NOTEBOOKS:  # all of them, for the links (only the ones run get an .ipynb)
        shutil.copy(script, folder / script.name)
    record = args.out / "run.json"
    figures: dict = {"quick": args.quick, "cold": args.cold}
    if args.phase in ("run", "all"):
        figures["run"] = phase_run(folder, scripts, args.quick, args.cold)
        record.write_text(json.dumps(figures["run"], indent=1))
    else:
        figures["run"] = json.loads(record.read_text())
    failed = [s for s, r in figures["run"].items() if r["error"] or r["stderr"] or r["reprs"]]
    if args.phase in ("lab", "all"):
        figures["lab"] = phase_lab(folder, figures["run"], args.out, args.browser)
        failed += [
            stem
            for stem, seen in figures["lab"]["saved"].items()
            if seen["drawn"] < figures["run"][stem]["images"] or seen["reprs"]
        ]
        links = figures["lab"]["links"]
        if len(links) < len(NOTEBOOKS) - 1 or not all(step["title"] for step in links):
            failed.append("links")
    print(json.dumps(figures))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
