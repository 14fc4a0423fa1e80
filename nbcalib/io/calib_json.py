"""Read and write the reference toolbox's ``calib.json``; the only place poses change convention.

``calib.json`` keeps the schema of the reference C++ toolbox
(koide3/direct_visual_lidar_calibration) so that either tool can continue the other's work
directory (docs/conventions.md section 4)::

    {
      "camera":  {"camera_model": str, "intrinsics": [...], "distortion_coeffs": [...]},
      "meta":    {"data_path", "camera_info_topic", "image_topic", "points_topic",
                  "intensity_channel", "bag_names": [...]},
      "results": {"init_T_lidar_camera": [x, y, z, qx, qy, qz, qw],       # manual guess
                  "init_T_lidar_camera_auto": [...],                        # automatic guess
                  "T_lidar_camera": [...]},                                 # final result
      "nbcalib": {...}                                                      # ours; ignored by it
    }

Poses are stored as ``T_lidar_camera`` (``p_lidar = T_lidar_camera @ p_camera``), translation in
metres and a quaternion in **xyzw** order; the rest of nbcalib works with ``T_camera_lidar``, its
inverse. :meth:`CalibFile.get_T_camera_lidar` and :meth:`CalibFile.set_T_camera_lidar` convert.

The reference does not store the image size. nbcalib keeps the raw ``camera`` entry and adds the
size (and the nbcalib model name, see below) under ``nbcalib.camera``; a reference-made work
directory gets its size from the camera image ``<bag_names[0]>.png`` next to ``calib.json``.
:meth:`CalibFile.camera_model` assembles the :class:`~nbcalib.camera.CameraModel`.

nbcalib's section ``nbcalib`` holds:

- ``camera``: ``{"camera_model": name, "width": W, "height": H}``. A ``pinhole`` camera is
  written as ``plumb_bob`` with zero distortion (the reference does not know ``pinhole``); the
  name recorded here turns it back into ``pinhole`` on reading.
- ``result_times``: ``{stage: ISO 8601 time}``, when nbcalib wrote each result, so that the most
  recent initial guess is decidable (:meth:`CalibFile.latest_initial_stage`), and
  ``result_values``: ``{stage: [7 numbers]}``, the values written then. A time counts only while
  the result still holds those values: a result the reference rewrote has no known time.
- anything else later stages add (quality figures, uncertainty, the config used), preserved.

The section is typed: :class:`~nbcalib.io.job_record.JobRecord` (:attr:`CalibFile.record`),
whose module is the only place its keys are spelled.

Files are written like nlohmann's ``dump(2)``: keys sorted, indent 2, UTF-8, a final newline, and
atomically (a temporary file in the same directory, then ``os.replace``), so a crash never leaves
a half-written ``calib.json``. Unknown keys anywhere are kept on a round trip.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._files import write_text_atomic
from nbcalib.io.job_record import (  # the result keys: re-exported, calib.json's vocabulary
    AUTO_STAGE,
    FINAL_STAGE,
    INITIAL_STAGES,
    MANUAL_STAGE,
    STAGES,
    CameraEntry,
    JobRecord,
)
from nbcalib.transforms import invert_T, pose_from_xyz_quat, pose_to_xyz_quat

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

#: Keys of the reference's ``camera`` entry.
CAMERA_KEYS = ("camera_model", "intrinsics", "distortion_coeffs")
#: Keys the reference's ``preprocess`` writes under ``meta``.
META_KEYS = (
    "data_path",
    "camera_info_topic",
    "image_topic",
    "points_topic",
    "intensity_channel",
    "bag_names",
)

#: Section of our own additions, which the reference ignores.
NBCALIB_KEY = "nbcalib"
_TOP_LEVEL = ("camera", "meta", "results", NBCALIB_KEY)

# Distortion counts of the reference's models (its factory pads/truncates to these).
_DISTORTION_COUNTS = {
    "pinhole": 0,
    "plumb_bob": 5,
    "rational_polynomial": 8,
    "fisheye": 4,
    "equidistant": 4,
    "atan": 1,
    "omnidir": 4,
    "equirectangular": 0,
}


@dataclass
class CalibFile:
    """The contents of a ``calib.json``.

    Attributes
    ----------
    camera : dict
        The reference's ``camera`` entry, ``{"camera_model", "intrinsics", "distortion_coeffs"}``
        as stored (plus any unknown keys). Use :meth:`camera_model` for a
        :class:`~nbcalib.camera.CameraModel` and :meth:`set_camera` to change it.
    meta : dict
        What preprocessing used (see :data:`META_KEYS`).
    results : dict
        Poses as stored: ``{stage: [x, y, z, qx, qy, qz, qw]}`` of ``T_lidar_camera``; use
        :meth:`get_T_camera_lidar` / :meth:`set_T_camera_lidar`.
    record : JobRecord
        nbcalib's additions, the ``nbcalib`` section (:mod:`nbcalib.io.job_record`).
    extra : dict
        Every other top-level key, preserved on a round trip.
    path : Path or None
        The file this was read from (for messages and the work-directory image); not written.
    """

    camera: dict = field(default_factory=dict)
    meta: dict = field(default_factory=dict)
    results: dict = field(default_factory=dict)
    record: JobRecord = field(default_factory=JobRecord)
    extra: dict = field(default_factory=dict)
    path: Path | None = None

    # ------------------------------------------------------------------ dict form
    @classmethod
    def from_dict(cls, data: dict, *, path: str | os.PathLike | None = None) -> CalibFile:
        """Validate a parsed ``calib.json`` object; :class:`InputError` names ``path``.

        The ``camera`` entry is required (the reference reads it unconditionally); ``results``
        poses must be 7 finite numbers with a non-zero quaternion.
        """
        if not isinstance(data, dict):
            raise InputError(f"expected a JSON object at the top level, got {_kind(data)}", path)
        camera = data.get("camera")
        if camera is None:
            raise InputError("no 'camera' entry (not a calib.json?)", path)
        _check_camera(camera, path)
        sections = {}
        for key in ("meta", "results", NBCALIB_KEY):
            value = data.get(key, {})
            if not isinstance(value, dict):
                raise InputError(f"'{key}' must be a JSON object, got {_kind(value)}", path)
            sections[key] = value
        for stage in STAGES:
            if stage in sections["results"]:
                _check_pose(sections["results"][stage], f"results.{stage}", path)
        extra = {key: value for key, value in data.items() if key not in _TOP_LEVEL}
        return cls(
            camera=camera,
            meta=sections["meta"],
            results=sections["results"],
            record=JobRecord.from_dict(sections[NBCALIB_KEY]),
            extra=extra,
            path=None if path is None else Path(path),
        )

    def to_dict(self) -> dict:
        """Return the JSON object to write (empty ``results``/``nbcalib`` sections left out)."""
        data = dict(self.extra)
        data["camera"] = self.camera
        data["meta"] = self.meta
        if self.results:
            data["results"] = self.results
        section = self.record.to_dict()
        if section:
            data[NBCALIB_KEY] = section
        return data

    # ------------------------------------------------------------------ camera
    @property
    def image_size(self) -> tuple[int, int] | None:
        """Image ``(width, height)`` recorded under ``nbcalib.camera``, or None."""
        return None if self.record.camera is None else self.record.camera.size

    def camera_model(self, width: int | None = None, height: int | None = None) -> CameraModel:
        """Build the :class:`~nbcalib.camera.CameraModel` of the ``camera`` entry.

        Parameters
        ----------
        width, height : int, optional
            Image size in pixels. Needed only when the file does not know it: the size is taken
            from ``nbcalib.camera``, else from an equirectangular camera's intrinsics ``[W, H]``,
            else from the camera image ``<bag_names[0]>.png`` beside the file. A given size
            that disagrees with the recorded one is an :class:`InputError`.

        Notes
        -----
        As the reference's factory, a distortion vector shorter than the model's is padded
        with zeros and extra trailing zeros are dropped; extra non-zero coefficients are an
        :class:`InputError` (the reference would silently drop them).
        """
        from nbcalib.camera import create_camera

        _check_camera(self.camera, self.path)
        model = self.camera["camera_model"]
        intrinsics = [float(x) for x in self.camera["intrinsics"]]
        distortion = [float(x) for x in self.camera["distortion_coeffs"]]
        recorded_model = None if self.record.camera is None else self.record.camera.model
        if recorded_model == "pinhole" and model == "plumb_bob" and not any(distortion):
            model, distortion = "pinhole", []
        distortion = self._fit_distortion(model, distortion)
        width, height = self._resolve_size(model, intrinsics, width, height)
        try:
            return create_camera(model, intrinsics, distortion, width, height)
        except ValueError as exc:
            raise InputError(f"camera: {exc}", self.path) from None

    def result_camera(self, stage: str = FINAL_STAGE) -> CameraModel:
        """The camera that goes with the result of ``stage``.

        Fine registration's result goes with the camera it refined (``refine.intrinsics``,
        recorded under ``nbcalib.calibration.intrinsics.camera`` in the ``camera`` entry's
        layout plus the image size) when the frames fixed it; every other result, and every
        job that did not refine, with :meth:`camera_model`, the camera given.
        """
        from nbcalib.camera import CameraModel

        info = self.record.calibration
        entry = None if info is None else info.figures.get("intrinsics")
        if stage != FINAL_STAGE or not isinstance(entry, dict) or not entry.get("refined"):
            return self.camera_model()
        try:
            return CameraModel.from_dict(entry["camera"])
        except (KeyError, TypeError, ValueError) as exc:
            message = f"invalid nbcalib.calibration.intrinsics.camera: {exc}"
            raise InputError(message, self.path) from None

    def set_camera(self, camera: CameraModel) -> None:
        """Store ``camera`` in the reference's layout and record its size and model name.

        ``pinhole`` is written as ``plumb_bob`` with zero distortion (docs/conventions.md s. 4).
        """
        model = str(camera.model)
        distortion = [float(x) for x in np.asarray(camera.distortion_coeffs).ravel()]
        if model == "pinhole":
            distortion = [0.0] * 5
        self.camera = {
            "camera_model": "plumb_bob" if model == "pinhole" else model,
            "intrinsics": [float(x) for x in np.asarray(camera.intrinsics).ravel()],
            "distortion_coeffs": distortion,
        }
        self.record.camera = CameraEntry(model, int(camera.width), int(camera.height))

    def _fit_distortion(self, model: str, distortion: list[float]) -> list[float]:
        count = _DISTORTION_COUNTS.get(model.strip().lower())
        if count is None or len(distortion) == count:
            return distortion  # unknown model names are left to create_camera
        if any(distortion[count:]):
            raise InputError(
                f"camera: {model} takes {count} distortion coefficients, got {len(distortion)}",
                self.path,
            )
        return distortion[:count] + [0.0] * (count - len(distortion))

    def _resolve_size(self, model, intrinsics, width, height) -> tuple[int, int]:
        if (width is None) != (height is None):
            raise ValueError("give both width and height, or neither")
        known = self.image_size
        if known is None and model == "equirectangular" and len(intrinsics) == 2:
            if all(x > 0 and float(x).is_integer() for x in intrinsics):
                known = int(intrinsics[0]), int(intrinsics[1])
        if known is None:
            known = self._workdir_image_size()
        if width is None:
            if known is None:
                raise InputError(
                    "the image size is unknown (calib.json does not store it and no camera "
                    "image was found beside it); give the width and height",
                    self.path,
                )
            return known
        if known is not None and known != (int(width), int(height)):
            raise InputError(
                f"the camera is for {known[0]}x{known[1]} images, not {width}x{height}", self.path
            )
        return int(width), int(height)

    def _workdir_image_size(self) -> tuple[int, int] | None:
        names = self.meta.get("bag_names")
        if self.path is None or not isinstance(names, list) or not names:
            return None
        image_path = self.path.parent / f"{names[0]}.png"
        if not image_path.is_file():
            return None
        return read_image_size(image_path)

    # ------------------------------------------------------------------ meta
    @property
    def bag_names(self) -> list[str]:
        """``meta.bag_names``: the data names (``<name>.png``, ``<name>.ply``, ...)."""
        names = self.meta.get("bag_names", [])
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InputError("meta.bag_names must be a list of strings", self.path)
        return names

    # ------------------------------------------------------------------ poses
    def has_result(self, stage: str) -> bool:
        """Whether ``results[stage]`` is present; ``stage`` is one of :data:`STAGES`."""
        _check_stage(stage)
        return stage in self.results

    def get_T_camera_lidar(self, stage: str) -> np.ndarray:
        """Return the pose stored under ``results[stage]`` as ``T_camera_lidar``.

        Parameters
        ----------
        stage : str
            One of :data:`STAGES`: ``"T_lidar_camera"`` (final), ``"init_T_lidar_camera"``
            (manual guess), ``"init_T_lidar_camera_auto"`` (automatic guess).

        Returns
        -------
        T_camera_lidar : ndarray of shape (4, 4), float64
            ``p_camera = T_camera_lidar @ p_lidar``, the inverse of the stored
            ``T_lidar_camera``; the stored quaternion is normalised (as the reference does).
        """
        _check_stage(stage)
        if stage not in self.results:
            raise InputError(f"no result '{stage}' in results", self.path)
        return T_camera_lidar_from_values(
            self.results[stage], what=f"results.{stage}", path=self.path
        )

    def set_T_camera_lidar(self, stage: str, T_camera_lidar: np.ndarray) -> None:
        """Store ``T_camera_lidar`` under ``results[stage]`` and record the time.

        Parameters
        ----------
        stage : str
            One of :data:`STAGES`.
        T_camera_lidar : ndarray of shape (4, 4), float64
            ``p_camera = T_camera_lidar @ p_lidar``; written as its inverse ``T_lidar_camera``,
            ``[x, y, z, qx, qy, qz, qw]``, with the time under ``nbcalib.result_times`` (UTC,
            ISO 8601, later than every time already recorded).
        """
        _check_stage(stage)
        self.results[stage] = values_from_T_camera_lidar(T_camera_lidar)
        # strictly after every recorded time, so that write order decides even on a coarse clock
        now = datetime.now(timezone.utc)
        recorded = [time for time in map(self.result_time, STAGES) if time is not None]
        if recorded and now <= max(recorded):
            now = max(recorded) + timedelta(microseconds=1)
        self.record.stamp(stage, now.isoformat(timespec="microseconds"), list(self.results[stage]))

    def result_time(self, stage: str) -> datetime | None:
        """Return when nbcalib wrote ``results[stage]``; None if the reference wrote it."""
        _check_stage(stage)
        times = self.record.result_times
        text = times.get(stage) if times is not None else None
        if not isinstance(text, str) or stage not in self.results:
            return None
        written = self.record.result_values
        current = self.results[stage]
        if isinstance(written, dict) and written.get(stage, current) != current:
            return None  # rewritten since (by the reference or by hand): time unknown
        try:
            time = datetime.fromisoformat(text)
        except ValueError:
            return None
        return time if time.tzinfo is not None else time.replace(tzinfo=timezone.utc)

    def latest_initial_stage(self) -> str | None:
        """Return the initial guess to start from: the more recently written one, or None.

        When both guesses are present and both have a recorded time, the later wins; otherwise
        (written by the reference, or equal times) the manual guess is preferred, as the
        reference's ``calibrate`` does.
        """
        present = [stage for stage in INITIAL_STAGES if stage in self.results]
        if len(present) < 2:
            return present[0] if present else None
        manual_time, auto_time = (self.result_time(stage) for stage in INITIAL_STAGES)
        if manual_time is not None and auto_time is not None and auto_time > manual_time:
            return AUTO_STAGE
        return MANUAL_STAGE

    def latest_stage(self) -> str | None:
        """Return the result to judge: the final one if present, else the latest initial guess."""
        if FINAL_STAGE in self.results:
            return FINAL_STAGE
        return self.latest_initial_stage()


# ---------------------------------------------------------------------- files
def read_calib_json(path: str | os.PathLike) -> CalibFile:
    """Read and validate a ``calib.json``.

    Parameters
    ----------
    path : str or PathLike
        The file (usually ``WORKDIR/calib.json``).

    Returns
    -------
    CalibFile

    Raises
    ------
    InputError
        Missing or unreadable file, invalid JSON, a non-finite number, a missing ``camera``
        entry or key, or a result that is not 7 finite numbers; the message names the file.
    """
    return CalibFile.from_dict(read_json(path), path=path)


def write_calib_json(path: str | os.PathLike, calib: CalibFile) -> None:
    """Write ``calib`` to ``path`` atomically, keys sorted, indent 2 (like the reference).

    Raises
    ------
    ValueError
        If ``calib`` lacks a valid ``camera`` entry or holds a non-finite number (both are
        programming errors: the file would not load again).
    """
    try:
        _check_camera(calib.camera, None)
    except InputError as exc:
        raise ValueError(f"cannot write calib.json: {exc}") from None
    write_json(path, calib.to_dict())


def read_json(path: str | os.PathLike) -> Any:
    """Parse a JSON file strictly (NaN, Infinity and overflowing numbers are an InputError)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a JSON file", path) from None
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    try:
        return json.loads(text, parse_constant=_reject_constant, parse_float=_parse_float)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}", path
        ) from None
    except _NonFiniteError as exc:
        raise InputError(
            f"non-finite number {exc} (calib files hold finite numbers)", path
        ) from None


