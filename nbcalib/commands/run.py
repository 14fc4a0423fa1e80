"""``nbcalib run INPUT... WORKDIR``: every stage of the method over one work directory.

A thin shell over :class:`nbcalib.pipeline.Calibrator`: the command line (and ``--config``)
becomes a :class:`~nbcalib.config.CalibrationConfig`, the inputs an
:class:`~nbcalib.preprocess.inputs.InputSpec`, and the calibrator runs or keeps each stage
(:mod:`nbcalib.resume` decides per product). Settings come from three places, the first that
has a value wins: the command line, the config file, the config the work directory recorded
(when continuing a job), the defaults.
"""

from __future__ import annotations

import argparse
import logging

from nbcalib.commands._args import (
    add_input_arguments,
    add_verbosity_arguments,
    check_model_dir,
    input_spec,
    parse_pose,
    parse_start,
    split_workdir,
)
from nbcalib.commands._options import (
    ASSESS,
    INITIAL_GUESS,
    MATCHING,
    PREPROCESS,
    REFINE,
    RUN_OPTIONS,
    add_options,
    build_config,
)
from nbcalib.errors import InputError

log = logging.getLogger("nbcalib.run")

DESCRIPTION = """\
Calibrate from recordings in one command: preprocess -> find-matches -> initial-guess ->
calibrate -> report, over one work directory. Takes every input form and option of
'nbcalib preprocess' and the options of the later stages (see each stage's --help).

Resumes: stages whose products WORKDIR already holds, made with the same settings, are skipped
(it says which); 'nbcalib run WORKDIR' continues a job with the inputs and settings it was
started with. A finished result is not overwritten without --force (every stage) or --from
STAGE.

Several cameras (a bag with several image topics, or --camera-topics): each camera is
calibrated in WORKDIR/<camera>/ (a one-camera work directory), the recording read and each
dense cloud made once for all; WORKDIR/rig.json lists the cameras, their results and the
camera-to-camera transforms the results imply. With --rig FILE (known camera-to-camera
extrinsics) one rig pose is refined from every camera's pairs at once (docs/multi_camera.md).

The initial guess is automatic (keypoint matches); --manual FILE uses hand-picked
correspondences instead; --init POSE is the fallback when the automatic guess fails (or the start
itself with --no-matching). --config FILE (TOML or YAML) supplies settings; those used are
written to WORKDIR/nbcalib_config.yaml, which --config reads back."""

EPILOG = """\
examples:
  nbcalib run rosbag2_2023_03_09-13_42_46 work/                 # ROS 2 bag, camera from CameraInfo
  nbcalib run run1.bag run2.bag work/ --dynamic --matcher sift
  nbcalib run --points lidar.pcd --image image.png work/ --camera camera.yaml
  nbcalib run scans/*.bin image.png work/ --camera camera.yaml --init -0.1,0,0,0.5,-0.5,0.5,0.5
  nbcalib run --frames kitti_raw/ work/ --camera calib.json --every 4 --neighbors 10
  nbcalib run scans/*.bin image.png work/ --camera camera.yaml --no-matching \\
      --init -0.1,0,0,0.5,-0.5,0.5,0.5 --init-uncertainty 0.05 2 --trust-translation 0.2
  nbcalib run work/                                              # continue an interrupted job
  nbcalib run work/ --from calibrate --optimizer nelder_mead     # redo the last stages
  nbcalib run --config job.toml data.bag work/
  nbcalib run ring.bag work/                   # every camera of a bag with several image topics
  nbcalib run ring.bag work/ --camera-topics /front/image,/left/image --rig camchain.yaml
  nbcalib run scan.pcd work/ --camera-image front front.png front.yaml \
      --camera-image left left.png left.yaml
  nbcalib evaluate work/ --ground-truth ground_truth.json

job.toml (tables are the config's sections; keys their settings, or option names):
  seed = 3
  [preprocess]
  voxel_size = 0.01
  [matching]
  matcher = "sift"
  [refine]
  optimizer = "nelder_mead"
"""

