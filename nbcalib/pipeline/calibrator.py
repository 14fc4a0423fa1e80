"""The calibration job: its stages in the order of the paper's method, and its products.

:class:`Calibrator` is the orchestrator the command line, the demo and :func:`nbcalib.calibrate`
share (:mod:`nbcalib.pipeline`). Its matching and initial-guess stages are in
:mod:`nbcalib.pipeline.guess`, its records and start poses in :mod:`nbcalib.pipeline.records`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, replace

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.config import CalibrationConfig
from nbcalib.errors import InputError
from nbcalib.io.calib_json import FINAL_STAGE
from nbcalib.io.job_record import CalibrationRecord, PreprocessSummary, RunOptions
from nbcalib.pipeline.guess import GuessSteps
from nbcalib.pipeline.records import JobRecords, _detail, _uncertainty_record
from nbcalib.pipeline.store import make_store
from nbcalib.products import CalibrationResult, Start, as_stored_values
from nbcalib.resume import plan_stages
from nbcalib.wording import say
from nbcalib.workdir import WorkDir

__all__ = ["Calibrator", "make_report"]

log = logging.getLogger("nbcalib.pipeline")


class Calibrator(GuessSteps, JobRecords):
    """One calibration job (module docstring).

    Parameters
    ----------
    config : CalibrationConfig, optional
        Every setting (:mod:`nbcalib.config`); default ``CalibrationConfig()``.
    workdir : str or os.PathLike or WorkDir, optional
        Keep the products here and resume from them; default: in memory only.
    model_dir : str or os.PathLike, optional
        Exported matcher models (default: ``$NBCALIB_MODEL_DIR`` or the user cache).
    """

    def __init__(self, config: CalibrationConfig | None = None, *, workdir=None, model_dir=None):
        self.config = config or CalibrationConfig()
        #: Where the products go (:mod:`nbcalib.pipeline.store`): the work directory, or
        #: memory only.
        self.store = make_store(workdir)
        self.model_dir = model_dir
        self.camera = None
        self.virtual = None
        self.pairs = None
        self._registration: tuple | None = None  # (key, RegistrationPairs)
        self._budget = None  # MemoryBudget of the dense clouds (_memory)
        self.matches: dict = {}
        self.guess = None
        self.start: Start | None = None
        self.refinement = None
        self.quality = None
        self.report = None
        self.seconds: dict[str, float] = {}
        self.ran: list[str] = []
        self.skipped: list[str] = []
        self._made: dict[str, dict] = {}
        self._inputs_record = None
        self._origin = None  # LidarOrigin of preprocessing
        self._recording = None  # RecordingMatches of a many-frame job's matching
        self._inputs = self._manual = self._prior = self._given = self._fallback = None
        self._guess_failed = False
        self._stage_t0 = time.perf_counter()
        #: How the command line ran the job (``--init``...), recorded for ``nbcalib run WORKDIR``.
        self.run_options: RunOptions | None = None
        #: Pairs of the other cameras of a rig, refined with this camera's
        #: (:mod:`nbcalib.rig_pipeline`; each with its ``T_camera_rig``).
        self.rig_pairs: list = []
        self._adopted: tuple | None = None  # (T_camera_lidar, source): a result found elsewhere

    @property
    def work(self):
        """The job's :class:`~nbcalib.workdir.WorkDir`, None in memory.

        For callers that name its files; the Calibrator itself goes through :attr:`store`.
        """
        return self.store.work

    # ================================================================ the method
    def run(
        self,
        inputs=None,
        *,
        init: Start | None = None,
        init_is_fallback: bool = False,
        manual=None,
        prior: Start | None = None,
        only: str | None = None,
        until: str | None = None,
        redo_from: str | None = None,
        overwrite: bool = True,
        accept_failed_guess: bool = False,
        skip: dict[str, str] | None = None,
    ) -> CalibrationResult | None:
        """Run (or keep) each stage in turn; returns the result once fine registration has one.

        Parameters
        ----------
        inputs : InputSpec or ArrayInputs, optional
            What to preprocess; may be left out when the work directory holds a preprocessed
            job.
        init : Start, optional
            Start fine registration here instead of at an estimated guess (no matching), or,
            with ``init_is_fallback``, only when the automatic guess fails.
        manual : str or os.PathLike, optional
            Hand-picked correspondences (:mod:`nbcalib.initial_guess.manual`) instead of
            matching.
        prior : Start, optional
            A rough extrinsic that matching renders its views around.
        only : str, optional
            Run just this stage (:data:`STAGES`), its inputs taken from the work directory.
        until : str, optional
            Stop after this stage.
        redo_from : str, optional
            Recompute this stage and every later one, done or not.
        overwrite : bool, optional
            False: refuse (:class:`InputError`) to recompute a stage when the work directory
            holds a finished result.
        accept_failed_guess : bool, optional
            Keep an initial guess that failed its success test instead of stopping.
        skip : dict of str to str, optional
            Stages to leave out, with the reason to show (``{"report": "--no-report"}``).

        Raises
        ------
        InputError
            A user error, or an automatic guess that failed (and no fallback was given).
        """
        fallback = init if init_is_fallback else None
        given = None if init_is_fallback else init
        self._inputs = inputs
        self._manual, self._prior, self._given, self._fallback = manual, prior, given, fallback
        self._accept_failed_guess, self._guess_failed = accept_failed_guess, False
        skip = dict(skip or {})
        if given is not None:
            skip.setdefault("find-matches", f"starting from {given.source}")
            skip.setdefault("initial-guess", f"starting from {given.source}")
        elif manual is not None:
            skip.setdefault("find-matches", "run.manual")
        self.store.check_writable()
        with self.store.lock():  # one job at a time in a work directory
            plan = plan_stages(
                self, only=only, until=until, redo_from=redo_from, overwrite=overwrite, skip=skip
            )
            self._run_plan(plan, only, fallback)
        return self.result()

    def _run_plan(self, plan, only, fallback) -> None:
        """Run the planned stages in turn (the work directory locked by :meth:`run`)."""
        for k, (stage, runs, reason) in enumerate(plan):
            header = f"[{k + 1}/{len(plan)}] {stage}"
            if not runs:
                # a stage this job already ran, or one the caller stopped before, needs no line
                said = stage in self.ran or reason.startswith("run.until")
                log.log(logging.DEBUG if said else logging.INFO, "%s: skipped (%s)", header, reason)
                self.skipped.append(stage)
                continue
            if self._guess_failed and stage == "initial-guess":
                continue  # matching found nothing: the fallback start takes over
            if only is None:  # a stage command needs no stage header
                log.info("%s%s", header, f" ({reason})" if reason else "")
            t0 = self._stage_t0 = time.perf_counter()
            try:
                self._run_stage(stage)
            except InputError as exc:
                if stage not in ("find-matches", "initial-guess") or fallback is None:
                    raise
                self._use_fallback(exc)
            self.seconds[stage] = round(time.perf_counter() - t0, 3)
            self.ran.append(stage)
            if only is None:
                log.info("    %s done in %.1f s", stage, self.seconds[stage])

    def _run_stage(self, stage: str) -> None:
        if stage == "preprocess":
            # III-C: scans -> dense cloud per pair; equalised intensities and image;
            # III-D: one virtual camera renders every cloud: LiDAR image + index map
            try:
                self._preprocess()
                self._write_preprocess_record()
                self.store.commit()  # a rerun replaces the job it reran only now
            except BaseException:
                self.store.abort()
                raise
        elif stage == "find-matches":
            # III-D: camera image x camera-shaped LiDAR views -> 2D-3D correspondences
            self._match()
        elif stage == "initial-guess":
            # III-D: rotation-only RANSAC, then Cauchy-robust LM -> initial T_camera_lidar
            self._initial_guess()
        elif stage == "calibrate":
            # III-E: hidden-point removal + NID minimisation over all pairs
            self._refine()
        else:
            # nbcalib: NID curves, uncertainty, verdict (and the HTML report)
            self._assess()

    # ================================================================ the steps
    def _preprocess(self) -> None:
        from nbcalib.preprocess.origin import lidar_origin
        from nbcalib.preprocess.prepare import check_pairs

        if self._inputs is None or getattr(self._inputs, "empty", False):
            raise InputError(
                "nothing to preprocess: give INPUT... WORKDIR (or inputs.points FILE "
                "inputs.image FILE)",
                self.store.path,
            )
        pair_inputs, camera, data_path = self._inputs.gather(self.config.preprocess)
        check_pairs(pair_inputs, camera)
        self.store.prepare()
        self.camera, self._data_path, self._topics = camera, data_path, pair_inputs[0].topics
        self._inputs_record = self._inputs.to_dict()
        # where the LiDAR sits in the clouds' frame: views and the LiDAR image are seen from there
        self._origin = lidar_origin(pair_inputs, self.config.preprocess)
        for pair in pair_inputs:  # the scans it read are read again by their pair
            getattr(pair.scans, "release", lambda: None)()
        _detail(self._origin.describe())
        self._forget_after("preprocess")
        self.pairs = self._prepare_and_write(pair_inputs)

    def _prepare_and_write(self, pending: list) -> list:
        """Each pair's dense cloud, rendered, written; the pairs as the job goes on with them.

        One pair after another on every core, each let go once written (its cloud then read
        from the work directory when needed: :meth:`~nbcalib.pipeline.store.WorkDirStore.
        write_pair`), so that preprocessing holds a pair per core, not the recording. The
        virtual camera is chosen from the first pair; the others wait for it.
        """
        import threading

        from nbcalib.preprocess.prepare import (
            choose_virtual_camera,
            describe_virtual_camera,
            prepare_pair,
            render_pair,
        )

        one = len(pending) == 1
        chosen = threading.Event()
        self._memory(len(pending))

        def prepare(k: int):  # pairs on every core (nbcalib._threads); a bar only for one pair
            pair, pending[k] = pending[k], None  # let go of the inputs once prepared
            log.info("    %s", pair.name)
            try:
                data = prepare_pair(pair, self.config.preprocess, log=_detail, progress=one)
                if k == 0:
                    self.virtual = choose_virtual_camera(data, self._origin.xyz)
                    _detail(describe_virtual_camera(self.virtual))
            finally:
                getattr(pair.scans, "release", lambda: None)()
                del pair
                if k == 0:
                    chosen.set()
            chosen.wait()
            if self.virtual is None:  # the first pair failed: its error is raised first
                raise InputError("the first pair could not be prepared")
            return self.store.write_pair(render_pair(self.virtual, data), self._memory())

        self.virtual = None
        return thread_map(prepare, range(len(pending)))

    def _write_preprocess_record(self) -> None:
        """calib.json of the new work directory: the camera, the pairs, the virtual camera."""
        from nbcalib.workdir import make_calib, set_virtual_camera

        topics = self._topics
        calib = make_calib(
            self.camera,
            [p.name for p in self.pairs],
            data_path=self._data_path,
            camera_info_topic=topics.get("camera_info_topic", "N/A"),
            image_topic=topics.get("image_topic", "N/A"),
            points_topic=topics.get("points_topic", "N/A"),
            intensity_channel=self.config.preprocess.intensity_channel,
        )
        set_virtual_camera(calib, self.virtual)
        calib.record.preprocess = PreprocessSummary(
            {p.name: p.summary for p in self.pairs},
            self.virtual.fov_deg,
            lidar_origin=asdict(self._origin),
        )
        calib.record.inputs = self._inputs_record
        self._remember("preprocess", calib)

    def _refine(self) -> None:
        from nbcalib.registration.refine import refine

        cfg = self.config.refine
        start = self._start_pose()
        pairs = self._registration_pairs() + list(self.rig_pairs)
        log.info(
            "    calibrating %d pair(s), %d points, %s, start: %s",
            len(pairs),
            sum(len(p) for p in pairs),
            cfg.optimizer,
            start.source,
        )

        levels: list[int] = []

        def progress(i, step):
            if step.level not in levels:  # a new level's NID is not comparable with the last
                levels.append(step.level)
                what = "full resolution" if step.level == 0 else f"1/{2**step.level} resolution"
                _detail(f"pyramid level {step.level} ({what}):")
            _detail(
                f"outer {i + 1} (level {step.level}): NID {step.nid_start:.5f} -> {step.nid:.5f}"
                f"  {step.iterations} it, {step.evaluations} evals, moved "
                f"{100 * step.translation_change:.2f} cm {step.rotation_change_deg:.3f} deg, "
                f"{sum(step.visible_points)} visible points, {step.seconds:.1f} s"
            )

        t0 = time.perf_counter()
        try:
            self.refinement = refine(pairs, start.T_camera_lidar, cfg, progress=progress)
        except InputError as exc:
            raise InputError(f"{exc} (start: {start.source})", self.store.calib_path) from None
        self.start = start
        self._forget_after("calibrate")
        calib = self._calib()
        result = self.refinement
        if calib is not None:
            from nbcalib.transforms import invert_T, pose_error

            dt, dr = pose_error(invert_T(result.T_camera_lidar), invert_T(start.T_camera_lidar))
            calib.record.calibration = CalibrationRecord.make(
                start=start.source,
                start_T_lidar_camera=start.values,
                start_uncertainty=_uncertainty_record(start.uncertainty),
                converged=result.converged,
                optimizer=cfg.optimizer,
                cost=cfg.cost,
                bins=cfg.bins,
                pyramid_levels=cfg.pyramid_levels,
                pairs=[p.name for p in pairs],
                nid=result.nid,
                nid_history=[result.history[0].nid_start, *(h.nid for h in result.history)],
                iterations=result.iterations,
                evaluations=result.evaluations,
                stopped=result.stopped,
                seconds=round(time.perf_counter() - t0, 3),
                change_from_start=(dt, dr),
                trust_region=(cfg.trust_translation, cfg.trust_rotation_deg),
                at_trust_boundary=result.at_trust_boundary,
            )
            if result.intrinsics is not None:
                calib.record.calibration.figures["intrinsics"] = result.intrinsics.to_record()
        if result.intrinsics is not None:
            log.info("    %s", result.intrinsics.summary())
        if result.at_trust_boundary:
            self._refine_failed(calib, start, result)
        if calib is not None:
            calib.set_T_camera_lidar(FINAL_STAGE, result.T_camera_lidar)
        self._remember("calibrate", calib)

    def adopt_result(
        self,
        T_camera_lidar,
        source: str,
        *,
        start: Start | None = None,
        converged: bool | None = None,
    ) -> None:
        """Take a result found elsewhere as this job's calibration (a rig's joint pose).

        Recorded as the calibrate stage's product: ``calib.json`` gets it as
        ``T_lidar_camera`` with a calibration record naming ``source`` (and this camera's own
        ``start``, which the report judges the move from); the report is then made as for a
        result of this job's own.
        """
        self._stage_t0 = time.perf_counter()
        T = np.asarray(T_camera_lidar, dtype=np.float64)
        self._adopted = (as_stored_values(T), source)
        self.refinement = None
        if start is not None:
            self.start = start
        self._forget_after("calibrate")
        calib = self._calib()
        if calib is not None:
            from nbcalib.transforms import invert_T, pose_error

            record = {}
            if start is not None:
                record = {
                    "start": start.source,
                    "start_T_lidar_camera": start.values,
                    "start_uncertainty": _uncertainty_record(start.uncertainty),
                    "change_from_start": pose_error(invert_T(T), invert_T(start.T_camera_lidar)),
                }
            calib.record.calibration = CalibrationRecord.adopted(
                source, converged=converged, **record
            )
            calib.set_T_camera_lidar(FINAL_STAGE, T)
        self._remember("calibrate", calib)

    def _refine_failed(self, calib, start: Start, result) -> None:
        """Fine registration ended on its trust region's edge: no result; say so and stop.

        Its optimum lies beyond the region (the start was too far off, or the cost has no
        minimum near it), so the pose it stopped at is no answer. ``calib.json`` keeps the
        attempt under ``nbcalib.calibration`` (``failed``, ``attempted_T_lidar_camera``) and
        loses any earlier result, so nothing stale looks finished; then
        :class:`~nbcalib.errors.RegistrationFailed` (exit status 3 on the command line).
        """
        from nbcalib.errors import RegistrationFailed

        dt, dr = result.moved
        message = say(  # kept in calib.json: spelt for the front end, as the error is
            f"fine registration ran to the edge of its trust region ({100 * dt:.1f} cm / "
            f"{dr:.2f} deg from the start; the region is {100 * result.trust_translation:g} cm / "
            f"{result.trust_rotation_deg:g} deg): its optimum lies beyond, so it has no result. "
            f"The start ({start.source}) is too far off, or the data hold no minimum near it: "
            "start closer (run.init, or manual picks: initial-guess run.manual) or widen the "
            "region (refine.trust_translation, refine.trust_rotation_deg)"
        )
        self.refinement = None
        if calib is not None:
            calib.results.pop(FINAL_STAGE, None)
            calib.record.unstamp(FINAL_STAGE)
            record = calib.record.calibration
            record.failed = message
            record.attempted_T_lidar_camera = as_stored_values(result.T_camera_lidar)
            calib.record.forget_made("calibrate")
            self._made.pop("calibrate", None)
            self.store.write_calib(calib)
        raise RegistrationFailed(message, result)

    def _assess(self) -> None:
        from nbcalib.report.quality import assess

        T, start = self._result_pose(), self._report_start()
        pairs = self._registration_pairs()
        camera = self._result_camera()
        if pairs and camera != pairs[0].camera:  # judged with the camera it refined
            pairs = [replace(p, camera=camera) for p in pairs]
        converged = None if self.refinement is None else self.refinement.converged
        calib = self._calib()
        if converged is None and calib is not None:
            info = calib.record.calibration
            converged = None if info is None else info.converged
        self.quality = assess(
            pairs,
            T,
            T_init=None if start is None else start.T_camera_lidar,
            config=self.config.refine,
            converged=converged,
            assess_config=self.config.assess,
            start_uncertainty=None if start is None else start.uncertainty,
            progress=True,
        )
        _detail(f"verdict: {self.quality.verdict}")
        check = self.quality.intrinsics_check
        if check is not None and check.get("checked"):
            (_detail if check.get("agrees") else log.warning)(check["note"])
        names = [p.name for p in pairs]
        loaded = [p for p in self._pairs() if p.name in names]
        self.report = self.store.write_report(  # none in memory: the quality is the product
            self.quality,
            loaded,
            pairs,
            T,
            None if start is None else start.T_camera_lidar,
            self.config.refine,
            None if start is None else start.source,
            progress=True,
        )
        calib = self._calib()
        info = None if calib is None else calib.record.calibration
        if start is not None and info is not None:  # the uncertainty the report judged by
            info.start_uncertainty = _uncertainty_record(start.uncertainty)
        self._remember("report", calib)

    # ================================================================ products
    def result(self) -> CalibrationResult | None:
        """The job's result so far (None before fine registration has run or been loaded)."""
        adopted = self._adopted is not None
        if self.refinement is None and not adopted and not self._has(FINAL_STAGE):
            return None
        start = self._start_pose(required=False)
        values = self.result_values if self.refinement is not None or adopted else None
        values = values or self._calib().results[FINAL_STAGE]
        return CalibrationResult(
            values=tuple(values),
            T_camera_lidar=self._result_pose(),
            T_init=None if start is None else start.T_camera_lidar,
            init_source="" if start is None else start.source,
            initial_guess=self.guess,
            pairs=list(self.pairs or []),
            refinement=self.refinement,
            camera=self._result_camera(),
            quality=self.quality,
            matches=list(self.matches.values()),
            virtual_camera=self.virtual,
            workdir=self.store.path,
            seconds=dict(self.seconds),
        )

    @property
    def result_values(self) -> list[float]:
        """Fine registration's result as ``calib.json`` holds it: ``T_lidar_camera`` 7 values."""
        if self.refinement is None and self._adopted is not None:
            return list(self._adopted[0])
        return as_stored_values(self.refinement.T_camera_lidar)

    @property
    def T_result(self) -> np.ndarray:
        """Fine registration's ``T_camera_lidar`` from its stored values.

        These are the bits a stage run on its own reads back from ``calib.json``.
        """
        return Start.from_values(self.result_values, FINAL_STAGE).T_camera_lidar

    def _calib(self):
        return self.store.read_calib()

    def _has(self, stage: str) -> bool:
        calib = self._calib()
        return calib is not None and calib.has_result(stage)

    def _result_camera(self):
        """The camera the result goes with: the refined one, when the job refined it."""
        if self.refinement is not None and self.refinement.camera is not None:
            return self.refinement.camera
        calib = self._calib()
        if calib is not None and self._has(FINAL_STAGE):
            return calib.result_camera()
        return self._camera()

    def _camera(self):
        if self.camera is None:
            self.camera = self.store.require_preprocessed().camera_model()
        return self.camera

    def _virtual(self):
        calib = self._calib() if self.virtual is None else None
        if calib is not None:
            from nbcalib.workdir import get_virtual_camera

            self.virtual = get_virtual_camera(calib)
        return self.virtual

    def _pairs(self) -> list:
        if self.pairs is None:
            self.pairs = self.store.load_pairs(budget=self._memory())
            self._memory(len(self.pairs))
        return self.pairs

    def _memory(self, n_pairs: int = 0):
        """The job's :class:`~nbcalib.clouds.MemoryBudget` for its dense clouds (one per job).

        A job of ``n_pairs`` >= :data:`~nbcalib._malloc.MANY_PAIRS` also has the arrays it
        frees go back to the system (:mod:`nbcalib._malloc`).
        """
        from nbcalib._malloc import MANY_PAIRS, return_freed_arrays
        from nbcalib.clouds import MemoryBudget

        if n_pairs >= MANY_PAIRS:
            return_freed_arrays()

        if self._budget is None:
            mb = self.config.refine.cloud_memory_mb
            self._budget = MemoryBudget(None if mb is None else int(mb * 2**20))
        return self._budget

    def _registration_pairs(self) -> list:
        """The pairs fine registration and the report work on, made once per loaded data.

        Calibrate and report of one job share them, so the report reuses the KD-trees,
        orientation classes and point subsets fine registration computed (``nbcalib run``).
        """
        from nbcalib.registration.refine import RegistrationPair

        pairs = self._pairs()
        if self.config.refine.max_pairs is not None:
            pairs = pairs[: self.config.refine.max_pairs]
        camera = self._camera()
        key = (camera, *pairs)  # the objects themselves: an id may be reused once freed
        cached = self._registration
        if (
            cached is None
            or len(cached[0]) != len(key)
            or any(a is not b for a, b in zip(cached[0], key))
        ):
            made = [RegistrationPair(camera, p.image, name=p.name, cloud=p.cloud) for p in pairs]
            self._registration = (key, made)
        return self._registration[1]

    def _result_pose(self) -> np.ndarray:
        if self.refinement is not None or self._adopted is not None:
            return self.T_result
        calib = self._calib()
        if calib is None or not calib.has_result(FINAL_STAGE):
            raise InputError(
                "no calibration result (results.T_lidar_camera): run nbcalib calibrate first",
                self.store.calib_path,
            )
        return calib.get_T_camera_lidar(FINAL_STAGE)


