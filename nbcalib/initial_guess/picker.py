"""An interactive picker of manual correspondences, for JupyterLab or any matplotlib window.

The camera image and the LiDAR intensity image of one pair are shown side by side. Click a point
in the camera image and the same point in the LiDAR image (in either order) to add a pair;
pairs are numbered and drawn in the same colour in both images. "Undo" removes the last pending
click, or else the last pair; "Save" writes the manual-correspondences file
(:mod:`nbcalib.initial_guess.manual`) that ``nbcalib initial-guess WORKDIR --manual FILE`` reads.
Clicks in the LiDAR image must land on (or within ``search_radius`` pixels of) a LiDAR point.
While the toolbar's zoom or pan is active, clicks navigate instead of picking.

In JupyterLab, use an interactive matplotlib backend (``%matplotlib widget`` with the ``ipympl``
package) and run::

    from nbcalib.initial_guess.picker import ManualPicker
    picker = ManualPicker("work")           # the work directory's first pair
    picker.show()
    # ... click pairs, then press "Save" (or call picker.save())

The logic lives in :class:`PickerState`, which the user interface only drives, so it is tested
without a display.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from nbcalib.initial_guess.manual import ManualCorrespondence, write_manual_correspondences
from nbcalib.matching.correspondences import lift_lidar_pixels

__all__ = ["DEFAULT_FILE_NAME", "ManualPicker", "PickerState"]

#: File name the picker saves to inside the work directory unless told otherwise.
DEFAULT_FILE_NAME = "manual_correspondences.json"


class PickerState:
    """Picks in progress: completed pairs plus at most one pending click per image.

    Parameters
    ----------
    name : str or None
        Data name written with every pair (None: leave it out, for single-pair directories).
    index_map : array_like of shape (H, W), integer, optional
        The pair's LiDAR index map; when given, LiDAR clicks that show no point within
        ``search_radius`` pixels are refused.
    search_radius : float, optional
        Pixels, see :func:`nbcalib.matching.correspondences.lift_lidar_pixels`.
    entries : sequence of ManualCorrespondence, optional
        Pairs to start with (e.g. read from an earlier file).
    """

    def __init__(
        self,
        name: str | None = None,
        *,
        index_map=None,
        search_radius: float = 2.0,
        entries=(),
    ):
        self.name = name
        self.index_map = None if index_map is None else np.asarray(index_map)
        self.search_radius = float(search_radius)
        self.pairs: list[ManualCorrespondence] = list(entries)
        self.pending_camera: tuple[float, float] | None = None
        self.pending_lidar: tuple[float, float] | None = None
        self._pending_order: list[str] = []
        self.message = "click a point in either image"

    def __len__(self) -> int:
        return len(self.pairs)

    def _complete(self) -> ManualCorrespondence | None:
        if self.pending_camera is None or self.pending_lidar is None:
            which = "LiDAR" if self.pending_camera is not None else "camera"
            self.message = f"{len(self.pairs)} pairs; now click the same point in the {which} image"
            return None
        pair = ManualCorrespondence(
            camera_uv=self.pending_camera, lidar_uv=self.pending_lidar, name=self.name
        )
        self.pairs.append(pair)
        self.pending_camera = self.pending_lidar = None
        self._pending_order.clear()
        self.message = f"{len(self.pairs)} pairs; click the next point in either image"
        return pair

    def _set_pending(self, which: str, uv: tuple[float, float]) -> None:
        if which in self._pending_order:
            self._pending_order.remove(which)
        self._pending_order.append(which)
        if which == "camera":
            self.pending_camera = uv
        else:
            self.pending_lidar = uv

    def click_camera(self, u: float, v: float) -> ManualCorrespondence | None:
        """Pick (or re-pick) the camera pixel of the current pair.

        Returns
        -------
        ManualCorrespondence or None
            The pair completed by this click, if any.
        """
        self._set_pending("camera", (float(u), float(v)))
        return self._complete()

    def click_lidar(self, u: float, v: float) -> ManualCorrespondence | None:
        """Pick (or re-pick) the LiDAR-image pixel of the current pair.

        A pixel without a LiDAR point nearby is refused (``message`` says so; returns None).
        """
        if self.index_map is not None:
            row = lift_lidar_pixels([[u, v]], self.index_map, search_radius=self.search_radius)
            if row[0] < 0:
                self.message = (
                    f"no LiDAR point within {self.search_radius:g} px of ({u:.1f}, {v:.1f}); "
                    "click on a LiDAR point"
                )
                return None
        self._set_pending("lidar", (float(u), float(v)))
        return self._complete()

    def undo(self) -> None:
        """Remove the last pending click, or else the last completed pair."""
        if self._pending_order:
            which = self._pending_order.pop()
            if which == "camera":
                self.pending_camera = None
            else:
                self.pending_lidar = None
            self.message = f"{len(self.pairs)} pairs; removed the pending {which} click"
        elif self.pairs:
            self.pairs.pop()
            self.message = f"{len(self.pairs)} pairs; removed the last pair"
        else:
            self.message = "nothing to undo"

    def entries(self) -> list[ManualCorrespondence]:
        """The completed pairs (pending clicks are not included)."""
        return list(self.pairs)

    def save(self, path: str | os.PathLike) -> Path:
        """Write the completed pairs to ``path`` (manual-correspondences format)."""
        path = Path(path)
        write_manual_correspondences(path, self.pairs)
        self.message = f"saved {len(self.pairs)} pairs to {path}"
        return path


class ManualPicker:
    """Side-by-side matplotlib picker over one pair of a work directory (module docstring).

    Parameters
    ----------
    workdir : str or PathLike or WorkDir
        The work directory.
    name : str, optional
        Data name of the pair (default: the first one).
    path : str or PathLike, optional
        File to save to (default ``WORKDIR/manual_correspondences.json``); pairs already in it
        for this data name are loaded.
    search_radius : float, optional
        Pixels around a LiDAR click searched for a LiDAR point.
    figsize : tuple of float, optional
        Figure size, inches.
    """

    _COLORS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:cyan")

    def __init__(
        self,
        workdir,
        name: str | None = None,
        *,
        path: str | os.PathLike | None = None,
        search_radius: float = 2.0,
        figsize: tuple[float, float] = (13.0, 5.5),
    ):
        from nbcalib.errors import require
        from nbcalib.initial_guess.manual import read_manual_correspondences
        from nbcalib.workdir import WorkDir

        plt = require("matplotlib.pyplot", "viz")
        widgets = require("matplotlib.widgets", "viz")
        self.workdir = workdir if isinstance(workdir, WorkDir) else WorkDir(workdir)
        names = self.workdir.names()
        self.name = name if name is not None else names[0]
        pair = self.workdir.load_pair(self.name)
        self.path = Path(path) if path is not None else self.workdir.path / DEFAULT_FILE_NAME
        others: list[ManualCorrespondence] = []
        mine: list[ManualCorrespondence] = []
        if self.path.is_file():
            for e in read_manual_correspondences(self.path):
                (mine if e.name in (self.name, None) else others).append(e)
        self._others = others  # pairs of other data names, kept when saving
        self.state = PickerState(
            self.name if len(names) > 1 else None,
            index_map=pair.lidar_index,
            search_radius=search_radius,
            entries=mine,
        )

        self.figure = plt.figure(figsize=figsize)
        self.ax_camera = self.figure.add_axes((0.01, 0.12, 0.48, 0.82))
        self.ax_lidar = self.figure.add_axes((0.51, 0.12, 0.48, 0.82))
        self.ax_camera.imshow(pair.image, cmap="gray", vmin=0, vmax=255)
        self.ax_lidar.imshow(pair.lidar_image.intensity, cmap="gray", vmin=0, vmax=255)
        self.ax_camera.set_title(f"camera: {self.name}.png")
        self.ax_lidar.set_title(f"LiDAR: {self.name}_lidar_intensities.png")
        for ax in (self.ax_camera, self.ax_lidar):
            ax.set_axis_off()
        self._undo_button = widgets.Button(self.figure.add_axes((0.01, 0.02, 0.08, 0.06)), "Undo")
        self._save_button = widgets.Button(self.figure.add_axes((0.10, 0.02, 0.08, 0.06)), "Save")
        self._undo_button.on_clicked(lambda _event: self.undo())
        self._save_button.on_clicked(lambda _event: self.save())
        self._status = self.figure.text(0.20, 0.045, "", va="center")
        self._artists: list = []
        self.figure.canvas.mpl_connect("button_press_event", self._on_click)
        self._redraw()

    # ---------------------------------------------------------------- events
    def _navigating(self) -> bool:
        toolbar = getattr(self.figure.canvas, "toolbar", None)
        return bool(toolbar is not None and getattr(toolbar, "mode", ""))

    def _on_click(self, event) -> None:
        if event.button != 1 or event.xdata is None or self._navigating():
            return
        if event.inaxes is self.ax_camera:
            self.state.click_camera(event.xdata, event.ydata)
        elif event.inaxes is self.ax_lidar:
            self.state.click_lidar(event.xdata, event.ydata)
        else:
            return
        self._redraw()

    def undo(self) -> None:
        """Undo the last click or pair."""
        self.state.undo()
        self._redraw()

    def save(self, path: str | os.PathLike | None = None) -> Path:
        """Write all pairs (this data name's and any others already in the file)."""
        target = Path(path) if path is not None else self.path
        write_manual_correspondences(target, [*self._others, *self.state.entries()])
        self.state.message = f"saved {len(self.state)} pairs to {target}"
        self._redraw()
        return target

    def show(self):
        """Display the figure (in JupyterLab: the interactive widget) and return it."""
        import matplotlib.pyplot as plt

        plt.show()
        return self.figure

    # ---------------------------------------------------------------- drawing
    def _redraw(self) -> None:
        for artist in self._artists:
            artist.remove()
        self._artists = []
        for k, pair in enumerate(self.state.pairs):
            color = self._COLORS[k % len(self._COLORS)]
            for ax, uv in ((self.ax_camera, pair.camera_uv), (self.ax_lidar, pair.lidar_uv)):
                if uv is None:
                    continue
                self._artists += ax.plot(uv[0], uv[1], "+", color=color, ms=12, mew=2)
                label = ax.annotate(
                    str(k), uv, color=color, xytext=(4, 4), textcoords="offset points"
                )
                self._artists.append(label)
        for ax, uv in (
            (self.ax_camera, self.state.pending_camera),
            (self.ax_lidar, self.state.pending_lidar),
        ):
            if uv is not None:
                self._artists += ax.plot(uv[0], uv[1], "x", color="yellow", ms=12, mew=2)
        self._status.set_text(self.state.message)
        self.figure.canvas.draw_idle()
