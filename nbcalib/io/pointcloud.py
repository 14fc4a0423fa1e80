"""Point clouds: :class:`PointCloud`, the field rules, and :func:`read_pointcloud` by suffix.

The formats have one module each: :mod:`nbcalib.io.pcd` (ascii, binary, binary_compressed),
:mod:`nbcalib.io.ply`, :mod:`nbcalib.io.kitti_bin` and :mod:`nbcalib.io.npy` (``.npy``, ``.npz``).
Each reads a file into named fields; :func:`read_pointcloud` makes of them a :class:`PointCloud`:
the finite points in the LiDAR frame (metres), the intensity channel and the per-point times
picked by the reference toolbox's rules, and every field of the file as read. The same rules
serve ``sensor_msgs/PointCloud2`` messages (:mod:`nbcalib.io.pointcloud2`) through
:func:`pointcloud_from_fields`:

- **intensity** (``intensity_channel="auto"``): ``reflectivity`` wins over ``intensity``; any
  other name is used as given. Values are kept as stored (no scaling), as float64.
- **times** (``time_field="auto"``): the first of ``t``, ``time``, ``time_stamp``, ``timestamp``.
  Integer fields hold nanoseconds (the reference reads ``uint32`` so; nbcalib extends it to every
  integer type), float fields hold seconds. Then the reference's ``TimeKeeper`` normalisation:
  negative times are shifted so that the minimum is 0; if the first time is still >= 1 s the
  times are absolute and are made relative to the first point; float values above 1e16 are taken
  as nanoseconds (Livox). The result is seconds relative to the scan, float64.
- **finite points only**: rows whose x, y or z is not finite are dropped from every field. The
  readers of files and bags log a warning (logger ``nbcalib``) naming the file and how many
  points were dropped; a file without a single finite point is an :class:`InputError`.

Writers (:func:`~nbcalib.io.pcd.write_pcd`, :func:`~nbcalib.io.ply.write_ply`,
:func:`~nbcalib.io.kitti_bin.write_kitti_bin`) write to a temporary file beside the target and
rename it into place, so a crash never leaves a file that looks complete.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError

#: Suffixes that :func:`read_pointcloud` understands.
POINTCLOUD_SUFFIXES = (".pcd", ".ply", ".bin", ".npy", ".npz")

#: Intensity channels in the order ``intensity_channel="auto"`` prefers them (reference rule).
INTENSITY_PRIORITY = ("reflectivity", "intensity")

#: Per-point time fields in the order ``time_field="auto"`` looks for them (reference rule).
TIME_FIELDS = ("t", "time", "time_stamp", "timestamp")

log = logging.getLogger("nbcalib")

_FIRST_TIME_ABSOLUTE_S = 1.0  # a first time >= 1 s means absolute times (reference TimeKeeper)
_NANOSECONDS_ABOVE = 1e16  # float "seconds" above this are nanoseconds (Livox)


@dataclass
class PointCloud:
    """One point cloud with its intensity and per-point times.

    Attributes
    ----------
    points : ndarray of shape (N, 3), float64
        Finite points in the sensor (LiDAR) frame, metres. Rows with a non-finite x, y or z in the
        file are dropped.
    intensity : ndarray of shape (N,), float64, or None
        The chosen intensity channel, raw values as stored (no scaling); None when there is none.
    times : ndarray of shape (N,), float64, or None
        Per-point time in seconds relative to the scan (module docstring); None when the source
        has no time field.
    fields : dict of str to ndarray
        Every field as read, with its own dtype, shape (N,) or (N, count), same rows as ``points``.
    """

    points: np.ndarray
    intensity: np.ndarray | None = None
    times: np.ndarray | None = None
    fields: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.points.shape[0])


# ----------------------------------------------------------------------------------------------
# Fields -> PointCloud (shared with PointCloud2 messages)


def select_intensity_field(
    names: Iterable[str], intensity_channel: str | None = "auto", *, source=None
) -> str | None:
    """Name of the intensity field to use, by the reference's rule.

    Parameters
    ----------
    names : iterable of str
        The available field names.
    intensity_channel : str or None
        ``"auto"`` picks ``reflectivity`` over ``intensity`` (None if neither exists); None or
        ``"none"`` means no intensity; any other name must exist.
    source : str or os.PathLike, optional
        File (or bag and topic) named in the error message.

    Raises
    ------
    InputError
        A named channel that does not exist; the message lists the available fields.
    """
    return _select_field(names, intensity_channel, INTENSITY_PRIORITY, "intensity channel", source)


def select_time_field(
    names: Iterable[str], time_field: str | None = "auto", *, source=None
) -> str | None:
    """Name of the per-point time field: ``"auto"`` takes the first of :data:`TIME_FIELDS`.

    None or ``"none"`` means no times; any other name must exist (else :class:`InputError`).
    """
    return _select_field(names, time_field, TIME_FIELDS, "time field", source)


def _select_field(
    names, choice: str | None, auto: tuple[str, ...], what: str, source
) -> str | None:
    """None for None / "none", the first of ``auto`` present for "auto", else ``choice`` checked."""
    names = list(names)
    if choice is None or choice == "none":
        return None
    if choice == "auto":
        return next((n for n in auto if n in names), None)
    if choice not in names:
        raise InputError(
            f"{what} '{choice}' not found; available fields: {', '.join(names) or '(none)'}",
            path=source,
        )
    return choice


def normalize_point_times(raw: np.ndarray) -> np.ndarray:
    """Per-point times in seconds relative to the scan, by the reference's ``TimeKeeper`` rules.

    Parameters
    ----------
    raw : ndarray of shape (N,)
        The time field as stored: integer types are nanoseconds, float types seconds.

    Returns
    -------
    ndarray of shape (N,), float64
        Seconds. Negative times are shifted so the minimum is 0; then, if the first time is >= 1 s,
        all times are made relative to the first point (they were absolute); float values above
        1e16 are treated as nanoseconds. Integer inputs are shifted in integer arithmetic, so
        absolute nanosecond stamps keep full precision.
    """
    raw = np.asarray(raw)
    if raw.ndim != 1:
        raise ValueError(f"point times must be 1-D, got shape {raw.shape}")
    if raw.size == 0:
        return np.zeros(0)
    if np.issubdtype(raw.dtype, np.integer):
        ns = raw.astype(np.int64)  # absolute ns stamps fit in int64 until the year 2262
        if ns.min() < 0:
            ns = ns - ns.min()
        if ns[0] >= _FIRST_TIME_ABSOLUTE_S * 1e9:
            ns = ns - ns[0]
        return ns.astype(np.float64) * 1e-9
    if not np.issubdtype(raw.dtype, np.floating):
        raise ValueError(f"point times must be integer or float, got {raw.dtype}")
    t = raw.astype(np.float64)
    finite = np.isfinite(t)
    if finite.any() and t[finite].min() < 0.0:
        t = t - t[finite].min()
    if t[0] >= _FIRST_TIME_ABSOLUTE_S:
        if t[0] > _NANOSECONDS_ABOVE:
            return (t - t[0]) * 1e-9
        t = t - t[0]
    return t


def pointcloud_from_fields(
    fields: Mapping[str, np.ndarray],
    *,
    intensity_channel: str | None = "auto",
    time_field: str | None = "auto",
    source=None,
) -> PointCloud:
    """Build a :class:`PointCloud` from named per-point arrays (one file or message).

    Parameters
    ----------
    fields : mapping of str to ndarray of shape (N,) or (N, count)
        Every field, same length; must contain ``x``, ``y``, ``z``.
    intensity_channel : str or None
        See :func:`select_intensity_field`.
    time_field : str or None
        See :func:`select_time_field`.
    source : str or os.PathLike, optional
        File (or bag and topic) named in error messages.

    Returns
    -------
    PointCloud
        Non-finite xyz rows dropped from every field.
    """
    names = list(fields)
    missing = [c for c in "xyz" if c not in fields]
    if missing:
        raise InputError(
            f"no {', '.join(missing)} field; fields present: {', '.join(names) or '(none)'}",
            path=source,
        )
    for c in "xyz":
        if fields[c].ndim != 1:
            raise InputError(f"field '{c}' has count {fields[c].shape[1:]}, expected 1", source)
        if fields[c].dtype.kind not in "iuf":
            raise InputError(f"field '{c}' holds {fields[c].dtype}, not numbers", source)
    xyz = np.stack([fields[c].astype(np.float64, copy=False) for c in "xyz"], axis=1)
    finite = np.isfinite(xyz).all(axis=1)
    if finite.all():
        kept = dict(fields)
    else:
        xyz = xyz[finite]
        kept = {name: values[finite] for name, values in fields.items()}
    points = np.ascontiguousarray(xyz, dtype=np.float64)

    intensity = None
    name = select_intensity_field(names, intensity_channel, source=source)
    if name is not None:
        values = kept[name]
        if values.ndim != 1 or not (
            np.issubdtype(values.dtype, np.integer) or np.issubdtype(values.dtype, np.floating)
        ):
            raise InputError(
                f"intensity field '{name}' must be one number per point, got {values.dtype} "
                f"with shape {values.shape}",
                path=source,
            )
        intensity = values.astype(np.float64)

    times = None
    name = select_time_field(names, time_field, source=source)
    if name is not None:
        values = kept[name]
        if values.ndim != 1 or values.dtype.kind not in "iuf":
            raise InputError(
                f"time field '{name}' must be one number per point, got {values.dtype} "
                f"with shape {values.shape}",
                path=source,
            )
        times = normalize_point_times(values)
    return PointCloud(points=points, intensity=intensity, times=times, fields=kept)


def warn_dropped_points(source, dropped: int, total: int) -> None:
    """Log a warning (logger ``nbcalib``) that points with a non-finite x, y or z were dropped.

    Parameters
    ----------
    source : str or os.PathLike
        The file (or bag and topic) the points came from.
    dropped, total : int
        Points dropped, and points read. Nothing is logged when ``dropped`` is 0.
    """
    if dropped:
        log.warning(
            "%s: dropped %d of %d points with a non-finite x, y or z", source, dropped, total
        )


def pointcloud_from_file_fields(
    fields: Mapping[str, np.ndarray],
    path,
    *,
    intensity_channel: str | None = "auto",
    time_field: str | None = "auto",
) -> PointCloud:
    """:func:`pointcloud_from_fields` for the fields of one file, its non-finite points reported.

    Dropped points are logged (:func:`warn_dropped_points`); a file of points none of which is
    finite is an :class:`InputError` naming ``path``. A file of 0 points gives an empty cloud.
    """
    cloud = pointcloud_from_fields(
        fields, intensity_channel=intensity_channel, time_field=time_field, source=path
    )
    total = len(fields["x"])
    if total and not len(cloud):
        raise InputError(f"none of its {total} points has a finite x, y and z", path=path)
    warn_dropped_points(path, total - len(cloud), total)
    return cloud


# ----------------------------------------------------------------------------------------------
# Dispatch


def read_pointcloud(
    path, *, intensity_channel: str | None = "auto", time_field: str | None = "auto"
) -> PointCloud:
    """Read a point cloud file, by suffix: ``.pcd``, ``.ply``, ``.bin`` (KITTI), ``.npy``, ``.npz``.

    Parameters
    ----------
    path : str or os.PathLike
        The file.
    intensity_channel : str or None
        ``"auto"`` (``reflectivity`` over ``intensity``), a field name, or None (no intensity).
    time_field : str or None
        ``"auto"`` (first of ``t``, ``time``, ``time_stamp``, ``timestamp``), a name, or None.

    Returns
    -------
    PointCloud
        Points in the sensor frame (metres), intensity as stored, times in seconds relative to
        the scan (module docstring). Points with a non-finite x, y or z are dropped, with a
        warning naming the file and how many.

    Raises
    ------
    InputError
        Missing, empty, truncated or corrupt file, an unknown suffix, or points none of which is
        finite; the message names the file.

    Notes
    -----
    ``.npy`` holds either a structured array (one field per column name) or a float array of shape
    (N, 3) ``x, y, z`` or (N, 4) ``x, y, z, intensity``. ``.npz`` holds one array per field
    (``x``, ``y``, ``z``, ...) or ``points`` (N, 3) with optional ``intensity`` and ``t``.
    """
    from nbcalib.io.kitti_bin import read_kitti_bin_fields
    from nbcalib.io.npy import read_npy_fields, read_npz_fields
    from nbcalib.io.pcd import read_pcd_fields
    from nbcalib.io.ply import read_ply_fields

    path = Path(path)
    suffix = path.suffix.lower()
    readers = {
        ".pcd": read_pcd_fields,
        ".ply": read_ply_fields,
        ".bin": read_kitti_bin_fields,
        ".npy": read_npy_fields,
        ".npz": read_npz_fields,
    }
    if suffix not in readers:
        raise InputError(
            f"unknown point cloud suffix '{path.suffix}'; expected one of "
            f"{', '.join(POINTCLOUD_SUFFIXES)}",
            path=path,
        )
    return pointcloud_from_file_fields(
        readers[suffix](path), path, intensity_channel=intensity_channel, time_field=time_field
    )
