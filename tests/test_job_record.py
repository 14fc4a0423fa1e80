"""The job's record (calib.json's nbcalib section), typed: a round trip loses nothing."""

from __future__ import annotations

import copy

from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE, MANUAL_STAGE
from nbcalib.io.job_record import (
    CalibrationRecord,
    CameraEntry,
    InitialGuessRecord,
    JobRecord,
    QualityRecord,
)

SECTION = {
    "camera": {"camera_model": "pinhole", "width": 640, "height": 480},
    "result_times": {FINAL_STAGE: "2026-12-05T10:00:00.000001+00:00"},
    "result_values": {FINAL_STAGE: [0.1, 0, 0, 0, 0, 0, 1]},
    "virtual_camera": {"camera": {}, "T_vcam_lidar": [[1.0]], "lidar_fov_deg": 70},
    "preprocess": {"pairs": {"a": {}}, "lidar_fov_deg": 70.0},
    "inputs": {"points": ["a.pcd"]},
    "config": {"refine": {"bins": 16}},
    "run": {
        "init": "0,0,0,0,0,0,1",
        "init_uncertainty": None,
        "manual": None,
        "prior": None,
        "no_matching": None,
        "no_report": True,
        "model_dir": None,
    },
    "made": {"preprocess": {"x": 1}},
    "seconds": {"preprocess": 1.5},
    "initial_guess": {
        AUTO_STAGE: {"matcher": "xfeat-lighterglue", "success": True},
        MANUAL_STAGE: {"inliers": 9},
        "failed": "imprecise",
        "someday": 1,
    },
    "calibration": {
        "start": AUTO_STAGE,
        "start_T_lidar_camera": [0, 0, 0, 0, 0, 0, 1],
        "start_uncertainty": None,  # not stated: written as null, kept so
        "converged": False,
        "nid": 1.25,
        "nid_history": [1.3, 1.25],
    },
    "quality": {"verdict": "ok", "assessed_T_lidar_camera": [0.1, 0, 0, 0, 0, 0, 1]},
    "unknown": {"kept": [1, 2]},
}


def test_a_round_trip_is_exact_and_typed():
    record = JobRecord.from_dict(copy.deepcopy(SECTION))
    assert record.to_dict() == SECTION
    assert record.camera == CameraEntry("pinhole", 640, 480) and record.camera.size == (640, 480)
    assert record.initial_guess.failed == "imprecise"
    assert record.initial_guess.matcher(AUTO_STAGE) == "xfeat-lighterglue"
    assert record.initial_guess.matcher(MANUAL_STAGE) is None
    assert record.initial_guess.other == {"someday": 1}
    cal = record.calibration
    assert (cal.start, cal.converged, cal.start_uncertainty) == (AUTO_STAGE, False, None)
    assert cal.figures["nid"] == 1.25 and "start" not in cal.figures
    assert record.quality.assessed_T_lidar_camera == [0.1, 0, 0, 0, 0, 0, 1]
    assert record.quality.figures == {"verdict": "ok"}
    assert record.other == {"unknown": {"kept": [1, 2]}}
    assert record.virtual_camera.lidar_fov_deg == 70 and record.virtual_camera.camera == {}
    assert record.preprocess.pairs == {"a": {}} and record.preprocess.lidar_fov_deg == 70.0
    assert record.run.given() == {"init": "0,0,0,0,0,0,1", "no_report": True}


def test_malformed_entries_read_as_absent_and_are_written_back():
    bad = {
        "camera": {"width": "640", "height": 0, "camera_model": 3},
        "calibration": {"start": 7, "converged": "yes", "start_T_lidar_camera": "x"},
        "quality": [1, 2],
        "made": "everything",
        "initial_guess": {AUTO_STAGE: "no", "failed": False},
    }
    record = JobRecord.from_dict(copy.deepcopy(bad))
    assert record.to_dict() == bad
    assert record.camera.size is None and record.camera.model is None
    assert record.calibration.start is None and record.calibration.converged is None
    assert record.quality is None and record.made is None  # not nbcalib-made
    assert record.initial_guess.stages == {} and record.initial_guess.failed is None
    # writing an entry replaces the malformed one
    record.made = {}
    record.quality = QualityRecord([1.0], {"verdict": "ok"})
    out = record.to_dict()
    assert out["made"] == {} and out["quality"] == {
        "assessed_T_lidar_camera": [1.0],
        "verdict": "ok",
    }


def test_empty_and_the_bookkeeping_helpers():
    record = JobRecord()
    assert record.to_dict() == {} and not record
    record.guess().failed = "no matches"
    record.set_made("preprocess", {"r": 1}, 2.5)
    record.stamp(FINAL_STAGE, "t", [1.0])
    assert record.to_dict() == {
        "initial_guess": {"failed": "no matches"},
        "made": {"preprocess": {"r": 1}},
        "seconds": {"preprocess": 2.5},
        "result_times": {FINAL_STAGE: "t"},
        "result_values": {FINAL_STAGE: [1.0]},
    }
    record.forget_made("preprocess")
    record.unstamp(FINAL_STAGE)
    record.guess().failed = None
    assert record.to_dict() == {
        "initial_guess": {},
        "made": {},
        "seconds": {"preprocess": 2.5},
        "result_times": {},
        "result_values": {},
    }
    assert CalibrationRecord(start="--init", figures={"nid": 1.0}).to_dict() == {
        "start": "--init",
        "nid": 1.0,
    }
    assert InitialGuessRecord().to_dict() == {}


def test_the_writers_spell_the_figures_once():
    from nbcalib.io.job_record import GuessFigures

    figures = GuessFigures.make(
        correspondences=10,
        ransac_inliers=8,
        inliers=9,
        rms_px=None,
        support=3.0,
        runner_up=1.0,
        runner_up_shared=0.5,
        bound_m=0.01,
        bound_deg=0.1,
        success=True,
        seed=0,
        confidence_weights=False,
        source="matches",
        matcher="xfeat-lighterglue",
    )
    assert (figures.success, figures.matcher, figures.inliers, figures.correspondences) == (
        True,
        "xfeat-lighterglue",
        9,
        10,
    )
    assert figures.to_dict()["rms_px"] is None  # a figure not measured is written as null
    record = InitialGuessRecord({AUTO_STAGE: figures})
    again = InitialGuessRecord.from_dict(record.to_dict())
    assert again.stages[AUTO_STAGE] == figures and again.matcher(AUTO_STAGE) == "xfeat-lighterglue"
    cal = CalibrationRecord.make(
        start=AUTO_STAGE,
        start_T_lidar_camera=[0, 0, 0, 0, 0, 0, 1],
        start_uncertainty=None,
        converged=True,
        optimizer="hybrid",
        cost="regional",
        bins=16,
        pyramid_levels=2,
        pairs=["a"],
        nid=1.0,
        nid_history=[1.2, 1.1, 1.0],
        iterations=5,
        evaluations=9,
        stopped="converged",
        seconds=1.5,
        change_from_start=(0.01, 0.2),
        trust_region=(0.5, 5.0),
        at_trust_boundary=False,
    )
    out = cal.to_dict()
    assert (
        out["nid_start"] == 1.2 and out["outer_iterations"] == 2 and "start_uncertainty" not in out
    )
    assert out["change_from_start"] == {"translation_m": 0.01, "rotation_deg": 0.2}
    assert CalibrationRecord.from_dict(out) == cal and cal.nid_history == [1.2, 1.1, 1.0]
