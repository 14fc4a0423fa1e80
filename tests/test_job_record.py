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
    "run": {"model_dir": None, "init": "0,0,0,0,0,0,1"},
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