def write_json(path: str | os.PathLike, data: Any) -> None:
    """Write ``data`` as JSON like nlohmann's ``dump(2)`` (sorted keys, indent 2), atomically.

    NumPy arrays and scalars are written as lists and numbers. Non-finite floats raise
    :class:`ValueError`.
    """
    text = json.dumps(
        data, indent=2, sort_keys=True, ensure_ascii=False, allow_nan=False, default=_to_json
    )
    write_text_atomic(path, text + "\n")


def read_image_size(path: str | os.PathLike) -> tuple[int, int]:
    """Return ``(width, height)`` of an image file (a PNG's header is read, not the image)."""
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            head = stream.read(24)
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    import cv2

    try:
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    except cv2.error:  # a corrupt header OpenCV refuses (sizes beyond its limits)
        image = None
    if image is None:
        raise InputError("not an image OpenCV can read", path)
    return int(image.shape[1]), int(image.shape[0])


# ---------------------------------------------------------------------- pose values
def T_camera_lidar_from_values(
    values, *, what: str = "pose", path: str | os.PathLike | None = None
) -> np.ndarray:
    """Convert stored ``T_lidar_camera`` ``[x, y, z, qx, qy, qz, qw]`` to ``T_camera_lidar``.

    The quaternion is normalised; a wrong length, non-finite value or zero quaternion is an
    :class:`InputError` naming ``what`` and ``path``.
    """
    _check_pose(values, what, path)
    xyz_quat = np.array(values, dtype=np.float64)
    xyz_quat[3:] /= np.max(np.abs(xyz_quat[3:]))  # first: the norm of huge values overflows
    xyz_quat[3:] /= np.linalg.norm(xyz_quat[3:])
    return invert_T(pose_from_xyz_quat(xyz_quat))


