"""The job's record: nbcalib's own section of ``calib.json``, typed; its keys are spelled here only.

The reference toolbox ignores ``calib.json``'s ``nbcalib`` section; nbcalib keeps in it what a
job did and how, so that a later command can resume, judge or report it. :class:`JobRecord` is
that section, one attribute per entry; the entries read field by field have record types of
their own (:class:`CameraEntry`, :class:`VirtualCameraEntry`, :class:`InitialGuessRecord`,
:class:`CalibrationRecord`, :class:`QualityRecord`), and the entries another module writes and
reads whole (the config tree, the inputs, what made each stage) stay mappings in that module's
own format. :class:`RunOptions` and :class:`PreprocessSummary` type the run's remembered options
and the preprocessing summary.

``nbcalib`` section of ``calib.json``:

========================== ================================================================
key                        attribute
========================== ================================================================
``camera``                 :attr:`JobRecord.camera` (model name and image size)
``result_times``           :attr:`JobRecord.result_times` (``{stage: ISO 8601 time}``)
``result_values``          :attr:`JobRecord.result_values` (``{stage: [7 numbers]}``)
``virtual_camera``         :attr:`JobRecord.virtual_camera` (the LiDAR images' camera)
``preprocess``             :attr:`JobRecord.preprocess` (:class:`PreprocessSummary`)
``inputs``                 :attr:`JobRecord.inputs` (the job's inputs, as given)
``config``                 :attr:`JobRecord.config` (:func:`nbcalib.config.config_to_dict`)
``run``                    :attr:`JobRecord.run` (:class:`RunOptions`)
``made``                   :attr:`JobRecord.made` (``{stage: recipe}``; absent: not nbcalib's)
``seconds``                :attr:`JobRecord.seconds` (``{stage: seconds}``)
``initial_guess``          :attr:`JobRecord.initial_guess`
``calibration``            :attr:`JobRecord.calibration`
``quality``                :attr:`JobRecord.quality`
========================== ================================================================

Every key this module does not know, and every value of the wrong kind (a hand-edited file),
is kept as read and written back unchanged (``other``), so that a round trip loses nothing; an
entry of the wrong kind reads as absent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

# The keys of calib.json's ``results`` (re-exported by :mod:`nbcalib.io.calib_json`).

#: Key of the final result (written by ``calibrate``).
FINAL_STAGE = "T_lidar_camera"
#: Key of the manual initial guess.
MANUAL_STAGE = "init_T_lidar_camera"
#: Key of the automatic initial guess.
AUTO_STAGE = "init_T_lidar_camera_auto"
#: Every result key, final first.
STAGES = (FINAL_STAGE, MANUAL_STAGE, AUTO_STAGE)
#: Initial guesses in the order the reference's ``calibrate`` prefers them.
INITIAL_STAGES = (MANUAL_STAGE, AUTO_STAGE)

__all__ = [
    "AUTO_STAGE",
    "FINAL_STAGE",
    "INITIAL_STAGES",
    "MANUAL_STAGE",
    "STAGES",
    "CalibrationRecord",
    "CameraEntry",
    "GuessFigures",
    "InitialGuessRecord",
    "JobRecord",
    "PreprocessSummary",
    "QualityRecord",
    "RunOptions",
    "VirtualCameraEntry",
]


def _is_dict(value) -> bool:
    return isinstance(value, dict)


def _is_str(value) -> bool:
    return isinstance(value, str)


def _is_list(value) -> bool:
    return isinstance(value, list)


def _is_bool(value) -> bool:
    return isinstance(value, bool)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_count(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _is_size(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def _split(data: dict, checks: dict[str, Callable[[Any], bool]]) -> tuple[dict, dict]:
    """(the declared keys whose values pass their check, every other key as read)."""
    known, other = {}, {}
    for key, value in data.items():
        (known if key in checks and checks[key](value) else other)[key] = value
    return known, other


def _join(other: dict, known: dict) -> dict:
    """``other`` with the known entries that are set (not None) over it."""
    out = dict(other)
    out.update({key: value for key, value in known.items() if value is not None})
    return out


@dataclass
class CameraEntry:
    """``nbcalib.camera``: the camera's nbcalib model name and image size.

    The reference stores neither: ``pinhole`` is written there as ``plumb_bob`` with zero
    distortion (:meth:`nbcalib.io.calib_json.CalibFile.set_camera`).
    """

    model: str | None = None
    width: int | None = None
    height: int | None = None
    other: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict) -> CameraEntry:
        """The entry of a parsed ``nbcalib.camera``."""
        known, other = _split(
            data, {"camera_model": _is_str, "width": _is_size, "height": _is_size}
        )
        return cls(known.get("camera_model"), known.get("width"), known.get("height"), other)

    def to_dict(self) -> dict:
        """The ``nbcalib.camera`` to write."""
        return _join(
            self.other, {"camera_model": self.model, "width": self.width, "height": self.height}
        )

    @property
    def size(self) -> tuple[int, int] | None:
        """``(width, height)``, or None when not both are recorded."""
        if self.width is None or self.height is None:
            return None
        return self.width, self.height


@dataclass
class VirtualCameraEntry:
    """``nbcalib.virtual_camera``: the camera that rendered the LiDAR images.

    :func:`nbcalib.workdir.set_virtual_camera` and :func:`~nbcalib.workdir.get_virtual_camera`
    turn it into a :class:`~nbcalib.preprocess.lidar_image.VirtualCamera` and back.

    Attributes
    ----------
    camera : dict or None
        :meth:`nbcalib.camera.CameraModel.to_dict` of its camera.
    T_vcam_lidar : list or None
        Its pose, 4 x 4 nested lists (maps LiDAR points into the virtual camera's frame).
    lidar_fov_deg : float or None
        The LiDAR's field of view it was chosen for.
    """

    camera: dict | None = None
    T_vcam_lidar: list | None = None
    lidar_fov_deg: float | None = None
    other: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict) -> VirtualCameraEntry:
        """The entry of a parsed ``nbcalib.virtual_camera``."""
        checks = {"camera": _is_dict, "T_vcam_lidar": _is_list, "lidar_fov_deg": _is_number}
        known, other = _split(data, checks)
        return cls(**known, other=other)

    def to_dict(self) -> dict:
        """The ``nbcalib.virtual_camera`` to write."""
        return _join(
            self.other,
            {
                "camera": self.camera,
                "T_vcam_lidar": self.T_vcam_lidar,
                "lidar_fov_deg": self.lidar_fov_deg,
            },
        )


@dataclass
class GuessFigures:
    """``nbcalib.initial_guess.<result key>``: one written guess's figures, as written.

    Written through :meth:`make` (every figure by name); read through the attributes below.
    """

    values: dict = field(default_factory=dict)

    @classmethod
    def make(
        cls,
        *,
        correspondences: int,
        ransac_inliers: int,
        inliers: int,
        rms_px: float | None,
        support,
        runner_up,
        runner_up_shared,
        bound_m: float | None,
        bound_deg: float | None,
        success: bool,
        seed: int,
        confidence_weights: bool,
        source: str,
        matcher: str | None,
        precise: bool | None = None,
    ) -> GuessFigures:
        """The figures of a guess (:class:`nbcalib.initial_guess.estimate.InitialGuess`).

        ``success``: the guess passed its whole test (found and precise); ``precise`` (written
        when given): its precision part alone. A found guess that is not precise is still
        refined, and the report judges the result.
        """
        extra = {} if precise is None else {"precise": precise}
        return cls(
            {
                **extra,
                "correspondences": correspondences,
                "ransac_inliers": ransac_inliers,
                "inliers": inliers,
                "rms_px": rms_px,
                "support": support,
                "runner_up": runner_up,
                "runner_up_shared": runner_up_shared,
                "bound_m": bound_m,
                "bound_deg": bound_deg,
                "success": success,
                "seed": seed,
                "confidence_weights": confidence_weights,
                "source": source,
                "matcher": matcher,
            }
        )

    def to_dict(self) -> dict:
        """The entry to write."""
        return dict(self.values)

    def _get(self, key: str, check: Callable[[Any], bool]):
        value = self.values.get(key)
        return value if check(value) else None

    @property
    def success(self) -> bool | None:
        """Whether the guess passed its success test."""
        return self._get("success", _is_bool)

    @property
    def matcher(self) -> str | None:
        """The matcher whose matches made it (None: hand-picked, or not recorded)."""
        return self._get("matcher", _is_str)

    @property
    def correspondences(self) -> int | None:
        """Correspondences it was estimated from."""
        return self._get("correspondences", _is_count)

    @property
    def inliers(self) -> int | None:
        """Correspondences its pose explains."""
        return self._get("inliers", _is_count)

    @property
    def bound_deg(self) -> float | None:
        """The rotation bound its noise allows, degrees (None: unbounded or not recorded)."""
        return self._get("bound_deg", _is_number)


@dataclass
class InitialGuessRecord:
    """``nbcalib.initial_guess``: each written guess's figures, and why the last one failed.

    Attributes
    ----------
    stages : dict
        ``{result key: GuessFigures}`` of each guess written.
    failed : str or None
        Why the automatic guess was not written (a fallback start then stands in).
    """

    stages: dict[str, GuessFigures] = field(default_factory=dict)
    failed: str | None = None
    other: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict) -> InitialGuessRecord:
        """The record of a parsed ``nbcalib.initial_guess``."""
        checks = {"failed": _is_str, **{stage: _is_dict for stage in INITIAL_STAGES}}
        known, other = _split(data, checks)
        failed = known.pop("failed", None)
        return cls({stage: GuessFigures(dict(v)) for stage, v in known.items()}, failed, other)

    def to_dict(self) -> dict:
        """The ``nbcalib.initial_guess`` to write."""
        stages = {stage: figures.to_dict() for stage, figures in self.stages.items()}
        return _join(self.other, {**stages, "failed": self.failed})

    def matcher(self, stage: str) -> str | None:
        """The matcher whose matches made the guess ``stage`` (None: not recorded)."""
        figures = self.stages.get(stage)
        return None if figures is None else figures.matcher


#: The fields of :class:`CalibrationRecord` and what their values must be.
_CALIBRATION_CHECKS = {
    "start": _is_str,
    "start_T_lidar_camera": _is_list,
    "start_uncertainty": _is_dict,
    "converged": _is_bool,
    "failed": _is_str,
    "attempted_T_lidar_camera": _is_list,
}


@dataclass
class CalibrationRecord:
    """``nbcalib.calibration``: fine registration's start, its end, and its figures.

    Attributes
    ----------
    start : str or None
        Where the start came from (a result key, ``--init``, ``warm-up``, ...).
    start_T_lidar_camera : list of 7 floats or None
        The start, stored like a result (``[x, y, z, qx, qy, qz, qw]`` of ``T_lidar_camera``).
    start_uncertainty : dict or None
        The start's stated uncertainty (``translation_m``, ``rotation_deg``), if stated.
    converged : bool or None
        Whether the optimiser converged.
    failed : str or None
        Why there is no result (its optimum beyond the trust region), with
    attempted_T_lidar_camera : list of 7 floats or None
        the pose it stopped at.
    figures : dict
        Everything else it records (optimizer, cost, NID history, iterations, seconds, ...).
    """

    start: str | None = None
    start_T_lidar_camera: list | None = None
    start_uncertainty: dict | None = None
    converged: bool | None = None
    failed: str | None = None
    attempted_T_lidar_camera: list | None = None
    figures: dict = field(default_factory=dict)

    @classmethod
    def make(
        cls,
        *,
        start: str,
        start_T_lidar_camera: list,
        start_uncertainty: dict | None,
        converged: bool,
        optimizer: str,
        cost: str,
        bins: int,
        pyramid_levels: int,
        pairs: list[str],
        nid: float,
        nid_history: list[float],
        iterations: int,
        evaluations: int,
        stopped: str,
        seconds: float,
        change_from_start: tuple[float, float],
        trust_region: tuple[float, float],
        at_trust_boundary: bool,
    ) -> CalibrationRecord:
        """The record of a fine registration.

        ``nid_history`` runs from the start's NID on; ``change_from_start`` and
        ``trust_region`` are (metres, degrees).
        """

        def move(pair):
            return {"translation_m": float(pair[0]), "rotation_deg": float(pair[1])}

        figures = {
            "optimizer": optimizer,
            "cost": cost,
            "bins": bins,
            "pyramid_levels": pyramid_levels,
            "pairs": pairs,
            "nid": nid,
            "nid_start": nid_history[0],
            "nid_history": nid_history,
            "outer_iterations": len(nid_history) - 1,
            "iterations": iterations,
            "evaluations": evaluations,
            "stopped": stopped,
            "seconds": seconds,
            "change_from_start": move(change_from_start),
            "trust_region": {
                "translation_m": trust_region[0],
                "rotation_deg": trust_region[1],
            },
            "at_trust_boundary": at_trust_boundary,
        }
        return cls(
            start=start,
            start_T_lidar_camera=start_T_lidar_camera,
            start_uncertainty=start_uncertainty,
            converged=converged,
            figures=figures,
        )

    @classmethod
    def adopted(
        cls,
        source: str,
        *,
        converged: bool | None,
        start: str | None = None,
        start_T_lidar_camera: list | None = None,
        start_uncertainty: dict | None = None,
        change_from_start: tuple[float, float] | None = None,
    ) -> CalibrationRecord:
        """The record of a result found elsewhere (``source``: a rig's joint registration)."""
        figures = {"adopted_from": source}
        if change_from_start is not None:
            figures["change_from_start"] = {
                "translation_m": float(change_from_start[0]),
                "rotation_deg": float(change_from_start[1]),
            }
        return cls(start, start_T_lidar_camera, start_uncertainty, converged, figures=figures)

    @property
    def nid_history(self) -> list | None:
        """NID at the start, then after each outer iteration."""
        value = self.figures.get("nid_history")
        return value if isinstance(value, list) else None

    @classmethod
    def from_dict(cls, data: dict) -> CalibrationRecord:
        """The record of a parsed ``nbcalib.calibration``."""
        known, figures = _split(data, _CALIBRATION_CHECKS)
        return cls(**known, figures=figures)

    def to_dict(self) -> dict:
        """The ``nbcalib.calibration`` to write."""
        return _join(self.figures, {key: getattr(self, key) for key in _CALIBRATION_CHECKS})


@dataclass
class QualityRecord:
    """``nbcalib.quality``: the report's figures and which result they judged.

    Attributes
    ----------
    assessed_T_lidar_camera : list of 7 floats or None
        The result the report judged, stored like a result: the report is current while
        ``results.T_lidar_camera`` still holds it.
    figures : dict
        :meth:`nbcalib.report.quality.Quality.to_dict`, with the page and when it was written.
    """

    assessed_T_lidar_camera: list | None = None
    figures: dict = field(default_factory=dict)

    @classmethod
    def make(cls, figures: dict, *, page: str, written: str, assessed: list) -> QualityRecord:
        """The record of a report.

        Its ``figures``, its ``page`` (relative to the work directory), when it was
        ``written`` (ISO 8601) and the result it ``assessed``.
        """
        return cls(assessed, {**figures, "report": page, "written": written})

    @classmethod
    def from_dict(cls, data: dict) -> QualityRecord:
        """The record of a parsed ``nbcalib.quality``."""
        known, figures = _split(data, {"assessed_T_lidar_camera": _is_list})
        return cls(known.get("assessed_T_lidar_camera"), figures)

    def to_dict(self) -> dict:
        """The ``nbcalib.quality`` to write."""
        return _join(self.figures, {"assessed_T_lidar_camera": self.assessed_T_lidar_camera})


@dataclass
class PreprocessSummary:
    """``nbcalib.preprocess``: what preprocessing made of each pair, and the LiDAR's view.

    Attributes
    ----------
    pairs : dict of str to dict
        Each pair's summary (:attr:`nbcalib.products.PairData.summary`: mode, scans, points,
        where the pair sits in its recording), by pair name.
    lidar_fov_deg : float or None
        The LiDAR's horizontal field of view the virtual camera was chosen for.
    lidar_origin : dict or None
        Where the LiDAR sits in the clouds' frame and how that was decided
        (:class:`nbcalib.preprocess.origin.LidarOrigin`: ``xyz``, ``source``, ``detail``).
    """

    pairs: dict = field(default_factory=dict)
    lidar_fov_deg: float | None = None
    other: dict = field(default_factory=dict)
    lidar_origin: dict | None = None

    @classmethod
    def from_dict(cls, data: dict) -> PreprocessSummary:
        """The record of a parsed ``nbcalib.preprocess``."""
        known, other = _split(
            data, {"pairs": _is_dict, "lidar_fov_deg": _is_number, "lidar_origin": _is_dict}
        )
        return cls(
            known.get("pairs", {}), known.get("lidar_fov_deg"), other, known.get("lidar_origin")
        )

    def to_dict(self) -> dict:
        """The ``nbcalib.preprocess`` to write."""
        return _join(
            self.other,
            {
                "pairs": self.pairs,
                "lidar_fov_deg": self.lidar_fov_deg,
                "lidar_origin": self.lidar_origin,
            },
        )


@dataclass
class RunOptions:
    """``nbcalib.run``: the options ``nbcalib run`` keeps for a resumed job (``run WORKDIR``).

    Each as typed (strings and flags; None: not given). Written with every field, given or
    not, so that a record says which options a job was run without.
    """

    init: Any = None
    init_uncertainty: Any = None
    manual: Any = None
    prior: Any = None
    no_matching: Any = None
    no_report: Any = None
    model_dir: Any = None
    other: dict = field(default_factory=dict)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The options kept, in the order written."""
        return tuple(f.name for f in fields(cls) if f.name != "other")

    @classmethod
    def from_dict(cls, data: dict) -> RunOptions:
        """The record of a parsed ``nbcalib.run`` (or of the command line's options)."""
        names = cls.names()
        known = {key: data[key] for key in names if key in data}
        other = {key: value for key, value in data.items() if key not in names}
        return cls(**known, other=other)

    def to_dict(self) -> dict:
        """The ``nbcalib.run`` to write (every option, None when not given)."""
        out = dict(self.other)
        out.update({name: getattr(self, name) for name in self.names()})
        return out

    def given(self) -> dict:
        """The options this record holds a value for (``{name: value}``)."""
        return {
            name: getattr(self, name) for name in self.names() if getattr(self, name) is not None
        }


#: Entries kept as mappings (each in its own module's format), by key = attribute name.
_MAPPINGS = (
    "result_times",
    "result_values",
    "inputs",
    "config",
    "made",
    "seconds",
)
#: Entries with record types of their own: key -> type.
_RECORDS = {
    "camera": CameraEntry,
    "virtual_camera": VirtualCameraEntry,
    "preprocess": PreprocessSummary,
    "run": RunOptions,
    "initial_guess": InitialGuessRecord,
    "calibration": CalibrationRecord,
    "quality": QualityRecord,
}


@dataclass
class JobRecord:
    """``calib.json``'s ``nbcalib`` section (module docstring); None: not recorded."""

    camera: CameraEntry | None = None
    result_times: dict | None = None
    result_values: dict | None = None
    virtual_camera: VirtualCameraEntry | None = None
    preprocess: PreprocessSummary | None = None
    inputs: dict | None = None
    config: dict | None = None
    run: RunOptions | None = None
    made: dict | None = None
    seconds: dict | None = None
    initial_guess: InitialGuessRecord | None = None
    calibration: CalibrationRecord | None = None
    quality: QualityRecord | None = None
    other: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, data: dict) -> JobRecord:
        """The record of a parsed ``nbcalib`` section (unknown or malformed entries kept)."""
        checks = {key: _is_dict for key in (*_MAPPINGS, *_RECORDS)}
        known, other = _split(data, checks)
        for key, kind in _RECORDS.items():
            if key in known:
                known[key] = kind.from_dict(known[key])
        return cls(**known, other=other)

    def to_dict(self) -> dict:
        """The ``nbcalib`` section to write (entries not recorded left out)."""
        known = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "other" or value is None:
                continue
            known[f.name] = value.to_dict() if f.name in _RECORDS else value
        return _join(self.other, known)

    def __bool__(self) -> bool:
        return bool(self.to_dict())

    # ------------------------------------------------------------------ entries by stage
    def guess(self) -> InitialGuessRecord:
        """:attr:`initial_guess`, made empty first if not recorded."""
        if self.initial_guess is None:
            self.initial_guess = InitialGuessRecord()
        return self.initial_guess

    def set_made(self, stage: str, recipe: dict, seconds: float) -> None:
        """Record what made ``stage``'s product and how long it took."""
        if self.made is None:
            self.made = {}
        self.made[stage] = recipe
        if self.seconds is None:
            self.seconds = {}
        self.seconds[stage] = seconds

    def forget_made(self, stage: str) -> None:
        """Forget what made ``stage`` (its product is gone or stale)."""
        if self.made is not None:
            self.made.pop(stage, None)

    def stamp(self, stage: str, time: str, values: list) -> None:
        """Record when a result was written, and its values then."""
        if self.result_times is None:
            self.result_times = {}
        if self.result_values is None:
            self.result_values = {}
        self.result_times[stage] = time
        self.result_values[stage] = values

    def unstamp(self, stage: str) -> None:
        """Forget a removed result's time and values."""
        for stamps in (self.result_times, self.result_values):
            if stamps is not None:
                stamps.pop(stage, None)
