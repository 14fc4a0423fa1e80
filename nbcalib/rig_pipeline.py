"""Several cameras, one LiDAR: a job per camera under one work directory, and the rig on top.

A recording with several cameras (a bag with several image topics) is calibrated camera by
camera with the single-camera pipeline (:class:`~nbcalib.pipeline.Calibrator`, every stage as
for one camera), sharing what the cameras have in common:

- the recording is read once, and each pair's dense cloud is accumulated once for every camera
  (:attr:`nbcalib.preprocess.inputs.PairInput.clouds`);
- without known camera-to-camera extrinsics each camera's extrinsic is found on its own (guess,
  then fine registration), and the camera-to-camera transforms they imply are reported;
- with them (``rig``: :class:`nbcalib.io.rig.Rig`, a Kalibr camchain or nbcalib's rig file),
  each camera's initial guess is found on its own, then one rig pose is refined from every
  camera's pairs at once: fine registration of the reference camera's ``T_camera_lidar`` with
  every other camera's pairs seen through the rig (:class:`~nbcalib.registration.costs.RigTerm`),
  and each other camera's extrinsic is that pose through the rig.

Work directory (docs/multi_camera.md)::

    WORK/rig.json        the job: cameras, topics, each result, the camera-to-camera transforms
    WORK/<camera>/       each camera's own work directory, the reference toolbox's layout

Example
-------
>>> from nbcalib.rig_pipeline import RigCalibrator, find_cameras             # doctest: +SKIP
>>> spec = InputSpec(inputs=("ring.bag",))                                    # doctest: +SKIP
>>> cameras = find_cameras(spec, config.preprocess)                          # doctest: +SKIP
>>> results = RigCalibrator(config, workdir="work").run(spec, cameras)       # doctest: +SKIP
"""

from __future__ import annotations

import contextlib
import json
import logging
import re
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from nbcalib.config import CalibrationConfig
from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.inputs import InputSpec
from nbcalib.preprocess.sources import PairInput, SharedClouds, bag_name, classify_inputs
from nbcalib.products import Start
from nbcalib.transforms import invert_T, pose_error, pose_to_xyz_quat

__all__ = ["CameraSource", "RigCalibrator", "RigResult", "find_cameras", "read_rig_job"]

log = logging.getLogger("nbcalib.pipeline")

#: The job's record at the top of a several-camera work directory.
RIG_JOB = "rig.json"

#: Cameras whose stages run at once. Each stage keeps about 1.7 of 2 cores busy (a one-camera
#: run: 86 s CPU in 50 s); two cameras side by side fill the gaps: two one-camera runs took
#: 84.9 s at once against 96.7 s one after the other, with the same results
#: (docs/BENCHMARKS.md, several cameras).
CAMERA_WORKERS = 2

#: How far (degrees) a camera's own guess, taken through the given rig, may put the rig from
#: the start before the rig is doubted: guesses are good to a few tenths of a degree, a wrong
#: rig file (other cameras, another order) is off by tens of degrees.
RIG_START_TOLERANCE_DEG = 2.0


@dataclass(frozen=True)
class CameraSource:
    """Where one camera of a recording is: its name, image topic and camera info topic.

    ``name`` names the camera's work directory (``WORK/<name>/``) and its lines in reports: the
    image topic's namespace (``/cam0/image`` -> ``cam0``, ``/front/image_raw`` -> ``front``).
    """

    name: str
    image_topic: str
    camera_info_topic: str | None = None


def camera_name(topic: str) -> str:
    """A camera's name from its image topic: the namespace, else the topic, as a folder name."""
    parts = [p for p in topic.split("/") if p]
    words = parts[:-1] or parts
    return re.sub(r"[^A-Za-z0-9_.-]", "_", "_".join(words)) or "camera"