def make_report(workdir, *, assess_config=None):
    """Judge the calibration of a work directory and write its HTML report (``nbcalib report``).

    The assessment stage of :class:`nbcalib.pipeline.Calibrator`, as ``nbcalib report`` runs
    it: the settings the work directory recorded, with ``assess_config`` (default:
    ``AssessConfig()``) as the assessment's own.

    Parameters
    ----------
    workdir : str or PathLike
        A work directory with ``calib.json`` holding ``results.T_lidar_camera`` (written by
        ``nbcalib calibrate``).
    assess_config : AssessConfig, optional
        Scale and verdict limits of :func:`~nbcalib.report.quality.assess`.

    Returns
    -------
    Report

    Raises
    ------
    InputError
        No work directory, no ``calib.json``, no calibration result, or a missing or corrupt
        pair file; the message names the file and the command to run first.
    """
    from dataclasses import replace

    from nbcalib.config import config_from_record
    from nbcalib.report.config import AssessConfig

    work = WorkDir(workdir)
    if work.path.is_dir() and not work.calib_path.is_file():
        raise InputError("no calib.json here: run nbcalib preprocess first", work.path)
    config = config_from_record(work.require_preprocessed().record.config)
    config = replace(config, assess=assess_config or AssessConfig())
    calibrator = Calibrator(config, workdir=work)
    calibrator.run(only="report")
    return calibrator.report