def values_from_T_camera_lidar(T_camera_lidar: np.ndarray) -> list[float]:
    """Convert a pose to the stored ``T_lidar_camera`` ``[x, y, z, qx, qy, qz, qw]``.

    Parameters
    ----------
    T_camera_lidar : ndarray of shape (4, 4), float64
        ``p_camera = T_camera_lidar @ p_lidar``.

    Returns
    -------
    list of 7 float
        Its inverse, ``T_lidar_camera``, translation in metres and quaternion xyzw.
    """
    T_camera_lidar = np.asarray(T_camera_lidar, dtype=np.float64)
    if T_camera_lidar.shape != (4, 4) or not np.all(np.isfinite(T_camera_lidar)):
        raise ValueError(f"T_camera_lidar must be a finite (4, 4) array, got {T_camera_lidar!r}")
    return [float(x) for x in pose_to_xyz_quat(invert_T(T_camera_lidar))]


# ---------------------------------------------------------------------- checks
class _NonFiniteError(ValueError):
    pass


def _reject_constant(name: str):
    raise _NonFiniteError(name)


def _parse_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _NonFiniteError(text)
    return value


def _to_json(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _kind(value) -> str:
    return {dict: "an object", list: "an array", str: "a string", bool: "a boolean"}.get(
        type(value), "null" if value is None else "a number"
    )


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _check_numbers(values, what: str, path) -> None:
    if not isinstance(values, list) or not all(_is_number(v) for v in values):
        raise InputError(f"{what} must be a list of numbers, got {json.dumps(values)}", path)
    try:
        finite = all(math.isfinite(v) for v in values)
    except OverflowError:  # an integer beyond the range of floats
        raise InputError(f"{what} holds a number too large for a float", path) from None
    if not finite:
        raise InputError(f"{what} holds a non-finite number", path)


def _check_camera(camera, path) -> None:
    if not isinstance(camera, dict):
        raise InputError(f"'camera' must be a JSON object, got {_kind(camera)}", path)
    missing = [key for key in CAMERA_KEYS if key not in camera]
    if missing:
        raise InputError(f"camera lacks {', '.join(missing)}", path)
    if not isinstance(camera["camera_model"], str) or not camera["camera_model"]:
        raise InputError("camera.camera_model must be a model name", path)
    _check_numbers(camera["intrinsics"], "camera.intrinsics", path)
    _check_numbers(camera["distortion_coeffs"], "camera.distortion_coeffs", path)


def _check_pose(values, what: str, path) -> None:
    if not isinstance(values, (list, tuple, np.ndarray)) or len(values) != 7:
        raise InputError(
            f"{what} must be 7 numbers [x, y, z, qx, qy, qz, qw], got {_short(values)}", path
        )
    _check_numbers(list(values), what, path)
    if math.hypot(*values[3:]) < 1e-12:
        raise InputError(f"{what} has a zero quaternion", path)


def _check_stage(stage: str) -> None:
    if stage not in STAGES:
        raise ValueError(f"stage must be one of {STAGES}, got {stage!r}")


def _matrix_pose(values, what: str, path) -> np.ndarray:
    shape_ok = (
        isinstance(values, list)
        and len(values) == 4
        and all(isinstance(row, list) and len(row) == 4 for row in values)
    )
    if not shape_ok:
        raise InputError(f"{what} must be a 4x4 nested list, got {_short(values)}", path)
    _check_numbers([x for row in values for x in row], what, path)
    T = np.array(values, dtype=np.float64)
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=1e-9):
        raise InputError(f"{what} last row must be [0, 0, 0, 1]", path)
    R = T[:3, :3]
    if np.max(np.abs(R.T @ R - np.eye(3))) > 1e-3 or np.linalg.det(R) <= 0:
        raise InputError(f"{what} rotation part is not a rotation matrix", path)
    U, _, Vt = np.linalg.svd(R)
    T[:3, :3] = U @ Vt
    return T


def _short(value) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 60 else text[:57] + "..."
