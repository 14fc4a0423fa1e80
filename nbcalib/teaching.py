"""What the teaching notebooks (``notebooks/``) share: their quick mode and their 3-D views.

The notebooks' 3-D views (pyvista, from ``nbcalib[notebooks]``) are always shown as a still
image (a matplotlib figure of the off-screen render), so they stay in a saved, executed or
shared notebook like any other figure, and reach a browser through any tunnel. In a Jupyter
kernel, where the kernel can serve one (:func:`live_views`), a view to turn (pyvista's trame
widget) is shown beside it. On a desktop outside Jupyter the view opens in a window. Without a
display, VTK renders through its EGL window, which needs only Mesa's ``libegl1`` and
``libgl1-mesa-dri`` (no X server, no Xvfb).

    from nbcalib.teaching import is_quick, plotter, show

    QUICK = is_quick()              # small data when the test suite runs the notebook
    pl = plotter()                  # None (and a message) when pyvista is not installed
    if pl is not None:
        pl.add_points(points, scalars=intensities)
        image = show(pl, "the dense cloud")   # the rendered RGB image, or None in a window
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from nbcalib.progress import in_jupyter

__all__ = [
    "egl_available",
    "first_run_note",
    "has_display",
    "in_jupyter",
    "is_quick",
    "live_views",
    "nbcalib_command",
    "off_screen",
    "plotter",
    "real_data_dir",
    "show",
    "textured_box",
    "work_folder",
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


def work_folder(name: str) -> Path:
    """An empty folder ``work/NAME`` where the notebook runs, for what it writes.

    In JupyterLab a notebook runs in its own folder, so the work directories and reports it
    writes are in its folder's ``work/NAME`` (ignored by git), where the lab's file browser opens
    them. Emptied first: each run starts afresh and the last run's files never pile up.
    """
    import shutil

    folder = Path("work", name)
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    return folder


class _Through:
    """Writes through to a stream (at once, so the order is kept) and keeps a copy."""

    def __init__(self, stream):
        self.stream, self.parts = stream, []

    def write(self, text: str) -> int:
        self.parts.append(text)
        return self.stream.write(text)

    def flush(self) -> None:
        self.stream.flush()

    def isatty(self) -> bool:
        return False


def nbcalib_command(*words) -> tuple[int, str]:
    """Run ``nbcalib WORDS`` as typed in a terminal, in this process; print it and its output.

    What a terminal shows, in the order it happens: the command line, then what the command
    prints and its progress, then the exit status when it is not 0. In a notebook the progress
    (the command's standard error) is shown with the rest as plain output, its bars as text
    updated in place, not as error-coloured blocks. Returns ``(status, stdout)``. The
    ``nbcalib`` logger is left as it was found.
    """
    import contextlib
    import logging
    import shlex

    from nbcalib.cli import main

    words = [str(w) for w in words]
    print("$ nbcalib", shlex.join(words), flush=True)
    out = _Through(sys.stdout)
    errors = sys.stdout if in_jupyter() else sys.stderr
    logger = logging.getLogger("nbcalib")
    handlers, level = list(logger.handlers), logger.level
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(errors):
            status = main(words)
    finally:
        logger.handlers[:] = handlers
        logger.setLevel(level)
    sys.stdout.flush()
    if status:
        print(f"(exit status {status})")
    return status, "".join(out.parts)


def has_display() -> bool:
    """Whether a window can open: not Linux, or Linux with an X or Wayland display."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def off_screen() -> bool:
    """Whether 3-D views render off screen (a still image) rather than in a window.

    Off screen in a Jupyter kernel (the still image, and beside it the live view of
    :func:`live_views`), under the quick mode or with ``PYVISTA_OFF_SCREEN=true`` (the tests,
    CI), and where no window can open (a script on a server). A window on a desktop outside
    Jupyter.
    """
    if is_quick() or os.environ.get("PYVISTA_OFF_SCREEN", "").lower() == "true":
        return True
    return in_jupyter() or not has_display()


def live_views() -> bool:
    """Whether a 3-D view in a notebook gets a view to turn beside its still image.

    ``NBCALIB_3D=image``: never; ``NBCALIB_3D=live``: always. By default (``auto``) where the
    kernel can serve one: in a Jupyter kernel, not in the quick mode, with pyvista's trame
    backend installed (``nbcalib[notebooks]``), and either a browser on this machine (no
    ``SSH_CONNECTION``) or pyvista set to reach its view through the Jupyter server
    (``PYVISTA_TRAME_SERVER_PROXY_PREFIX``, set by hand for a JupyterLab behind an SSH tunnel;
    on JupyterHub pyvista sets it itself), which needs ``jupyter-server-proxy``. The live view
    lives in its kernel: in a saved notebook opened later only the still image is left.
    """
    setting = os.environ.get("NBCALIB_3D", "auto").lower()
    if setting in ("image", "live"):
        return setting == "live"
    if not in_jupyter() or is_quick() or os.environ.get("PYVISTA_OFF_SCREEN", "") == "true":
        return False
    import importlib.util

    if importlib.util.find_spec("trame") is None:
        return False
    proxied = bool(
        os.environ.get("PYVISTA_TRAME_SERVER_PROXY_PREFIX")
        or os.environ.get("JUPYTERHUB_SERVICE_PREFIX")
    )
    if proxied:
        return importlib.util.find_spec("jupyter_server_proxy") is not None
    return not os.environ.get("SSH_CONNECTION")


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
    live = live_views()
    pl = pv.Plotter(off_screen=still, notebook=live, window_size=list(window_size), **kwargs)
    pl._nbcalib_still, pl._nbcalib_live = still, live  # what show() does with it
    return pl


#: The text a saved notebook keeps of a live view where no widget can be drawn.
LIVE_VIEW_TEXT = "(a 3-D view to turn: it needs its kernel; the still image above is the same view)"


def show(pl, title: str | None = None) -> np.ndarray | None:
    """Show a plotter from :func:`plotter`: a still image, and a view to turn where one can be.

    The still image is a matplotlib figure of the off-screen render: in a notebook it is shown
    at once (before what the cell prints next) and closed, so it is saved with the notebook;
    in a script it stays open like the script's other figures. In a notebook with
    :func:`live_views`, pyvista's view to turn follows it. On a desktop outside Jupyter the
    view opens in a window instead.

    Returns the rendered (H, W, 3) uint8 image (the notebooks' tests check that it is not
    blank); None when the view opened in a window.
    """
    if not getattr(pl, "_nbcalib_still", pl.off_screen):
        pl.show(title=title)
        return None
    image = np.asarray(pl.screenshot(return_img=True))
    import matplotlib.pyplot as plt

    height, width = image.shape[:2]
    fig, ax = plt.subplots(figsize=(width / 100, height / 100))
    ax.imshow(image)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    fig.tight_layout()
    if in_jupyter():
        from IPython.display import display

        display(fig, metadata={"nbcalib": {"view": "3-D", "title": title or ""}})
        plt.close(fig)
        if getattr(pl, "_nbcalib_live", False):
            # rendered by the kernel (EGL) and streamed: no vtk.js or WebAssembly to fetch
            widget = pl.show(jupyter_backend="server", return_viewer=True)
            bundle = widget._repr_mimebundle_()
            bundle = bundle[0] if isinstance(bundle, tuple) else bundle
            display({**bundle, "text/plain": LIVE_VIEW_TEXT}, raw=True)
            return image
    pl.close()
    return image


def first_run_note() -> bool:
    """Print that numba will compile the kernels, when its cache is cold (a first run here).

    The notebooks import this module in their first code cell, which says it there once.
    Returns whether it was said.
    """
    from nbcalib.warmup import COMPILING_NOTE, cache_is_warm

    if cache_is_warm():
        return False
    print(COMPILING_NOTE[0].upper() + COMPILING_NOTE[1:] + ".")  # the one text the CLI logs too
    return True


first_run_note()


def textured_box(camera, back: float, rng, n: int = 25000):
    """A textured box seen from inside by ``camera`` (the LiDAR frame = the camera's).

    Its back wall ``back`` metres ahead, side walls at +-3 m, a floor and a ceiling; each
    surface painted with one smooth texture. Returns the grey image (uint8) of each pixel's
    first hit, and LiDAR points (``5 n``, 3) on the surfaces with the texture as intensity.
    Several boxes of different depths are the smallest scene where a focal length can be told
    from the camera's forward position (notebook 8; ``tests/test_refine_intrinsics.py``).
    """

    def texture(p):
        return 0.5 + 0.25 * np.sin(2.3 * p[..., 0] + 1.1 * p[..., 2]) * np.cos(1.9 * p[..., 1])

    planes = [(2, back), (1, 1.5), (1, -2.0), (0, -3.0), (0, 3.0)]
    h, w = camera.height, camera.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = camera.unproject(np.column_stack([u.ravel(), v.ravel()]))
    depth = np.full(len(rays), np.inf)
    for axis, offset in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = offset / rays[:, axis]
        depth = np.where((s > 0.1) & (s < depth), s, depth)
    hit = rays * np.where(np.isfinite(depth), depth, 0.0)[:, None]
    image = np.where(np.isfinite(depth), texture(hit), 0.0).reshape(h, w)
    points = []
    for axis, offset in planes:
        p = rng.uniform((-3.0, -2.0, 0.5), (3.0, 1.5, back), (n, 3))
        p[:, axis] = offset
        points.append(p)
    points = np.concatenate(points)
    return (255 * image).astype(np.uint8), points, texture(points)