#: Inputs a config file may give by option name (``frames = "kitti/"``), as on the command line.
FILE_INPUT_KEYS = (
    "camera",
    "camera_model",
    "intrinsics",
    "distortion",
    "image",
    "frames",
    "images",
    "image_times",
    "scan_times",
    "every",
    "pair_count",
)


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``run``: its own options, then those of every stage."""
    from nbcalib.resume import STAGES

    p = subparsers.add_parser(
        "run",
        help="every stage: preprocess, find-matches, initial-guess, calibrate, report",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    add_input_arguments(p)
    own = p.add_argument_group("run")
    for option in RUN_OPTIONS:
        kwargs = {"default": argparse.SUPPRESS, "help": option.help}
        if option.takes_value:
            kwargs["metavar"] = option.metavar
            if option.flag in ("--from", "--until"):
                kwargs["choices"] = STAGES
            if isinstance(option.metavar, tuple):
                kwargs["nargs"] = len(option.metavar)
            if option.flag == "--camera-image":
                kwargs["action"] = "append"
        else:
            kwargs["action"] = "store_true"
        dest = "from_stage" if option.flag == "--from" else option.dest
        own.add_argument(option.flag, dest=dest, **kwargs)
    add_verbosity_arguments(own)
    add_options(p.add_argument_group("preprocess (nbcalib preprocess --help)"), PREPROCESS)
    add_options(p.add_argument_group("find-matches (nbcalib find-matches --help)"), MATCHING)
    add_options(p.add_argument_group("initial-guess (nbcalib initial-guess --help)"), INITIAL_GUESS)
    add_options(p.add_argument_group("calibrate (nbcalib calibrate --help)"), REFINE)
    add_options(p.add_argument_group("report (nbcalib report --help)"), ASSESS)
    return p


def _file(args) -> tuple[dict, dict, str | None]:
    """Settings and other options of ``--config`` (empty without one)."""
    path = getattr(args, "config", None)
    if path is None:
        return {}, {}, None
    from nbcalib.commands._options import file_settings
    from nbcalib.config import read_config_file

    settings, other = file_settings(read_config_file(path), path)
    return settings, other, path


def run(args: argparse.Namespace) -> int:
    """Run every stage over WORKDIR; returns the exit status."""
    from nbcalib import warmup
    from nbcalib.config import CalibrationConfig, config_from_record
    from nbcalib.io.job_record import RunOptions
    from nbcalib.pipeline import Calibrator
    from nbcalib.workdir import WorkDir

    file_values, file_other, file_path = _file(args)
    for key in FILE_INPUT_KEYS:  # the config file's inputs, unless given on the command line
        if key in file_other and getattr(args, key, None) is None:
            setattr(args, key, file_other[key])
    inputs, points, images, workdir = split_workdir(
        getattr(args, "inputs", None) or file_other.get("inputs") or [],
        getattr(args, "points", None),
        getattr(args, "images", None) or [],
    )
    if isinstance(file_other.get("inputs"), dict) and not inputs:  # a written config's inputs
        inputs = []
    work = WorkDir(workdir)
    calib = work.read_calib() if work.is_complete() else None
    given_inputs = inputs or points or images or getattr(args, "frames", None) is not None
    resuming = calib is not None and not given_inputs
    recorded_run = calib.record.run.given() if resuming and calib.record.run else {}
    options = {k: v for k, v in file_other.items() if k != "inputs"}
    options.update({k: v for k, v in vars(args).items() if k in _run_dests()})
    for key in RunOptions.names():
        if key not in options and key in recorded_run:
            options[key] = recorded_run[key]
    recorded_inputs = calib.record.inputs if resuming else None
    if isinstance(file_other.get("inputs"), dict):
        recorded_inputs = file_other["inputs"]
    spec = input_spec(args, inputs, points, images=images, recorded=recorded_inputs)
    base = config_from_record(calib.record.config) if resuming else CalibrationConfig()
    config = build_config(args, base=base, file_values=file_values, file_path=file_path)

    init = parse_start(options.get("init"), options.get("init_uncertainty"))
    prior = parse_pose(options["prior"], "--prior") if options.get("prior") else None
    manual = options.get("manual")
    no_matching = bool(options.get("no_matching"))
    if no_matching and init is None and manual is None:
        raise InputError("--no-matching needs --init POSE or --manual FILE")
    if "model_dir" in vars(args) or "model_dir" in file_other:
        check_model_dir(options.get("model_dir"))
    force = bool(options.get("force"))
    spec, cameras, rig, rig_file = _cameras(spec, config, workdir, options, given_inputs)
    plan = {  # which stages run: the same for one camera and for several
        "until": options.get("until"),
        "redo_from": "preprocess" if force else options.get("from_stage"),
        "overwrite": force or options.get("from_stage") is not None,
        "skip": {"report": "--no-report"} if options.get("no_report") else None,
    }
    warmup.compiling_note()
    warmup.start()  # a first run: the later stages' kernels compile beside the first ones
    if cameras is not None:
        from nbcalib.rig_pipeline import RigCalibrator

        job = RigCalibrator(
            config, workdir=workdir, model_dir=options.get("model_dir"), rig=rig, rig_file=rig_file
        )
        result = job.run(spec, cameras, init=init, no_matching=no_matching, **plan)
        _rig_summary(job, result)
        return 0
    calibrator = Calibrator(config, workdir=work, model_dir=options.get("model_dir"))
    calibrator.run_options = RunOptions.from_dict({k: options.get(k) for k in RunOptions.names()})
    calibrator.run(
        spec,
        init=init,
        init_is_fallback=not (no_matching and manual is None),
        manual=manual,
        prior=prior,
        **plan,
    )
    _summary(calibrator)
    return 0


def _cameras(spec, config, workdir, options, given_inputs):
    """(spec, cameras or None, rig or None, rig file or None) of the job; continues a rig job.

    ``nbcalib run WORKDIR`` of a several-camera job takes its inputs, cameras and rig file
    from ``WORKDIR/rig.json``.
    """
    from nbcalib.preprocess.inputs import InputSpec
    from nbcalib.rig_pipeline import CameraSource, find_cameras, read_rig_job

    topics = options.get("camera_topics")
    rig_path = options.get("rig")
    files = options.get("camera_image")
    job = None if given_inputs else read_rig_job(workdir)
    if job is not None:  # nbcalib run WORKDIR of a several-camera job
        inputs = job.get("inputs") or {}
        rig_path = rig_path or job.get("rig_file")
        if isinstance(inputs.get("per_camera"), dict):  # cameras from files
            spec = {n: InputSpec.from_dict(d) for n, d in inputs["per_camera"].items()}
            cameras = [CameraSource(name, "") for name in spec]
            return spec, cameras, *_read_rig(rig_path)
        spec = InputSpec.from_dict(inputs)
        recorded = [CameraSource(c["name"], c["image_topic"], c.get("camera_info_topic"))
                    for c in job["cameras"]]  # fmt: skip
        topics = topics or ",".join(c.image_topic for c in recorded)
    elif not given_inputs and topics is None and rig_path is None:
        return spec, None, None, None  # nbcalib run WORKDIR of a one-camera job
    if topics is not None:
        topics = [t.strip() for t in str(topics).split(",") if t.strip()]
    if files:
        spec, cameras = _file_cameras(spec, files, topics)
    else:
        cameras = find_cameras(spec, config.preprocess, topics)
    if cameras is None:
        if rig_path is not None:
            raise InputError("--rig is for several cameras: give a bag with several image topics")
        return spec, None, None, None
    for flag in ("manual", "prior"):
        if options.get(flag):
            raise InputError(
                f"--{flag} is for one camera; several cameras find their starts by matching "
                "(with --rig, --init gives the rig's)"
            )
    if rig_path is None and (options.get("init") or options.get("no_matching")):
        raise InputError(
            "--init/--no-matching with several cameras need --rig: the start is the rig's (the "
            "first camera's T_lidar_camera)"
        )
    return spec, cameras, *_read_rig(rig_path)


def _read_rig(path):
    """(the rig, its absolute path), or (None, None)."""
    from pathlib import Path

    if path is None:
        return None, None
    from nbcalib.io.rig import read_rig

    return read_rig(path), str(Path(path).absolute())


def _file_cameras(spec, files, topics):
    """Several cameras from files (``--camera-image NAME IMAGE CAMERA``): an InputSpec each.

    Every camera takes the point clouds of ``spec`` (INPUT or ``--points``) with its own
    image and camera file; the cameras' order is the options' (the first is the reference).
    """
    from dataclasses import replace

    from nbcalib.preprocess.inputs import CLOUD_SUFFIXES, InputSpec
    from nbcalib.rig_pipeline import CameraSource, camera_name

    if topics:
        raise InputError("give cameras as --camera-topics (bags) or --camera-image (files)")
    clouds = [p for p in spec.inputs if str(p).lower().endswith(CLOUD_SUFFIXES)]
    if len(clouds) != len(spec.inputs) or not (clouds or spec.points):
        raise InputError("--camera-image takes point cloud files as INPUT or --points (no bag)")
    if spec.image or spec.camera or spec.camera_model or spec.per_image:
        raise InputError(
            "--camera-image gives each camera its image and camera: leave out --image, "
            "--camera, --camera-model and the per-image options"
        )
    specs, cameras = {}, []
    for name, image, camera in files:
        if camera_name(f"/{name}/image") != name:
            raise InputError(f"--camera-image: {name!r} is no camera name (letters, digits, _ . -)")
        if name in specs:
            raise InputError(f"--camera-image: camera {name} given twice")
        specs[name] = InputSpec(inputs=spec.inputs, points=spec.points, image=image, camera=camera)
        cameras.append(CameraSource(name, ""))
    if len(cameras) < 2:
        one = files[0]
        return replace(spec, image=one[1], camera=one[2]), None
    return specs, cameras


def _rig_summary(job, result) -> None:
    """One line per camera (its result and verdict), the rig, and where it all is."""
    import numpy as np

    from nbcalib.transforms import pose_to_xyz_quat

    for name, res in result.cameras.items():
        if res is None:
            print(f"{name}: no result")
            continue
        values = ", ".join(f"{v:.6f}" for v in res.values)
        verdict = f", verdict {res.quality.verdict}" if res.quality is not None else ""
        print(f"{name}: T_lidar_camera = [{values}]{verdict}")
    how = "given (--rig), one pose from every camera" if result.joint else "implied by the results"
    print(f"camera-to-camera transforms ({how}), T_{result.reference}_camera:")
    for name, T in result.T_ref_camera.items():
        values = ", ".join(f"{v:.6f}" for v in pose_to_xyz_quat(np.asarray(T)))
        error = result.rig_errors.get(name)
        off = "" if error is None else f"  ({100 * error[0]:.2f} cm, {error[1]:.3f} deg from --rig)"
        print(f"  {name}: [{values}]{off}")
    if job.report is not None:
        print(f"report: {job.report}")
    print(f"nbcalib run: {len(result.cameras)} cameras in {result.seconds:.1f} s; "
          f"job in {job.workdir / 'rig.json'}")  # fmt: skip


def _run_dests() -> set[str]:
    return {"from_stage" if o.flag == "--from" else o.dest for o in RUN_OPTIONS}


def _summary(calibrator) -> None:
    from nbcalib.io.calib_json import FINAL_STAGE

    calib = calibrator.work.read_calib() if calibrator.work.is_complete() else None
    if calib is None or not calib.has_result(FINAL_STAGE):
        return
    if calibrator.report is not None:
        from nbcalib.commands.report import print_verdict

        print_verdict(calibrator.report)
    values = ", ".join(f"{v:.6f}" for v in calib.results[FINAL_STAGE])
    ran = ", ".join(calibrator.ran) or "nothing (every stage was done)"
    print(f"T_lidar_camera = [{values}]  (x y z qx qy qz qw)")
    print(f"started from: {_start_origin(calib)}")
    if calibrator.seconds:
        times = ", ".join(f"{s} {t:.1f} s" for s, t in calibrator.seconds.items())
        print(f"time: {times}")
    print(f"nbcalib run: ran {ran}; result in {calibrator.work.calib_path}")


def _start_origin(calib) -> str:
    """Where fine registration's start came from, in words, from ``calib.json``."""
    from nbcalib.io.calib_json import AUTO_STAGE, MANUAL_STAGE
    from nbcalib.io.job_record import InitialGuessRecord

    record = calib.record.calibration
    start = record.start if record is not None and record.start is not None else "unknown"
    guess = calib.record.initial_guess or InitialGuessRecord()
    if start == AUTO_STAGE:
        return f"the automatic initial guess ({guess.matcher(AUTO_STAGE) or 'keypoint'} matches)"
    if start == MANUAL_STAGE:
        return "the initial guess from hand-picked correspondences"
    if guess.failed:
        return f"{start} (the automatic initial guess failed: {guess.failed})"
    return start
