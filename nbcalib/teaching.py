"""What the teaching notebooks (``notebooks/``) share: their quick mode and their 3-D views.

The notebooks open interactive 3-D views in JupyterLab (pyvista, from ``nbcalib[notebooks]``).
Where there is no display (CI, a server, the test suite), a view is rendered off screen through
VTK's EGL window, which needs only Mesa's ``libegl1`` and ``libgl1-mesa-dri`` (no X server, no
Xvfb), and shown as a still image with matplotlib, so that it appears in the notebook's outputs
like any other figure.

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

__all__ = ["egl_available", "is_quick", "off_screen", "plotter", "show"]


def is_quick() -> bool:
    """Whether the notebooks should run on small data (``NBCALIB_NOTEBOOK_QUICK=1``, as in CI)."""
    return os.environ.get("NBCALIB_NOTEBOOK_QUICK") == "1"


def off_screen() -> bool:
    """Whether 3-D views are rendered to still images rather than opened interactively.

    Off screen under the quick mode, with ``PYVISTA_OFF_SCREEN=true``, or on Linux without a
    display; interactive otherwise (JupyterLab on a desktop).
    """
    if is_quick() or os.environ.get("PYVISTA_OFF_SCREEN", "").lower() == "true":
        return True
    return sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


def egl_available() -> bool:
    """Whether the EGL library VTK renders off screen with can be loaded (Linux)."""
    import ctypes

    try:
        ctypes.CDLL("libEGL.so.1")
    except OSError:
        return False
    return True


def plotter(window_size=(900, 600), **kwargs):
    """A ``pyvista.Plotter``, off screen where :func:`off_screen` says; None without pyvista.

    Off screen, VTK is told to use its EGL window (``VTK_DEFAULT_OPENGL_WINDOW``), unless the
    variable is already set: VTK's X window would fail without an X server.
    """
    try:
        import pyvista as pv
    except ImportError:
        print("pyvista is not installed, so no 3-D view: pip install 'nbcalib[notebooks]'")
        return None
    hidden = off_screen()
    if hidden and sys.platform.startswith("linux"):
        if not egl_available():
            print(
                "no 3-D view: rendering off screen needs Mesa's EGL "
                "(apt install libegl1 libgl1-mesa-dri)"
            )
            return None
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    return pv.Plotter(off_screen=hidden, window_size=list(window_size), **kwargs)


def show(pl, title: str | None = None) -> np.ndarray | None:
    """Show a plotter: interactively, or off screen as a still matplotlib figure.

    Returns the rendered (H, W, 3) uint8 image off screen (the notebooks' tests check that it
    is not blank), None when the view opened interactively.
    """
    if not pl.off_screen:
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