def find_cameras(
    spec: InputSpec, config: PreprocessConfig, topics: Sequence[str] | None = None
) -> list[CameraSource] | None:
    """The cameras of a job's recording, or None for a job of one camera.

    Several cameras: ``topics`` (image topics, ``--camera-topics``), or every image topic of a
    bag that has several when no image topic is chosen (``config.image_topic``). Each camera's
    camera info is the one topic in its image topic's namespace (``/cam0/camera_info`` for
    ``/cam0/image``), or none.

    Raises
    ------
    InputError
        Camera topics for inputs that are not bags, a topic the bag does not have or that is
        no image, two cameras of one name, or a recording form (pairs per image) that several
        cameras do not take yet.
    """
    from nbcalib.io.bag import open_bag

    bags, _, _ = classify_inputs(spec.inputs)
    if not bags:
        if topics:
            raise InputError("run.camera_topics takes image topics of bags; give a bag")
        return None
    if topics is None and config.image_topic is not None:
        return None
    first = sorted(bags, key=lambda p: p.name)[0]
    with open_bag(first) as bag:
        images = bag.candidates("image")
        infos = bag.candidates("camera info")
        if topics is not None:
            for topic in topics:
                bag.select_topic("image", topic)  # exists and carries images
    if topics is None:
        if len(images) < 2:
            return None
        topics = images
    topics = list(dict.fromkeys(topics))
    if len(topics) < 2:
        return None
    if spec.per_image:
        raise InputError(
            "several cameras take one pair per bag for now: leave out inputs.every, "
            "inputs.pair_count "
            "and inputs.image_times (or calibrate one camera with preprocess.image_topic)"
        )
    if spec.camera or spec.camera_model:
        raise InputError(
            "inputs.camera/inputs.camera_model give one camera: with several cameras each "
            "camera's comes "
            "from its camera info topic (or from run.rig)"
        )
    cameras = []
    for topic in topics:
        space = topic.rsplit("/", 1)[0] + "/"
        mine = [t for t in infos if t.startswith(space)] if space != "/" else []
        cameras.append(CameraSource(camera_name(topic), topic, mine[0] if len(mine) == 1 else None))
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise InputError(f"two camera topics make the same camera name: {', '.join(topics)}")
    return cameras


class _Recording:
    """Every bag of a job read once: each pair's scans, and each camera's image and camera info."""

    def __init__(self, spec: InputSpec, cameras: Sequence[CameraSource], rig_cameras=None):
        self.spec, self.cameras = spec, list(cameras)
        self.rig_cameras = dict(rig_cameras or {})  # {camera: CameraModel} of a given rig
        self._pairs: dict[str, list[PairInput]] | None = None
        self._camera: dict[str, object] = {}
        self._data_path = ""
        self._lock = threading.Lock()  # cameras preprocess at once: the first one reads

    def gather(self, name: str, config: PreprocessConfig):
        """(pairs, camera, data path) of camera ``name``, as :meth:`InputSpec.gather`."""
        with self._lock:
            if self._pairs is None:
                self._read(config)
        camera = self._camera.get(name)
        if camera is None:
            raise InputError(
                f"camera {name}: no camera info topic found; give the cameras with run.rig FILE "
                "(a Kalibr camchain or an nbcalib rig file)"
            )
        return self._pairs[name], camera, self._data_path

    def _read(self, config: PreprocessConfig) -> None:
        from nbcalib.io.bag import open_bag
        from nbcalib.preprocess.sources import bag_scans, first_image

        bags = sorted(classify_inputs(self.spec.inputs)[0], key=lambda p: p.name)
        pairs: dict[str, list[PairInput]] = {c.name: [] for c in self.cameras}
        for path in bags:
            with open_bag(path) as bag:
                points_topic = bag.select_topic("point cloud", config.points_topic)
                scans = bag_scans(bag, points_topic, config, path)
                clouds = SharedClouds()  # one dense cloud per pair, for every camera
                for source in self.cameras:
                    image = first_image(bag, source.image_topic, path)
                    info = source.camera_info_topic
                    camera = bag.camera_info(info) if info is not None else None
                    if camera is None:  # the rig's camera of this name, if any
                        camera = self.rig_cameras.get(source.name)
                    self._camera.setdefault(source.name, camera)
                    topics = {
                        "points_topic": points_topic,
                        "image_topic": source.image_topic,
                        "camera_info_topic": info or "N/A",
                    }
                    pairs[source.name].append(
                        PairInput(
                            bag_name(path),
                            scans,
                            image,
                            f"{path} {source.image_topic}",
                            camera,
                            topics,
                            clouds=clouds,
                        )
                    )
        self._pairs = pairs
        self._data_path = str(Path(bags[0]).resolve().parent)


