"""What a job can keep: for each product, whether these settings and inputs made it.

:func:`plan_stages` decides, for each stage of :class:`nbcalib.pipeline.Calibrator`, whether it
runs, and says why in a few words (shown by ``nbcalib run``):

- a stage runs when its product is missing, or was made with other settings or inputs (its
  record, ``calib.json``'s ``nbcalib.made.<stage>``, differs from
  :meth:`~nbcalib.pipeline.Calibrator.recipe`: the reason names the settings that changed);
- once a stage runs, every later stage runs too (its inputs change);
- a work directory without records (made by the reference toolbox, or by hand) keeps whatever
  products it holds;
- ``redo_from`` recomputes from that stage on; ``until`` stops after a stage; ``skip`` leaves
  stages out with a reason (``--manual`` needs no matching, a given start pose no guess).

With ``overwrite=False`` (``nbcalib run`` without ``--force``), a plan that would recompute a
finished result is refused with one line that says how to ask for it.
"""

from __future__ import annotations

from nbcalib.errors import InputError
from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE, MANUAL_STAGE

__all__ = ["STAGES", "changed_settings", "plan_stages"]

#: The stages of :class:`nbcalib.pipeline.Calibrator` as the command line names them, in order.
STAGES = ("preprocess", "find-matches", "initial-guess", "calibrate", "report")


def changed_settings(recorded, wanted, prefix: str = "") -> list[str]:
    """Dotted names of the entries in which two nested records differ."""
    if isinstance(recorded, dict) and isinstance(wanted, dict):
        names = []
        for key in sorted(set(recorded) | set(wanted)):
            names += changed_settings(recorded.get(key), wanted.get(key), f"{prefix}{key}.")
        return names
    return [] if recorded == wanted else [prefix.rstrip(".") or "record"]


def _lookup(record, name: str):
    """(found, value) of a dotted name in a nested record."""
    value = record
    for key in name.split("."):
        if not isinstance(value, dict) or key not in value:
            return False, None
        value = value[key]
    return True, value


def _added_at_default(name: str, recorded, wanted) -> bool:
    """A setting newer than the record, wanted at its default: the record's job used it too.

    A setting is added with the default that keeps what the code did before, so a record
    written before it existed was made as that default makes it.
    """
    from nbcalib.config import CalibrationConfig, config_to_dict

    if _lookup(recorded, name)[0]:
        return False
    found, default = _lookup(config_to_dict(CalibrationConfig()), name)
    return found and _lookup(wanted, name) == (True, default)


def _report_is_current(work, calib) -> bool:
    quality = calib.record.quality
    return (
        (work.path / "report" / "index.html").is_file()
        and quality is not None
        and quality.assessed_T_lidar_camera == calib.results.get(FINAL_STAGE)
    )


def _present(calibrator, calib, stage: str) -> bool:
    """The stage's product exists (on disk, or in memory for a job without a work directory)."""
    work = calibrator.work
    if work is None:
        return stage in calibrator._made
    if calib is None:
        return False
    if stage == "preprocess":
        return True
    if stage == "find-matches":
        return all(work.has_matches(name) for name in calib.bag_names)
    if stage == "initial-guess":
        guess = MANUAL_STAGE if calibrator._manual is not None else AUTO_STAGE
        failed = calib.record.initial_guess and calib.record.initial_guess.failed
        return calib.has_result(guess) or bool(failed and calibrator._fallback is not None)
    if stage == "calibrate":
        return calib.has_result(FINAL_STAGE)
    return _report_is_current(work, calib)


def _done(calibrator, calib, stage: str) -> tuple[bool, str]:
    """(keep the product, why) for one stage."""
    managed = calibrator.work is None or (calib is not None and calib.record.made is not None)
    if not managed and calib is not None:
        # made without nbcalib: keep what is there; a later product stands for its inputs
        # (a guess picked by hand needs no matches, a result implies its guess)
        later = STAGES[STAGES.index(stage) :]
        if any(_present(calibrator, calib, s) for s in later if s != "report"):
            return True, "done, made without nbcalib"
    if not _present(calibrator, calib, stage):
        return False, "not made yet"
    if not managed:
        return True, "done, made without nbcalib"
    made = calibrator._made if calibrator.work is None else calib.record.made
    recorded = made.get(stage)
    if recorded is None:
        return False, "made by an earlier stage's old settings"
    wanted = calibrator.recipe(stage)
    changed = [
        name
        for name in changed_settings(recorded, wanted)
        if not _added_at_default(name, recorded, wanted)
    ]
    if changed:
        shown = ", ".join(changed[:4]) + (", ..." if len(changed) > 4 else "")
        return False, f"settings changed: {shown}"
    return True, "done"


def plan_stages(
    calibrator,
    *,
    only: str | None = None,
    until: str | None = None,
    redo_from: str | None = None,
    overwrite: bool = True,
    skip: dict[str, str] | None = None,
) -> list[tuple[str, bool, str]]:
    """Per stage: (name, runs, why) (module docstring).

    Raises
    ------
    InputError
        ``overwrite`` is False and the plan would recompute a finished result.
    """
    for name in (only, until, redo_from):
        if name is not None and name not in STAGES:
            raise ValueError(f"unknown stage {name!r}; one of {', '.join(STAGES)}")
    work = calibrator.work
    calib = work.read_calib() if work is not None and work.is_complete() else None
    if only is not None:
        if (
            not overwrite
            and only != "report"
            and calib is not None
            and calib.has_result(FINAL_STAGE)
        ):
            raise InputError(
                f"holds a finished result (T_lidar_camera), which {only} would replace; use "
                "run.force to recompute it",
                work.calib_path,
            )
        return [(only, True, "")]
    skip = dict(skip or {})
    plan: list[tuple[str, bool, str]] = []
    rerun = False
    for k, stage in enumerate(STAGES):
        if until is not None and k > STAGES.index(until):
            plan.append((stage, False, f"run.until {until}"))
            continue
        if stage in skip:
            plan.append((stage, False, skip[stage]))
            continue
        if stage == redo_from:
            rerun, reason = True, f"run.from {stage}"
        elif rerun:
            reason = "an earlier stage ran"
        else:
            keep, reason = _done(calibrator, calib, stage)
            rerun = not keep
        plan.append((stage, rerun, reason))
    if not overwrite and calib is not None and calib.has_result(FINAL_STAGE):
        first = next(((s, r) for s, runs, r in plan if runs and s != "report"), None)
        if first is not None:
            raise InputError(
                f"holds a finished result (T_lidar_camera) and {first[0]} would run again "
                f"({first[1]}); use run.force to recompute it, or run.from STAGE",
                work.calib_path,
            )
    return plan
