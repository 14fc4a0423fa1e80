"""``nbcalib run INPUT... WORKDIR``: every stage of the method over one work directory.

The stages are the commands themselves (``preprocess``, ``find-matches``, ``initial-guess``,
``calibrate``, then ``report`` when this version has it): :class:`Pipeline` calls
each command module's ``run(args)`` with a namespace made by that command's own parser, so a stage
behaves exactly as when run by hand, and ``run`` accepts every option of every stage.

Options come from three places, the first that has a value wins: the command line, the config
file (``--config``, :mod:`nbcalib.config`), the stage's default. The options each stage used are
recorded under ``nbcalib.config.<stage>`` of ``calib.json`` and in ``nbcalib_config.yaml``.

Resuming: a stage is skipped when the work directory holds its product and it was made with the
same options (or by the reference toolbox, which records none); once a stage runs, every later
stage runs again. A finished result (``results.T_lidar_camera``) is never overwritten without
``--force`` (recompute every stage) or ``--from STAGE`` (recompute from that stage on).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import io
import json
import logging
import time
from pathlib import Path

from nbcalib.commands._args import (
    add_input_arguments,
    add_preprocess_arguments,
    add_verbosity_arguments,
    copy_stage_options,
    stage_parser,
    suppress_defaults,
)
from nbcalib.errors import InputError

#: The stages in order, with the command module that runs each.
STAGES = {
    "preprocess": "preprocess",
    "find-matches": "find_matches",
    "initial-guess": "initial_guess",
    "calibrate": "calibrate",
    "report": "report",
}

#: Options of ``run`` itself that a resumed job keeps.
_REMEMBERED = ("no_matching", "no_report", "init")

#: Namespace entries that are not options of a stage.
_NOT_OPTIONS = ("run", "command", "workdir", "verbose", "quiet")

log = logging.getLogger("nbcalib.run")

DESCRIPTION = """\
Calibrate from recordings in one command: preprocess -> find-matches -> initial-guess ->
calibrate -> report, over one work directory. Takes every input form and option of
'nbcalib preprocess' and the options of the later stages (see each stage's --help).

Resumes: stages whose products WORKDIR already holds, made with the same options, are skipped
(it says which); 'nbcalib run WORKDIR' continues a job with the inputs it was started with.
A finished result is not overwritten without --force (every stage) or --from STAGE.

The initial guess is automatic (keypoint matches); --manual FILE uses hand-picked
correspondences instead; --init POSE is the fallback when the automatic guess fails (or the start
itself with --no-matching). --config FILE (TOML or YAML, keys = long option names) supplies
options; those used are written to WORKDIR/nbcalib_config.yaml and calib.json."""

EPILOG = """\
examples:
  nbcalib run rosbag2_2023_03_09-13_42_46 work/                 # ROS 2 bag, camera from CameraInfo
  nbcalib run run1.bag run2.bag work/ --dynamic --matcher sift
  nbcalib run --points lidar.pcd --image image.png work/ --camera camera.yaml
  nbcalib run scans/*.bin image.png work/ --camera camera.yaml --init=0.1,0,0,0.5,-0.5,0.5,0.5
  nbcalib run work/                                              # continue an interrupted job
  nbcalib run work/ --from calibrate --optimizer nelder_mead     # redo the last stages
  nbcalib run --config job.toml data.bag work/
  nbcalib evaluate work/ --ground-truth ground_truth.json

job.toml:
  camera = "camera.yaml"
  matcher = "sift"
  [calibrate]
  optimizer = "nelder_mead"
"""


class _RaisingParser(argparse.ArgumentParser):
    """A parser whose errors are :class:`InputError`s (values read from a config file)."""

    source = None

    def error(self, message):
        raise InputError(f"{message}", path=self.source)


def add_parser(subparsers, formatter_class=argparse.HelpFormatter) -> argparse.ArgumentParser:
    """Register ``run``: its own options, then those of every stage."""
    from nbcalib.commands import calibrate, find_matches, initial_guess

    p = subparsers.add_parser(
        "run",
        help="every stage: preprocess, find-matches, initial-guess, calibrate, report",
        description=DESCRIPTION,
        epilog=EPILOG,
        formatter_class=formatter_class,
    )
    add_input_arguments(p)
    own = p.add_argument_group("run")
    own.add_argument("--config", metavar="FILE", help="options from a TOML or YAML file")
    own.add_argument(
        "--force", action="store_true", help="recompute every stage, even a finished result"
    )
    own.add_argument(
        "--from",
        dest="from_stage",
        choices=tuple(STAGES),
        metavar="STAGE",
        help=f"recompute from STAGE on ({', '.join(STAGES)})",
    )
    own.add_argument(
        "--no-matching",
        action="store_true",
        help="skip find-matches and the automatic guess: start from --init (or --manual)",
    )
    own.add_argument(
        "--until",
        choices=tuple(STAGES),
        metavar="STAGE",
        help="stop after STAGE (e.g. --until initial-guess to check the guess first)",
    )
    own.add_argument("--no-report", action="store_true", help="skip the report")
    add_verbosity_arguments(own)
    actions = add_preprocess_arguments(p)
    actions += copy_stage_options(p, find_matches, "find-matches (nbcalib find-matches --help)")
    actions += copy_stage_options(
        p, initial_guess, "initial-guess (nbcalib initial-guess --help)", skip=("--force",)
    )
    actions += copy_stage_options(p, calibrate, "calibrate (nbcalib calibrate --help)")
    if _has_report():
        from nbcalib.commands import report

        actions += copy_stage_options(p, report, "report (nbcalib report --help)")
    inputs = [a for a in p._actions if a.dest in ("points", "image")]
    suppress_defaults([*actions, *own._group_actions, *inputs])
    return p


# --------------------------------------------------------------------------------------------
# Options: command line over config file over stage defaults


def _config_options(path: str, formatter_class) -> dict:
    """The run options a config file sets, parsed and checked by the ``run`` parser itself."""
    from nbcalib.config import load_config

    options = load_config(path)
    parser = _run_parser(_RaisingParser, formatter_class)
    parser.source = path
    tokens: list[str] = []
    inputs = options.pop("--inputs", None)
    for option, value in options.items():
        action = parser._option_string_actions.get(option)
        if action is None or option in ("--config", "-h", "--help"):
            raise InputError(f"unknown option {option} (see nbcalib run --help)", path)
        if value is None:
            continue
        if action.nargs == 0:
            if not isinstance(value, bool):
                raise InputError(f"{option} must be true or false, got {value!r}", path)
            if value:
                tokens.append(option)
        elif isinstance(value, list):
            tokens += [option, *(str(v) for v in value)]
        else:
            tokens.append(f"{option}={value}")
    namespace = parser.parse_args(tokens)
    given = vars(namespace)
    if inputs is not None:
        given["inputs"] = [str(v) for v in (inputs if isinstance(inputs, list) else [inputs])]
    return given


def _run_parser(parser_class, formatter_class) -> argparse.ArgumentParser:
    scratch = parser_class(add_help=False)
    return add_parser(scratch.add_subparsers(parser_class=parser_class), formatter_class)


def merged_options(args: argparse.Namespace, formatter_class=argparse.HelpFormatter) -> dict:
    """The options of a ``run`` namespace, with a config file's values under them."""
    given = {k: v for k, v in vars(args).items() if k not in _NOT_OPTIONS}
    inputs = given.pop("inputs", None) or []
    options = {}
    if given.get("config"):
        options.update(_config_options(given["config"], formatter_class))
    options.update(given)
    options["inputs"] = options.get("inputs", []) + list(inputs)
    return options


def _plain(value):
    """JSON-comparable form of an option value."""
    return json.loads(json.dumps(value, default=str))


# --------------------------------------------------------------------------------------------
# The pipeline


class Pipeline:
    """The stages of the method over one work directory (module docstring).

    Parameters
    ----------
    workdir : str or os.PathLike
        The work directory.
    options : dict
        Option dest -> value (:func:`merged_options`); ``inputs`` holds the positional inputs.
    quiet : bool
        Hide the stages' own output.
    """

    def __init__(self, workdir, options: dict, *, quiet: bool = False):
        from nbcalib.workdir import WorkDir

        self.work = WorkDir(workdir)
        self.options = dict(options)
        self.quiet = quiet
        self.ran: list[str] = []
        self.skipped: list[str] = []
        self._guess_failed = False

    def run(self) -> int:
        """Run or skip each stage in turn; returns the exit status."""
        recorded = self._recorded_config()
        self._restore_inputs(recorded)
        plan = self._plan(recorded)
        # preprocess: inputs -> dense clouds, LiDAR images, calib.json
        # find-matches + initial-guess: keypoint matches -> initial T_camera_lidar
        # calibrate: NID fine registration -> T_lidar_camera
        # report: overlays, cost landscapes, uncertainty, verdict
        for k, (stage, namespace, reason) in enumerate(plan):
            header = f"[{k + 1}/{len(plan)}] {stage}"
            if namespace is None:
                log.info("%s: skipped (%s)", header, reason)
                self.skipped.append(stage)
                continue
            log.info("%s%s", header, f" ({reason})" if reason else "")
            t0 = time.perf_counter()
            status = self._run_stage(stage, namespace)
            if status:
                return status
            self.ran.append(stage)
            self._record(stage, namespace)
            log.info("    %s done in %.1f s", stage, time.perf_counter() - t0)
        self._summary()
        return 0

    # ------------------------------------------------------------ planning
    def _recorded_config(self) -> dict:
        if not self.work.calib_path.is_file():
            return {}
        return dict(self.work.read_calib().nbcalib.get("config", {}))

    def _restore_inputs(self, recorded: dict) -> None:
        """``nbcalib run WORKDIR`` (no inputs): continue with the options recorded there.

        Options given now win; with inputs given, the command line is the whole specification.
        """
        if self.options["inputs"] or self.options.get("points") or "preprocess" not in recorded:
            return
        for stage_options in recorded.values():
            for key, value in stage_options.items():
                if key not in self.options or key == "inputs":
                    self.options[key] = value

    def _plan(self, recorded: dict) -> list[tuple[str, argparse.Namespace | None, str]]:
        """Per stage: (name, namespace to run it with or None to skip it, why)."""
        from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE, MANUAL_STAGE

        opts = self.options
        manual = opts.get("manual") is not None
        no_matching = opts.get("no_matching", False)
        if no_matching and opts.get("init") is None and not manual:
            raise InputError("--no-matching needs --init POSE or --manual FILE")
        calib = self.work.read_calib() if self.work.is_complete() else None
        force_from = "preprocess" if opts.get("force") else opts.get("from_stage")
        has = calib.has_result if calib is not None else (lambda stage: False)
        done = {
            "preprocess": calib is not None,
            "find-matches": calib is not None
            and (
                all(self.work.matches_path(n).is_file() for n in calib.bag_names)
                or "find-matches" in recorded  # it failed and --init took over
            ),
            "initial-guess": has(MANUAL_STAGE if manual else AUTO_STAGE)
            or "initial-guess" in recorded,
            "calibrate": has(FINAL_STAGE),
            "report": "report" in recorded,
        }
        stop_after = opts.get("until")
        plan = []
        rerun = False  # an earlier stage runs: every later one must too
        for stage in STAGES:
            if stop_after and list(STAGES).index(stage) > list(STAGES).index(stop_after):
                plan.append((stage, None, f"--until {stop_after}"))
                continue
            if stage == "find-matches" and (manual or no_matching):
                plan.append((stage, None, "--manual" if manual else "--no-matching"))
                continue
            if stage == "initial-guess" and no_matching and not manual:
                plan.append((stage, None, "--no-matching: starting from --init"))
                continue
            if stage == "report" and (opts.get("no_report") or not _has_report()):
                why = "--no-report" if opts.get("no_report") else "no report in this version"
                plan.append((stage, None, why))
                continue
            namespace = self._namespace(stage)
            used = _plain(self._used(namespace))
            if stage == force_from:
                rerun, reason = True, "--force" if opts.get("force") else f"--from {stage}"
            elif rerun:
                reason = "an earlier stage ran"
            elif not done[stage]:
                rerun, reason = True, ""
            elif stage in recorded and recorded[stage] != used:
                changed = sorted(k for k in used if recorded[stage].get(k) != used[k])
                rerun, reason = True, f"options changed: {', '.join(changed) or 'removed'}"
            else:
                reason = "done" + ("" if stage in recorded else ", made without nbcalib run")
            plan.append((stage, namespace if rerun else None, reason))
        if stage_would_overwrite(plan, done) and not (opts.get("force") or opts.get("from_stage")):
            first = next(s for s, ns, _ in plan if ns is not None)
            raise InputError(
                f"holds a finished result (T_lidar_camera) and {first} would run again "
                f"({dict((s, r) for s, _, r in plan)[first]}); use --force to recompute it, or "
                "--from STAGE",
                self.work.calib_path,
            )
        if plan[0][1] is not None and not (opts["inputs"] or opts.get("points")):
            raise InputError(
                "nothing to preprocess: give INPUT... WORKDIR (or --points FILE --image FILE)",
                self.work.path,
            )
        return plan

    def _namespace(self, stage: str) -> argparse.Namespace:
        """The stage's own parser's defaults, overridden by the options given to ``run``."""
        module = importlib.import_module(f"nbcalib.commands.{STAGES[stage]}")
        parser = stage_parser(module)
        if stage == "preprocess":
            namespace = parser.parse_args([])
            namespace.inputs = [*self.options["inputs"], str(self.work.path)]
        else:
            namespace = parser.parse_args([str(self.work.path)])
        for key, value in self.options.items():
            if key != "inputs" and (hasattr(namespace, key) or _accepts(parser, key)):
                setattr(namespace, key, value)
        if stage == "initial-guess":
            namespace.force = False  # run's --force means "recompute"
        return namespace

    def _use_init(self) -> bool:
        """Calibrate from --init: with --no-matching, or when there is no initial guess."""
        if not self.options.get("init"):
            return False
        if self.options.get("no_matching") or self._guess_failed:
            return True
        return self.work.read_calib().latest_initial_stage() is None

    @staticmethod
    def _used(namespace: argparse.Namespace) -> dict:
        used = {k: v for k, v in vars(namespace).items() if k not in _NOT_OPTIONS}
        if "inputs" in used:  # preprocess: INPUT... WORKDIR -> INPUT...
            used["inputs"] = list(used["inputs"][:-1])
        return used

    # ------------------------------------------------------------ running
    def _run_stage(self, stage: str, namespace: argparse.Namespace) -> int:
        if stage == "calibrate" and not self._use_init():
            namespace = argparse.Namespace(**{**vars(namespace), "init": None})
        module = importlib.import_module(f"nbcalib.commands.{STAGES[stage]}")
        try:
            with self._output():
                return int(module.run(namespace) or 0)
        except InputError as exc:
            if stage in ("find-matches", "initial-guess") and self.options.get("init"):
                log.warning(
                    "automatic initial guess failed (%s): calibrating from --init instead", exc
                )
                self._guess_failed = True
                return 0
            raise

    def _output(self):
        """Stages print their progress; ``-q`` hides it."""
        if not self.quiet:
            return contextlib.nullcontext()
        sink = io.StringIO()
        stack = contextlib.ExitStack()
        stack.enter_context(contextlib.redirect_stdout(sink))
        stack.enter_context(contextlib.redirect_stderr(sink))
        return stack

    def _record(self, stage: str, namespace: argparse.Namespace) -> None:
        """Write the options the stage used into calib.json and nbcalib_config.yaml."""
        from nbcalib.config import CONFIG_FILE, write_config

        calib = self.work.read_calib()
        config = calib.nbcalib.setdefault("config", {})
        if stage == "preprocess":
            config.clear()
        config[stage] = _plain(self._used(namespace))
        config["run"] = {k: self.options.get(k) for k in _REMEMBERED}
        self.work.write_calib(calib)
        tables = {s: option_values(config[s]) for s in ("run", *STAGES) if s in config}
        write_config(self.work.path / CONFIG_FILE, tables)

    def _summary(self) -> None:
        from nbcalib.io.calib_json import FINAL_STAGE

        calib = self.work.read_calib()
        if not calib.has_result(FINAL_STAGE):
            return
        values = ", ".join(f"{v:.6f}" for v in calib.results[FINAL_STAGE])
        ran = ", ".join(self.ran) or "nothing (every stage was done)"
        print(f"T_lidar_camera = [{values}]  (x y z qx qy qz qw)")
        print(f"nbcalib run: ran {ran}; result in {self.work.calib_path}")


def stage_would_overwrite(plan, done: dict) -> bool:
    """A stage up to ``calibrate`` would run while a finished result exists."""
    return done["calibrate"] and any(ns is not None for stage, ns, _ in plan if stage != "report")


def option_values(used: dict) -> dict:
    """Option dests and values -> long option names and values that ``--config`` reads back.

    ``--no-confidence-weights`` (dest ``confidence_weights``, stored False when given) is written
    as ``no-confidence-weights: true``; dests that ``run`` has no option for are left out.
    """
    parser = _run_parser(argparse.ArgumentParser, argparse.HelpFormatter)
    by_dest = {}
    for action in parser._actions:
        if action.option_strings and action.dest not in by_dest:
            by_dest[action.dest] = action
    options = {}
    for dest, value in used.items():
        if dest == "inputs":
            options["inputs"] = value
            continue
        action = by_dest.get(dest)
        if action is None or dest in ("force", "from_stage", "config", "until"):
            continue
        name = max(action.option_strings, key=len).lstrip("-")
        if isinstance(action, argparse._StoreFalseAction):
            value = not value
        options[name] = value
    return options


def _accepts(parser: argparse.ArgumentParser, dest: str) -> bool:
    return any(action.dest == dest for action in parser._actions)


def _has_report() -> bool:
    import importlib.util

    try:
        return importlib.util.find_spec("nbcalib.commands.report") is not None
    except ImportError:
        return False


def run(args: argparse.Namespace) -> int:
    """Run every stage over WORKDIR; returns the exit status."""
    from nbcalib.preprocess.pipeline import CLOUD_SUFFIXES

    options = merged_options(args)
    inputs = list(options["inputs"])
    points = list(options.get("points") or [])
    # `--points a.pcd b.pcd WORKDIR`: the last --points entry is WORKDIR (as preprocess)
    if not inputs and len(points) > 1 and Path(points[-1]).suffix.lower() not in CLOUD_SUFFIXES:
        inputs = [points.pop()]
        options["points"] = points
    if not inputs:
        raise InputError("WORKDIR missing: give the work directory as the last argument")
    workdir = inputs.pop()
    options["inputs"] = inputs
    quiet = bool(getattr(args, "quiet", False))
    return Pipeline(workdir, options, quiet=quiet).run()