@dataclass
class _CameraInputs:
    """One camera's inputs for its :class:`~nbcalib.pipeline.Calibrator` (as an InputSpec)."""

    spec: InputSpec
    name: str
    recording: _Recording

    @property
    def empty(self) -> bool:
        return self.spec.empty

    def gather(self, config: PreprocessConfig):
        return self.recording.gather(self.name, config)

    def to_dict(self) -> dict:
        # the spec itself: the camera's topic is in its config, so that the camera's own work
        # directory continues as a one-camera job (nbcalib run WORK/<camera>)
        return self.spec.to_dict()


@dataclass
class RigResult:
    """What a several-camera job found.

    Attributes
    ----------
    cameras : dict of str to CalibrationResult or None
        Each camera's result (None: the job stopped before fine registration).
    reference : str
        The reference camera (the first): the rig's pose is its ``T_camera_lidar``.
    joint : bool
        One rig pose refined from every camera (camera-to-camera extrinsics given).
    T_ref_camera : dict of str to ndarray (4, 4)
        Each camera in the reference camera's frame, as the LiDAR results imply (without a
        rig) or as given (with one).
    rig_errors : dict of str to (float, float)
        Given rig only, no joint pose: how far each implied camera-to-camera transform is from
        the given one (metres, degrees).
    failed : dict of str to str
        The cameras left without a result, and why.
    seconds : float
    """

    cameras: dict
    reference: str
    joint: bool = False
    T_ref_camera: dict = field(default_factory=dict)
    rig_errors: dict = field(default_factory=dict)
    failed: dict = field(default_factory=dict)
    seconds: float = 0.0


