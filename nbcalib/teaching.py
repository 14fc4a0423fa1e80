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

import numpy as np

__all__ = [
    "egl_available",
    "has_display",
    "in_jupyter",
    "is_quick",
    "off_screen",
    "plotter",
    "show",
]


def is_quick() -> bool:
    """Whether the notebooks should run on small data (``NBCALIB_NOTEBOOK_QUICK=1``, as in CI)."""
    return os.environ.get("NBCALIB_NOTEBOOK_QUICK") == "1"


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
