"""Manual correspondences: the file ``nbcalib initial-guess WORKDIR --manual FILE`` reads.

A JSON file (written by :class:`nbcalib.initial_guess.picker.ManualPicker` or by hand)::

    {
      "format": "nbcalib-manual-correspondences",
      "version": 1,
      "correspondences": [
        {"name": "000000", "camera_uv": [812.4, 377.0], "lidar_uv": [640.0, 512.5]},
        {"name": "000000", "camera_uv": [101.0, 220.5], "point_lidar": [4.21, -1.03, 0.30]}
      ]
    }

Each correspondence pairs a pixel of the camera image ``<name>.png`` (``camera_uv``, pixels,
u = column, v = row, centres at integers: docs/conventions.md section 6) with either

- ``lidar_uv``: a pixel of the LiDAR intensity image ``<name>_lidar_intensities.png``, lifted to
  the dense-cloud point it shows through ``<name>_lidar_indices.png`` (the nearest filled pixel
  within a small radius, as for automatic matches: :mod:`nbcalib.matching.correspondences`),
  or
- ``point_lidar``: a 3-D point in the LiDAR frame, metres (picked in a 3-D viewer, or measured).

``name`` is the work directory's data name (``meta.bag_names`` of ``calib.json``); it may be left
out when the directory holds a single pair. Other keys (e.g. ``"comment"``) are ignored. At least
:data:`~nbcalib.initial_guess.estimate.MIN_CORRESPONDENCES` correspondences are needed; more, and
spread over the image and over depths, give a better pose.

The reference toolbox's manual tool pairs 2-D picks with points picked in a 3-D view and has no
file format; this one is nbcalib's.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nbcalib.errors import InputError
from nbcalib.matching.correspondences import (
    Correspondences,
    lift_lidar_pixels,
    pool_correspondences,
)

__all__ = [
    "FORMAT",
    "VERSION",
    "ManualCorrespondence",
    "manual_to_dict",
    "parse_manual_correspondences",
    "read_manual_correspondences",
    "resolve_manual_correspondences",
    "write_manual_correspondences",
]

#: Value of the file's ``format`` key.
FORMAT = "nbcalib-manual-correspondences"
#: Version of the format this module writes and reads.
VERSION = 1


@dataclass(frozen=True)
class ManualCorrespondence:
    """One picked pair: a camera pixel and a LiDAR-image pixel or a 3-D LiDAR point.

    Attributes
    ----------
    camera_uv : tuple of 2 floats
        Camera-image pixel ``(u, v)``.
    lidar_uv : tuple of 2 floats or None
        LiDAR-image pixel ``(u, v)``; exactly one of ``lidar_uv`` and ``point_lidar`` is set.
    point_lidar : tuple of 3 floats or None
        Point in the LiDAR frame, metres.
    name : str or None
        Data name of the pair (None: the work directory's only pair).
    """

    camera_uv: tuple[float, float]
    lidar_uv: tuple[float, float] | None = None
    point_lidar: tuple[float, float, float] | None = None
    name: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "camera_uv", _numbers(self.camera_uv, 2, "camera_uv"))
        if (self.lidar_uv is None) == (self.point_lidar is None):
            raise ValueError("give exactly one of lidar_uv and point_lidar")
        if self.lidar_uv is not None:
            object.__setattr__(self, "lidar_uv", _numbers(self.lidar_uv, 2, "lidar_uv"))
        else:
            object.__setattr__(self, "point_lidar", _numbers(self.point_lidar, 3, "point_lidar"))
        if self.name is not None and (not isinstance(self.name, str) or not self.name):
            raise ValueError(f"name must be a non-empty string or None, got {self.name!r}")


def _numbers(values, count: int, what: str) -> tuple:
    if isinstance(values, (str, bytes)) or not isinstance(values, (Sequence, np.ndarray)):
        raise ValueError(f"{what} must be a list of {count} numbers, got {values!r}")
    if len(values) != count:
        raise ValueError(f"{what} must hold {count} numbers, got {len(values)}")
    out = []
    for x in values:
        if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
            raise ValueError(f"{what} must hold numbers, got {x!r}")
        if not math.isfinite(float(x)):
            raise ValueError(f"{what} must be finite, got {x!r}")
        out.append(float(x))
    return tuple(out)


def manual_to_dict(entries: Sequence[ManualCorrespondence]) -> dict:
    """The JSON document of ``entries`` (module docstring)."""
    items = []
    for e in entries:
        item: dict = {"camera_uv": list(e.camera_uv)}
        if e.name is not None:
            item["name"] = e.name
        if e.lidar_uv is not None:
            item["lidar_uv"] = list(e.lidar_uv)
        else:
            item["point_lidar"] = list(e.point_lidar)
        items.append(item)
    return {"format": FORMAT, "version": VERSION, "correspondences": items}


def parse_manual_correspondences(
    doc, *, path: str | os.PathLike | None = None
) -> list[ManualCorrespondence]:
    """Validate a parsed manual-correspondences document; :class:`InputError` names ``path``."""
    if not isinstance(doc, dict):
        raise InputError("expected a JSON object with a 'correspondences' list", path)
    if doc.get("format", FORMAT) != FORMAT:
        raise InputError(f"'format' is {doc.get('format')!r}, expected {FORMAT!r}", path)
    version = doc.get("version", VERSION)
    if version != VERSION:
        raise InputError(f"unsupported version {version!r} (this nbcalib reads {VERSION})", path)
    items = doc.get("correspondences")
    if not isinstance(items, list):
        raise InputError("'correspondences' must be a list", path)
    entries = []
    for k, item in enumerate(items):
        if not isinstance(item, dict):
            raise InputError(f"correspondence {k}: expected an object, got {item!r}", path)
        if "camera_uv" not in item:
            raise InputError(f"correspondence {k}: no 'camera_uv'", path)
        try:
            entries.append(
                ManualCorrespondence(
                    camera_uv=item["camera_uv"],
                    lidar_uv=item.get("lidar_uv"),
                    point_lidar=item.get("point_lidar"),
                    name=item.get("name"),
                )
            )
        except ValueError as exc:
            raise InputError(f"correspondence {k}: {exc}", path) from None
    return entries


def read_manual_correspondences(path: str | os.PathLike) -> list[ManualCorrespondence]:
    """Read and validate a manual-correspondences file (module docstring).

    Raises
    ------
    InputError
        Missing file, invalid JSON, or an invalid entry; the message names the file (and entry).
    """
    from nbcalib.io.calib_json import read_json

    return parse_manual_correspondences(read_json(path), path=path)


def write_manual_correspondences(
    path: str | os.PathLike, entries: Sequence[ManualCorrespondence]
) -> None:
    """Write ``entries`` as a manual-correspondences file (sorted keys, indent 2, atomically)."""
    from nbcalib.io.calib_json import write_json

    for e in entries:
        if not isinstance(e, ManualCorrespondence):
            raise ValueError(f"entries must be ManualCorrespondence, got {type(e).__name__}")
    write_json(path, manual_to_dict(entries))


def resolve_manual_correspondences(
    entries: Sequence[ManualCorrespondence],
    pairs,
    *,
    search_radius: float = 2.0,
    path: str | os.PathLike | None = None,
) -> Correspondences:
    """Turn manual picks into 2D-3D correspondences, lifting LiDAR-image pixels.

    Parameters
    ----------
    entries : sequence of ManualCorrespondence
        The picks.
    pairs : sequence of PairData
        The job's pairs (their index maps and clouds lift ``lidar_uv``).
    search_radius : float, optional
        Pixels around an empty LiDAR-image pixel searched for a filled one.
    path : str or PathLike, optional
        The picks' file, for messages.

    Returns
    -------
    Correspondences
        One per entry, in order (``point_index`` -1 and ``uv_lidar`` NaN for 3-D points).

    Raises
    ------
    InputError
        An unknown or missing ``name``, or a LiDAR pixel that shows no point.
    """
    by_name = {pair.name: pair for pair in pairs}
    names = list(by_name)
    parts = []
    for k, e in enumerate(entries):
        name = e.name
        if name is None:
            if len(names) != 1:
                raise InputError(
                    f"correspondence {k}: no 'name', and the work directory holds "
                    f"{len(names)} pairs ({', '.join(names)})",
                    path,
                )
            name = names[0]
        elif name not in names:
            raise InputError(
                f"correspondence {k}: unknown name {name!r} (work directory: {', '.join(names)})",
                path,
            )
        uv_camera = np.array([e.camera_uv])
        if e.point_lidar is not None:
            point = np.array([e.point_lidar])
            row = np.array([-1])
            uv_lidar = np.full((1, 2), np.nan)
        else:
            index_map, cloud = by_name[name].lidar_index, by_name[name].points_lidar
            uv_lidar = np.array([e.lidar_uv])
            row = lift_lidar_pixels(uv_lidar, index_map, search_radius=search_radius)
            if row[0] < 0:
                u, v = e.lidar_uv
                raise InputError(
                    f"correspondence {k}: LiDAR-image pixel ({u:g}, {v:g}) of {name!r} shows no "
                    f"point within {search_radius:g} px; pick a pixel with a LiDAR point",
                    path,
                )
            point = cloud[row]
        parts.append(
            Correspondences(
                uv_camera=uv_camera,
                points_lidar=np.asarray(point, dtype=np.float64),
                uv_lidar=uv_lidar,
                point_index=row.astype(np.int64),
                pair=np.zeros(1, dtype=np.int64),
                names=(name,),
                n_matches=1,
            )
        )
    return pool_correspondences(parts)