class RigCalibrator:
    """Calibrate every camera of a recording against its LiDAR (module docstring).

    Parameters
    ----------
    config : CalibrationConfig, optional
        The settings of every camera's job (each gets its own topics).
    workdir : str or os.PathLike, optional
        ``WORK``: each camera's job in ``WORK/<camera>/``, the rig in ``WORK/rig.json``;
        default: in memory.
    model_dir : str or os.PathLike, optional
    rig : Rig, optional
        Known camera-to-camera extrinsics (:func:`nbcalib.io.rig.read_rig`): one rig pose from
        every camera at once.
    rig_file : str, optional
        Where ``rig`` was read from, recorded in ``rig.json`` for ``nbcalib run WORK``.
    """

    def __init__(self, config=None, *, workdir=None, model_dir=None, rig=None, rig_file=None):
        self.config = config or CalibrationConfig()
        self.workdir = None if workdir is None else Path(workdir)
        self.model_dir = model_dir
        self.rig = rig
        self.rig_file = None if rig_file is None else str(rig_file)
        #: ``WORK/report/index.html`` once written.
        self.report: Path | None = None
        self.calibrators: dict = {}
        #: ``{camera: message}`` of the cameras whose own stages failed.
        self.failed: dict = {}
        #: With a rig: ``{camera: (metres, degrees)}``, how far each camera's own guess puts
        #: the rig from the start through the rig (the start's camera left out).
        self.start_disagreement: dict = {}

    def run(
        self,
        spec,
        cameras: Sequence[CameraSource],
        *,
        init: Start | None = None,
        no_matching: bool = False,
        until: str | None = None,
        redo_from: str | None = None,
        overwrite: bool = True,
        accept_failed_guess: bool = False,
        skip: dict[str, str] | None = None,
    ) -> RigResult:
        """Each camera's job, then (with a rig) the joint pose; writes ``WORK/rig.json``.

        ``spec``: the recording (:class:`InputSpec`, its bags read once for every camera), or
        each camera's inputs by name (``{name: ArrayInputs}``, :func:`nbcalib.calibrate`).
        With a rig, ``init`` is the rig's start (the first camera's ``T_camera_lidar``) when no
        camera's own guess succeeds, or, with ``no_matching``, the start itself (no camera is
        matched).
        """
        from nbcalib.pipeline import Calibrator
        from nbcalib.workdir import check_writable

        t0 = time.perf_counter()
        cameras = list(cameras)
        if (init is not None or no_matching) and self.rig is None:
            raise InputError("a start (run.init) for several cameras needs their rig (run.rig)")
        if no_matching and init is None:
            raise InputError("run.no_matching needs run.init: the rig's start")
        self._init = init
        self._check_rig(cameras)
        if no_matching:
            reason = "run.no_matching: the rig starts from run.init"
            skip = {"find-matches": reason, "initial-guess": reason, **(skip or {})}
        if self.workdir is not None:
            check_writable(self.workdir)
        joint = self.rig is not None and until in (None, "calibrate", "report")
        if isinstance(spec, InputSpec):
            recording = _Recording(spec, cameras, self._rig_cameras())
            self._inputs = {c.name: _CameraInputs(spec, c.name, recording) for c in cameras}
        else:
            self._inputs = dict(spec)
        for source in cameras:
            pre = self.config.preprocess
            if source.image_topic:
                pre = replace(
                    pre, image_topic=source.image_topic, camera_info_topic=source.camera_info_topic
                )
            work = None if self.workdir is None else self.workdir / source.name
            self.calibrators[source.name] = Calibrator(
                replace(self.config, preprocess=pre), workdir=work, model_dir=self.model_dir
            )
        names = ", ".join(f"{c.name} ({c.image_topic or 'arrays'})" for c in cameras)
        log.info("%d cameras: %s", len(cameras), names)

        def own_job(source):
            self.calibrators[source.name].run(
                self._inputs[source.name],
                until="initial-guess" if joint else until,
                redo_from=redo_from,
                overwrite=overwrite,
                accept_failed_guess=accept_failed_guess,
                skip=skip,
            )

        self.failed = self._each(cameras, own_job)
        if joint:
            self._joint(cameras, until=until, skip=skip)
        result = self._result(cameras, joint)
        result.failed = {n: m for n, m in self.failed.items() if result.cameras.get(n) is None}
        result.seconds = round(time.perf_counter() - t0, 3)
        if self.workdir is not None:
            job = self._write(spec, cameras, result)
            if until in (None, "report") and "report" not in (skip or {}):
                from nbcalib.report.rig import write_rig_report

                self.report = write_rig_report(self.workdir, job)
        if result.failed:
            where = "" if self.workdir is None else f"; the others' results are in {self.workdir}"
            failed = "; ".join(f"camera {n}: {m}" for n, m in result.failed.items())
            raise InputError(f"{failed}{where}")
        return result

    def _each(self, cameras, job) -> dict[str, str]:
        """``job(camera)`` for each camera, :data:`CAMERA_WORKERS` at a time.

        Each camera's log lines start with its name and its progress shows as step lines.
        Results are those of one camera after another: the cameras share no state but the
        recording, read once under a lock. A camera's :class:`InputError` (its guess failed,
        its images do not fit its camera) does not stop the others: returns
        ``{camera: message}`` of those that failed.
        """
        from nbcalib._threads import thread_map
        from nbcalib.progress import lines_only

        def run(source):
            with _camera_lines(source.name), lines_only():
                try:
                    job(source)
                except InputError as exc:
                    log.warning("camera %s: %s", source.name, exc)
                    return source.name, str(exc)
            return source.name, None

        with _camera_log_prefix():
            done = thread_map(run, cameras, workers=CAMERA_WORKERS)
        return {name: message for name, message in done if message is not None}

    # ------------------------------------------------------------------ the rig
    def _check_rig(self, cameras: Sequence[CameraSource]) -> None:
        """Every camera of the recording must be in the rig (by name or topic)."""
        if self.rig is None:
            return
        by_topic = {c.topic: c.name for c in self.rig.cameras if c.topic}
        missing = []
        self._rig_names = {}
        for source in cameras:
            name = source.name if source.name in self.rig.names() else None
            name = name or by_topic.get(source.image_topic)
            if name is None:
                missing.append(source.name)
            self._rig_names[source.name] = name
        if missing:
            raise InputError(
                f"the rig has no camera {', '.join(missing)} (its cameras: "
                f"{', '.join(self.rig.names())}); name them as the topics' namespaces or give "
                "their topics"
            )

    def _rig_cameras(self) -> dict:
        """``{camera: CameraModel}`` the rig file gives (for cameras without camera info)."""
        if self.rig is None:
            return {}
        models = {c.name: c.camera for c in self.rig.cameras}
        return {name: models[rig] for name, rig in self._rig_names.items() if rig is not None}

    def T_camera_ref(self, name: str, reference: str) -> np.ndarray:
        """``T_<name>_<reference>`` from the rig."""
        return self.rig.T(self._rig_names[name], self._rig_names[reference])

    def _joint(self, cameras, *, until, skip) -> None:
        """One rig pose: the reference camera refined with every camera's pairs, the rest follow."""
        ref = cameras[0].name
        starts = {}
        for source in cameras:
            start = self.calibrators[source.name]._start_pose(required=False)
            if start is not None:
                starts[source.name] = start
        if starts:
            name = min(starts, key=lambda n: self._guess_bound(n, starts[n]))
            T_start = invert_T(self.T_camera_ref(name, ref)) @ starts[name].T_camera_lidar
            start = Start.from_matrix(T_start, f"rig start ({name}'s {starts[name].source})")
            self._check_starts(starts, name, T_start, ref)
            log.info("rig: one pose from %d cameras, starting from %s's guess", len(cameras), name)
        elif self._init is not None:
            start = replace(self._init, source=f"rig start ({self._init.source})")
            log.info("rig: one pose from %d cameras, starting from %s", len(cameras), start.source)
        else:
            raise InputError(
                "no camera has an initial guess: the rig has no start (give the first camera's "
                "rough T_lidar_camera with run.init)"
            )
        reference = self.calibrators[ref]
        extra = []
        for source in cameras[1:]:
            T = self.T_camera_ref(source.name, ref)
            try:
                pairs = self.calibrators[source.name]._registration_pairs()
            except (InputError, TypeError, AttributeError):
                log.warning("rig: camera %s has no preprocessed pairs: left out", source.name)
                continue
            for pair in pairs:
                extra.append(
                    replace(pair, name=f"{source.name}/{pair.name}", T_camera_rig=T, classes=None)
                )
        reference.rig_pairs = extra
        with _camera_log_prefix(), _camera_lines(f"rig ({ref})"):
            reference.run(
                self._inputs[ref], init=start, redo_from="calibrate", until=until, skip=skip
            )
        if reference.refinement is None:
            return
        T_ref = reference._result_pose()

        def follow(source):  # the rig's pose through the rig, and the camera's own report
            if self.calibrators[source.name].pairs is None and self.workdir is None:
                return  # never preprocessed (its error is in self.failed)
            calibrator = self.calibrators[source.name]
            calibrator.adopt_result(
                self.T_camera_ref(source.name, ref) @ T_ref,
                f"rig ({ref}'s joint registration)",
                start=starts.get(source.name),
                converged=reference.refinement.converged,
            )
            calibrator.run(self._inputs[source.name], until=until, skip=skip)

        self.failed.update(self._each(cameras[1:], follow))
        for source in cameras:  # a camera the rig calibrated has not failed, whatever its guess
            if self.calibrators[source.name].result() is not None:
                self.failed.pop(source.name, None)

    def _check_starts(self, starts: dict, chosen: str, T_start, ref: str) -> None:
        """Each camera's own guess through the rig against the rig's start: a rig that fits.

        Logs how far each other guess puts the rig; warns for one beyond
        :data:`RIG_START_TOLERANCE_DEG`, and refuses the rig when every other camera's is.
        """
        self.start_disagreement = {}
        far = []
        for name, start in starts.items():
            if name == chosen:
                continue
            T = invert_T(self.T_camera_ref(name, ref)) @ start.T_camera_lidar
            dt, dr = pose_error(invert_T(T), invert_T(T_start))
            self.start_disagreement[name] = (float(dt), float(dr))
            log.info(
                "    rig: %s's own guess puts the rig %.2f cm, %.3f deg from %s's", name,
                100 * dt, dr, chosen,
            )  # fmt: skip
            if dr > RIG_START_TOLERANCE_DEG:
                far.append(f"{name} {dr:.1f} deg")
                log.warning(
                    "%s's own guess puts the rig %.1f deg from %s's through run.rig: the rig file "
                    "may not fit these cameras (other cameras, another order?)", name, dr, chosen,
                )  # fmt: skip
        if far and len(far) == len(starts) - 1:
            raise InputError(
                "the rig does not fit the cameras: through it every other camera's own guess "
                f"puts the rig far from {chosen}'s ({', '.join(far)}); check the rig file's "
                "cameras and their order, or calibrate without run.rig to see the transforms the "
                "data imply"
            )

    def _guess_bound(self, name: str, start: Start) -> float:
        """The rotation bound of camera ``name``'s guess, degrees (inf: not known).

        The rig starts from the camera whose guess is tightest (ties: the first camera).
        """
        calibrator = self.calibrators[name]
        guess = calibrator.guess
        if guess is not None and np.isfinite(guess.bound_deg):
            return float(guess.bound_deg)
        calib = calibrator._calib()
        record = None if calib is None else calib.record.initial_guess
        figures = None if record is None else record.stages.get(start.source)
        bound = None if figures is None else figures.bound_deg
        return float("inf") if bound is None else float(bound)

    def _result(self, cameras, joint: bool) -> RigResult:
        ref = cameras[0].name
        results = {c.name: self.calibrators[c.name].result() for c in cameras}
        out = RigResult(results, ref, joint=joint)
        T_ref = results[ref].T_camera_lidar if results[ref] is not None else None
        for source in cameras:
            result = results[source.name]
            if joint:
                T = self.T_camera_ref(source.name, ref)
                out.T_ref_camera[source.name] = np.eye(4) if source.name == ref else invert_T(T)
            elif result is not None and T_ref is not None:
                out.T_ref_camera[source.name] = T_ref @ invert_T(result.T_camera_lidar)
                if self.rig is not None:
                    given = invert_T(self.T_camera_ref(source.name, ref))
                    out.rig_errors[source.name] = pose_error(out.T_ref_camera[source.name], given)
        return out

    # ------------------------------------------------------------------ record
    def _write(self, spec: InputSpec, cameras, result: RigResult) -> dict:
        from nbcalib.io._files import write_text_atomic

        doc = {
            "cameras": [
                {
                    "name": c.name,
                    "workdir": c.name,
                    "image_topic": c.image_topic,
                    "camera_info_topic": c.camera_info_topic,
                    "T_lidar_camera": None
                    if result.cameras[c.name] is None
                    else [float(v) for v in result.cameras[c.name].values],
                    "T_ref_camera": None
                    if c.name not in result.T_ref_camera
                    else _values(result.T_ref_camera[c.name]),
                    "failed": result.failed.get(c.name),
                }
                for c in cameras
            ],
            "reference": result.reference,
            "joint": result.joint,
            "rig_file": self.rig_file,
            "rig_errors": {
                name: {"translation_m": float(dt), "rotation_deg": float(dr)}
                for name, (dt, dr) in result.rig_errors.items()
            },
            "start_disagreement": {
                name: {"translation_m": dt, "rotation_deg": dr}
                for name, (dt, dr) in self.start_disagreement.items()
            },
            "inputs": _inputs_record(spec),
            "seconds": result.seconds,
        }
        write_text_atomic(self.workdir / RIG_JOB, json.dumps(doc, indent=2) + "\n")
        return doc


