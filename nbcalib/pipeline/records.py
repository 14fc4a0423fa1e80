"""What made each product of a job, and where its fine registration starts.

:class:`JobRecords` is the part of :class:`~nbcalib.pipeline.Calibrator` that keeps a job's
records: each stage's *recipe* (the config sections and inputs its product depends on), written
to ``calib.json`` beside the product so that a later run keeps what still holds
(:mod:`nbcalib.resume`) and forgets what a recomputed stage made stale; and the precedence of
the poses fine registration and the report start from.
"""

from __future__ import annotations

import json
import logging
import time

import numpy as np

from nbcalib.config import config_to_dict
from nbcalib.errors import InputError
from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE
from nbcalib.io.job_record import CalibrationRecord, RunOptions
from nbcalib.products import Start, as_stored_values
from nbcalib.resume import STAGES

__all__ = ["JobRecords"]

log = logging.getLogger("nbcalib.pipeline")


class JobRecords:
    """Records and start poses of a :class:`~nbcalib.pipeline.Calibrator` (module docstring)."""

    def _report_start(self) -> Start | None:
        """The start the report judges the move from, with the uncertainty stated for it now.

        The start of the result (:meth:`_start_pose`); when this run was given that same pose
        (as the start or the fallback), the uncertainty stated with it now replaces the
        recorded one, so that restating it redoes the report, not fine registration.
        """
        from dataclasses import replace

        start = self._start_pose(required=False)
        if start is None:
            return None
        for mine in (self._given, self._fallback):
            if mine is not None and tuple(mine.values) == tuple(start.values):
                return replace(start, uncertainty=mine.uncertainty)
        return start

    def _start_pose(self, *, required: bool = True) -> Start | None:
        """Where fine registration starts (or started), in this order of precedence.

        A pose given as the start; this run's guess; the fallback pose when the guess failed;
        the start a finished result records; the latest guess in ``calib.json``.
        """
        if self._given is not None:
            return self._given
        if self.start is not None:
            return self.start
        if self._guess_failed and self._fallback is not None:
            return self._fallback
        calib = self._calib()
        if calib is not None:
            info = calib.record.calibration or CalibrationRecord()
            stored = info.start_T_lidar_camera
            if calib.has_result(FINAL_STAGE) and stored is not None and len(stored) == 7:
                return Start.from_values(
                    stored,
                    info.start if info.start is not None else "start",
                    _uncertainty_from_record(info.start_uncertainty),
                )
            stage = calib.latest_initial_stage()
            if stage is not None:  # its seven stored numbers: a resumed job starts to the bit
                calib.get_T_camera_lidar(stage)  # (checked)
                return Start.from_values(calib.results[stage], stage)
        if self._fallback is not None:
            return self._fallback
        if not required:
            return None
        raise InputError(
            "no initial guess in calib.json: run nbcalib initial-guess first, or pass run.init",
            self.store.calib_path,
        )

    # ================================================================ records
    def recipe(self, stage: str) -> dict:
        """What ``stage``'s product depends on: the config sections and inputs it uses."""
        c = config_to_dict(self.config)
        if stage == "preprocess":
            inputs = None if self._inputs is None else self._inputs.to_dict()
            return _plain({"inputs": inputs, "preprocess": c["preprocess"]})
        if stage == "find-matches":
            from nbcalib.matching.match import resolve_matcher

            return _plain(
                {
                    "matching": c["matching"],
                    "matcher": resolve_matcher(self.config.matching.matcher, self.model_dir),
                    "ransac_threshold": self.config.initial_guess.ransac_threshold,
                    "seed": c["seed"],
                    "prior": None if self._prior is None else self._prior.values,
                }
            )
        if stage == "initial-guess":
            manual = None if self._manual is None else str(self._manual)
            return _plain(
                {"initial_guess": c["initial_guess"], "seed": c["seed"], "manual": manual}
            )
        if stage == "calibrate":
            given = None if self._given is None else self._given.values
            recipe = {"refine": c["refine"], "start": given}
            if self.rig_pairs:  # the other cameras' pairs and where the rig puts them
                recipe["rig_pairs"] = {
                    p.name: as_stored_values(p.T_camera_rig) for p in self.rig_pairs
                }
            if self._adopted is not None:
                recipe["adopted"] = {"T_lidar_camera": self._adopted[0], "from": self._adopted[1]}
            return _plain(recipe)
        start = self._report_start()
        stated = None if start is None else start.uncertainty
        return _plain({"assess": c["assess"], "refine": c["refine"], "start_uncertainty": stated})

    def _remember(self, stage: str, calib=None) -> None:
        """Record what made ``stage``'s product (in memory, and in calib.json when given)."""
        recipe = self.recipe(stage)
        self._made[stage] = recipe
        if calib is None:
            return
        record = calib.record
        record.set_made(stage, recipe, round(time.perf_counter() - self._stage_t0, 3))
        record.config = config_to_dict(self.config)
        if self._inputs_record is not None:
            record.inputs = self._inputs_record
        if self.run_options is not None:
            record.run = RunOptions.from_dict(_plain(self.run_options.to_dict()))
        self.store.write_calib(calib)
        self.store.write_config(self.config, {"inputs": record.inputs})

    def _forget_after(self, stage: str) -> None:
        """A stage ran: what later stages made from its old product no longer holds.

        Their records go, and in the work directory their results too (an automatic guess
        from old matches, a result from an old guess), with the report and exports: nothing
        stale is left that looks finished.
        """
        later = STAGES[STAGES.index(stage) + 1 :]
        for name in later:
            self._made.pop(name, None)
        calib = self._calib() if self.store.is_complete() else None
        if calib is None or stage == "report":
            return
        for name in later:
            calib.record.forget_made(name)
        stale = {"find-matches": (AUTO_STAGE, FINAL_STAGE), "initial-guess": (FINAL_STAGE,)}
        for result in stale.get(stage, ()):
            calib.results.pop(result, None)
            calib.record.unstamp(result)
        if stage in ("find-matches", "initial-guess"):
            if calib.record.initial_guess is not None:
                calib.record.initial_guess.failed = None
            calib.record.calibration = None
        calib.record.quality = None
        self.store.write_calib(calib)
        # after the record that no longer has them: a full disk leaves both as they were
        self.store.remove_derived()


def _plain(value):
    """JSON-comparable copy (tuples to lists, paths to str)."""
    return json.loads(json.dumps(value, default=str))


def _detail(line: str) -> None:
    log.info("    %s", line)


def _rounded(value: float, digits: int) -> float | None:
    """``value`` rounded for calib.json, None when not finite (JSON has no inf)."""
    return round(float(value), digits) if np.isfinite(value) else None


def _uncertainty_record(uncertainty) -> dict | None:
    """A start's stated uncertainty as ``calib.json`` records it (None: not stated)."""
    if uncertainty is None:
        return None
    return {"translation_m": float(uncertainty[0]), "rotation_deg": float(uncertainty[1])}


def _uncertainty_from_record(record) -> tuple[float, float] | None:
    """The stated uncertainty a record holds, or None (not stated, or not readable)."""
    from nbcalib.products import check_uncertainty

    if not isinstance(record, dict):
        return None
    try:
        return check_uncertainty((record.get("translation_m"), record.get("rotation_deg")))
    except ValueError:
        return None
