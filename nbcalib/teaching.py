"""What the teaching notebooks (``notebooks/``) share: their quick mode and their 3-D views.

The notebooks' 3-D views (pyvista, from ``nbcalib[notebooks]``) can be turned in JupyterLab,
through pyvista's notebook backend, on a desktop or on a server. In the tests and CI (the quick
mode), and in scripts where no window can open, a view is rendered off screen and shown as a
still image with matplotlib, so that it appears in the outputs like any other figure. Without
a display, VTK renders through its EGL window, which needs only Mesa's ``libegl1`` and
``libgl1-mesa-dri`` (no X server, no Xvfb).

    from nbcalib.teaching import is_quick, plotter, show

    QUICK = is_quick()              # small data when the test suite runs the notebook
    pl = plotter()                  # None (and a message) when pyvista is not installed
    if pl is not None:
        pl.add_points(points, scalars=intensities)
        image = show(pl, "the dense cloud")   # the rendered RGB image, or None when interactive
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

__all__ = [
    "egl_available",
    "has_display",
    "in_jupyter",
    "is_quick",
    "nbcalib_command",
    "off_screen",
    "plotter",
    "real_data_dir",
    "show",
]


def is_quick() -> bool:
    """Whether the notebooks should run on small data (``NBCALIB_NOTEBOOK_QUICK=1``, as in CI)."""
    return os.environ.get("NBCALIB_NOTEBOOK_QUICK") == "1"


def real_data_dir() -> Path:
    """The real recordings nbcalib's developers keep beside the repository (not shipped).

    ``$NBCALIB_REAL_DATA`` if set; else ``../shared/data/real`` beside the repository this
    module (an editable install) or the working folder's project lives in, the first that
    exists; else that first place, which does not exist (callers then fall back and say so).
    """
    if os.environ.get("NBCALIB_REAL_DATA"):
        return Path(os.environ["NBCALIB_REAL_DATA"])
    tail = Path("shared", "data", "real")
    candidates = [Path(__file__).resolve().parents[2] / tail]  # <repo>/nbcalib/teaching.py
    cwd = Path.cwd().resolve()
    candidates += [folder / tail for folder in (cwd.parent, cwd.parent.parent)]  # notebooks/
    return next((c for c in candidates if c.is_dir()), candidates[0])


def nbcalib_command(*words) -> tuple[int, str]:
    """Run ``nbcalib WORDS`` as typed in a terminal, in this process; print it and its output.

    What a terminal shows: the command line, then what it prints (its progress lines go to
    stderr as in a terminal), and the exit status when it is not 0. Returns ``(status,
    stdout)``. The ``nbcalib`` logger is left as it was found.
    """
    import contextlib
    import io
    import logging
    import shlex

    from nbcalib.cli import main

    words = [str(w) for w in words]
    print("$ nbcalib", shlex.join(words))
    out = io.StringIO()
    logger = logging.getLogger("nbcalib")
    handlers, level = list(logger.handlers), logger.level
    try:
        with contextlib.redirect_stdout(out):
            status = main(words)
    finally:
        logger.handlers[:] = handlers
        logger.setLevel(level)
    text = out.getvalue()
    print(text, end="" if text.endswith("\n") or not text else "\n")
    if status:
        print(f"(exit status {status})")
    return status, text


def in_jupyter() -> bool:
    """Whether this code runs in a Jupyter kernel (JupyterLab, Notebook, VS Code notebooks)."""
    shell = sys.modules.get("IPython") and sys.modules["IPython"].get_ipython()
    return type(shell).__name__ == "ZMQInteractiveShell"


def has_display() -> bool:
    """Whether a window can open: not Linux, or Linux with an X or Wayland display."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def off_screen() -> bool:
    """Whether 3-D views become still images rather than views you can turn.

    Still images under the quick mode or with ``PYVISTA_OFF_SCREEN=true`` (the tests, CI), and
    outside Jupyter where no window can open (a script on a server). In a Jupyter kernel the
    view is interactive (pyvista's notebook backend: trame, from ``nbcalib[notebooks]``), also
    on a server without a display; on a desktop outside Jupyter it opens a window.
    """
    if is_quick() or os.environ.get("PYVISTA_OFF_SCREEN", "").lower() == "true":
        return True
    return not in_jupyter() and not has_display()


def egl_available() -> bool:
    """Whether the EGL library VTK renders off screen with can be loaded (Linux)."""
    import ctypes

    try:
        ctypes.CDLL("libEGL.so.1")
    except OSError:
        return False
    return True


def plotter(window_size=(900, 600), **kwargs):
    """A ``pyvista.Plotter`` for :func:`show`; None (and a message) without pyvista or EGL.

    Where no display is (CI, a server, JupyterLab on a server), VTK is told to render through
    its EGL window (``VTK_DEFAULT_OPENGL_WINDOW``, unless already set): its X window would fail
    without an X server.
    """
    try:
        import pyvista as pv
    except ImportError:
        print("pyvista is not installed, so no 3-D view: pip install 'nbcalib[notebooks]'")
        return None
    still = off_screen()
    if not has_display():
        if not egl_available():
            print(
                "no 3-D view: rendering without a display needs Mesa's EGL "
                "(apt install libegl1 libgl1-mesa-dri)"
            )
            return None
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    notebook = in_jupyter() and not still
    pl = pv.Plotter(off_screen=still, notebook=notebook, window_size=list(window_size), **kwargs)
    pl._nbcalib_still = still  # what show() does with it
    return pl


def show(pl, title: str | None = None) -> np.ndarray | None:
    """Show a plotter from :func:`plotter`: a view to turn, or a still matplotlib figure.

    Returns the rendered (H, W, 3) uint8 image when still (the notebooks' tests check that it
    is not blank), None when the view is interactive (a notebook widget or a window).
    """
    if not getattr(pl, "_nbcalib_still", pl.off_screen):
        pl.show(title=title)
        return None
    image = np.asarray(pl.screenshot(return_img=True))
    pl.close()
    import matplotlib.pyplot as plt

    height, width = image.shape[:2]
    fig, ax = plt.subplots(figsize=(width / 100, height / 100))
    ax.imshow(image)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    return image