_camera = threading.local()


@contextlib.contextmanager
def _camera_lines(name: str):
    """Log lines of this thread meanwhile start with ``name: ``."""
    _camera.name = name
    try:
        yield
    finally:
        _camera.name = None


@contextlib.contextmanager
def _camera_log_prefix():
    """While several cameras run at once, prefix each nbcalib log line with its camera's name."""
    previous = logging.getLogRecordFactory()

    def factory(*args, **kwargs):
        record = previous(*args, **kwargs)
        name = getattr(_camera, "name", None)
        if name and record.name.startswith("nbcalib"):
            record.msg = f"{name}: {record.msg}"
        return record

    logging.setLogRecordFactory(factory)
    try:
        yield
    finally:
        logging.setLogRecordFactory(previous)


def _inputs_record(spec) -> dict | None:
    """What ``rig.json`` records of the inputs, for ``nbcalib run WORK`` to continue with."""
    if isinstance(spec, InputSpec):
        return spec.to_dict()
    specs = dict(spec)
    if specs and all(isinstance(v, InputSpec) for v in specs.values()):
        return {"per_camera": {name: v.to_dict() for name, v in specs.items()}}
    return None  # arrays (nbcalib.calibrate) are not recorded


def _values(T) -> list[float]:
    return [float(v) for v in pose_to_xyz_quat(np.asarray(T, dtype=np.float64))]


def read_rig_job(workdir) -> dict | None:
    """``WORK/rig.json`` of a several-camera work directory, or None (a one-camera one)."""
    path = Path(workdir) / RIG_JOB
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read: {exc}", path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("cameras"), list):
        raise InputError("not an nbcalib rig job (no camera list)", path)
    for k, entry in enumerate(doc["cameras"]):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise InputError(f"cameras[{k}]: expected an object with a name", path)
    return doc
