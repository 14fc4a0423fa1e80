"""Does the report's word hold? Coverage of its intervals and its verdicts at scale (issue 29).

Every run goes through the command line as a user types it. Two phases, each resumable, so
that the report can be changed and judged again on the same calibrations:

``--phase calibrate`` makes the calibrations:

- **Synthetic rigs** (modality gap 1, the rig's default): rig ``i`` has seed ``i``, a LiDAR x
  camera combination (all 35, in a fixed shuffled order, each seed pair ``2k, 2k + 1`` on the
  same one), a scene (room or street) and 1, 2, 5 or 15 pairs (a fixed cycle). ``nbcalib synth
  OUT --lidar L --camera C --scene S --pairs N --seed i --format bag1``, then ``nbcalib
  preprocess OUT/pair_*.bag BASE``. Per rig, starts on copies of BASE: ``truth`` (``nbcalib
  calibrate COPY --init`` the ground truth), ``near`` (the truth turned by 1-3 deg and moved by
  5-15 cm in a seeded direction) and, for rigs of one or two pairs, ``auto`` (``nbcalib
  find-matches COPY``, ``nbcalib initial-guess COPY``, ``nbcalib calibrate COPY``: the automatic
  guess; a guess refused by its success test is written with ``initial-guess --force`` to know
  its error, and not calibrated). Even seeds tune, odd seeds check.
- **Real sets** (``../shared/data/real``, skipped when absent): the 38 sets of
  benchmarks/bench_bias.py, each preprocessed once; starts ``reference`` (the reference
  calibration), two ``near`` (1 deg / 5 cm) and one ``far`` (2-3 deg / 10-15 cm); sets alternate
  between tuning and checking.

``--phase report`` runs ``nbcalib report COPY`` on every calibration (again whenever the
report's code changes: the stored report is keyed by the commit) and stores the verdict, the
stated intervals and the error per camera axis.

``--phase analyse`` (the default runs all three) prints the tables: coverage of the stated 95 %
intervals per axis and of the error norms, per group (single pair, several pairs, camera
family, real), on the check half; the verdict's confusion table against *good* (within 1 cm /
0.1 deg synthetic, 0.3 deg / 5 cm real) and *bad* (worse than 1 deg or 10 cm); the guess's
success test against the paper's 1 deg / 0.5 m.

Run (one at a time on an idle machine; DIR outside the repository, kept between runs):

    python benchmarks/bench_verdict.py --out DIR --rigs 80
    python benchmarks/bench_verdict.py --out DIR --phase report
    python benchmarks/bench_verdict.py --out DIR --phase analyse
"""

from __future__ import annotations

import argparse
import itertools
import json
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_bias import init_arg, nbcalib, offset_start, real_sets

from nbcalib.commands.synth import CAMERAS, LIDARS, SCENES
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.transforms import invert_T, pose_from_xyz_quat, se3_log

REAL_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
PAIR_CYCLE = (1, 2, 1, 5, 1, 2, 1, 15)
#: combinations in a fixed order that puts every LiDAR and camera early
COMBOS = [
    c for _, c in sorted(
        (float(np.random.default_rng([29, k]).random()), c)
        for k, c in enumerate(itertools.product(LIDARS, CAMERAS))
    )
]  # fmt: skip


def checked(*args) -> subprocess.CompletedProcess:
    run = nbcalib(*args)
    if run.returncode != 0:
        last = (run.stderr or run.stdout).strip().splitlines()
        raise RuntimeError(f"nbcalib {args[0]} failed: {last[-1] if last else run.returncode}")
    return run


def evaluate(work: Path, truth: Path, stage: str = "T_lidar_camera") -> dict | None:
    run = nbcalib("evaluate", work, "--ground-truth", truth, "--stage", stage)
    if run.returncode != 0:
        return None
    return json.loads(run.stdout.strip().splitlines()[-1])


@dataclass(frozen=True)
class Rig:
    lidar: str
    camera: str
    scene: str
    pairs: int
    seed: int

    @property
    def name(self) -> str:
        return f"{self.lidar}_{self.camera}_{self.scene}_p{self.pairs}_s{self.seed}"

    @property
    def half(self) -> str:
        return "tune" if self.seed % 2 == 0 else "check"


def rig(i: int) -> Rig:
    k = i // 2
    lidar, camera = COMBOS[k % len(COMBOS)]
    scene = SCENES[int(np.random.default_rng([29, i, 1]).integers(len(SCENES)))]
    return Rig(lidar, camera, scene, PAIR_CYCLE[k % len(PAIR_CYCLE)], i)


def near_start(T_true: np.ndarray, seed, lo_deg=1.0, hi_deg=3.0, lo_m=0.05, hi_m=0.15):
    rng = np.random.default_rng(seed)
    return offset_start(T_true, rng.uniform(lo_deg, hi_deg), rng.uniform(lo_m, hi_m), rng)


def calibrate_case(case: Path, base: Path, truth: Path, start, meta: dict) -> dict:
    """Copy ``base`` to ``case/work``, calibrate from ``start`` (a pose or ``"auto"``)."""
    work = case / "work"
    if case.exists():
        shutil.rmtree(case)
    case.mkdir(parents=True)
    shutil.copytree(base, work)
    row = dict(meta)
    t0 = time.perf_counter()
    if isinstance(start, str):  # the automatic guess, as `nbcalib run` makes it
        checked("find-matches", work)
        guess = nbcalib("initial-guess", work)
        info = json.loads((work / "calib.json").read_text()).get("nbcalib", {})
        record = (info.get("initial_guess") or {}).get("init_T_lidar_camera_auto") or {}
        row["guess_exit"] = guess.returncode
        row["guess_flagged_ok"] = bool(record.get("success", False))
        if not record:  # refused, so not written: write it anyway to know its error
            nbcalib("initial-guess", work, "--force")
        ev = evaluate(work, truth, "init_T_lidar_camera_auto")
        row["guess_t_m"] = None if ev is None else ev["translation_error_m"]
        row["guess_r_deg"] = None if ev is None else ev["rotation_error_deg"]
        run = nbcalib("calibrate", work) if row["guess_flagged_ok"] else None
    else:
        run = nbcalib("calibrate", work, init_arg(start))
    row["calibrate_exit"] = None if run is None else run.returncode
    if run is not None and run.returncode != 0:
        row["calibrate_error"] = (run.stderr.strip().splitlines() or [""])[-1][:300]
    row["calibrate_s"] = round(time.perf_counter() - t0, 1)
    (case / "row.json").write_text(json.dumps(row))
    return row


def synthetic_cases(i: int, root: Path):
    """Yield (case folder, base, truth, start, meta) of rig ``i``, making its data on demand."""
    r = rig(i)
    folder = root / "rigs" / r.name
    base, truth = folder / "base", folder / "synth" / "ground_truth.json"

    def ensure():
        if (base / "calib.json").is_file() and truth.is_file():
            return
        shutil.rmtree(folder, ignore_errors=True)
        checked("synth", folder / "synth", "--lidar", r.lidar, "--camera", r.camera,
                "--scene", r.scene, "--pairs", r.pairs, "--seed", r.seed, "--format", "bag1",
                "-q")  # fmt: skip
        checked("preprocess", *sorted((folder / "synth").glob("pair_*.bag")), base, "-q")
        for bag in (folder / "synth").glob("pair_*.bag"):  # the work directory has what it needs
            bag.unlink()

    meta = dict(part="synthetic", **asdict(r), half=r.half, rig=r.name)
    starts = ["truth", "near"] + (["auto"] if r.pairs <= 2 else [])
    for kind in starts:
        case = root / "cases" / f"{r.name}_{kind}"
        yield case, ensure, base, truth, kind, {**meta, "start": kind}


def real_cases(root: Path, data: Path):
    for j, (group, name, pre, calib) in enumerate(real_sets(data)):
        slug = name.replace(" ", "_").replace("+", "")
        folder = root / "real" / slug
        base, truth = folder / "base", folder / "reference.json"

        def ensure(pre=pre, base=base, truth=truth, calib=calib, folder=folder):
            if (base / "calib.json").is_file() and truth.is_file():
                return
            shutil.rmtree(folder, ignore_errors=True)
            folder.mkdir(parents=True)
            if None in pre:  # positional inputs, then the work directory, then options
                k = pre.index(None)
                checked("preprocess", *pre[:k], base, *pre[k + 1 :], "-q")
            else:
                checked("preprocess", base, *pre, "-q")
            T_ref = read_ground_truth(calib)
            truth.write_text(json.dumps({"T_camera_lidar": T_ref.tolist()}))

        meta = dict(part="real", group=group, set=name, half="tune" if j % 2 == 0 else "check")
        for kind in ("reference", "near0", "near1", "far"):
            case = root / "cases" / f"real_{slug}_{kind}"
            yield case, ensure, base, truth, kind, {**meta, "start": kind}


def start_pose(kind: str, truth: Path, case: Path):
    if kind == "auto":
        return "auto"
    T = read_ground_truth(truth)
    seed = [29, *case.name.encode()]
    if kind in ("truth", "reference"):
        return T
    if kind.startswith("near") and "real_" in case.name:
        rng = np.random.default_rng(seed)
        return offset_start(T, 1.0, 0.05, rng)
    if kind == "far":
        return near_start(T, seed, 2.0, 3.0, 0.10, 0.15)
    return near_start(T, seed)


def phase_calibrate(args) -> None:
    root = Path(args.out)
    synthetic = [list(synthetic_cases(i, root)) for i in range(args.rigs)]
    real = []
    if args.real and REAL_DATA.is_dir():
        real = [list(g) for _, g in itertools.groupby(real_cases(root, REAL_DATA), lambda c: c[2])]
    elif args.real:
        print(f"no real data at {REAL_DATA}: real sets skipped", file=sys.stderr)
    # two synthetic rigs, then one real set, so that any prefix of the work has both
    order = []
    for k in range(max(len(synthetic), 2 * len(real))):
        order += synthetic[k : k + 1] + (real[k // 2 : k // 2 + 1] if k % 2 else [])
    for case, ensure, base, truth, kind, meta in itertools.chain.from_iterable(order):
        if (case / "row.json").is_file():
            continue
        t0 = time.perf_counter()
        try:
            ensure()
            row = calibrate_case(case, base, truth, start_pose(kind, truth, case), meta)
        except RuntimeError as exc:
            print(f"{case.name}: {exc}", file=sys.stderr, flush=True)
            continue
        ev = None
        if row.get("calibrate_exit") == 0:
            ev = evaluate(case / "work", truth)
        row["t_m"] = None if ev is None else ev["translation_error_m"]
        row["r_deg"] = None if ev is None else ev["rotation_error_deg"]
        (case / "row.json").write_text(json.dumps(row))
        t, r = row["t_m"], row["r_deg"]
        print(
            f"{case.name}: {'-' if t is None else f'{100 * t:.2f} cm / {r:.3f} deg'}"
            f" ({time.perf_counter() - t0:.0f} s)",
            flush=True,
        )


# ------------------------------------------------------------------------------ guesses phase

GUESS_SEED0 = 1000


def guess_only(case: Path, base: Path, truth: Path, meta: dict) -> dict:
    """``find-matches``, ``initial-guess`` on a copy of ``base``: the guess, its test, its error."""
    work = case / "work"
    shutil.rmtree(case, ignore_errors=True)
    case.mkdir(parents=True)
    shutil.copytree(base, work)
    t0 = time.perf_counter()
    checked("find-matches", work, "-q")
    guess = nbcalib("initial-guess", work)
    record = lambda: (  # noqa: E731
        (json.loads((work / "calib.json").read_text()).get("nbcalib", {}).get("initial_guess")
         or {}).get("init_T_lidar_camera_auto") or {}
    )  # fmt: skip
    row = {**meta, "guess_only": True, "guess_exit": guess.returncode}
    row["guess_flagged_ok"] = bool(record().get("success", False))
    if not record():  # refused, so not written: write it anyway to know its error
        nbcalib("initial-guess", work, "--force")
    row["guess_record"] = record()
    ev = evaluate(work, truth, "init_T_lidar_camera_auto")
    row["guess_t_m"] = None if ev is None else ev["translation_error_m"]
    row["guess_r_deg"] = None if ev is None else ev["rotation_error_deg"]
    row["t_m"] = row["r_deg"] = row["calibrate_exit"] = None
    row["guess_s"] = round(time.perf_counter() - t0, 1)
    (case / "row.json").write_text(json.dumps(row))
    shutil.rmtree(work)  # the row holds what counts; the clouds are large
    return row


def phase_guesses(args) -> None:
    """Automatic guesses alone: ``--guess-rigs`` one-pair rigs (seeds from 1000) and every real
    set, for the success test's figures (the issue asks for 100 on check seeds)."""
    root = Path(args.out)
    jobs = []
    for i in range(args.guess_rigs):
        seed = GUESS_SEED0 + i
        lidar, camera = COMBOS[i % len(COMBOS)]
        scene = SCENES[int(np.random.default_rng([29, seed, 1]).integers(len(SCENES)))]
        r = Rig(lidar, camera, scene, 1, seed)
        folder = root / "guess_rigs" / r.name
        meta = dict(part="synthetic", **asdict(r), half=r.half, rig=r.name, start="auto")
        jobs.append((root / "cases" / f"guess_{r.name}", folder, meta, r))
    if args.real and REAL_DATA.is_dir():
        for case, ensure, base, truth, kind, meta in real_cases(root, REAL_DATA):
            if kind == "reference":
                jobs.append((case.with_name(case.name[: -len("_reference")] + "_guess"),
                             (ensure, base, truth), {**meta, "start": "auto"}, None))  # fmt: skip
    for case, where, meta, r in jobs:
        if (case / "row.json").is_file():
            continue
        try:
            if r is not None:
                base, truth = where / "base", where / "synth" / "ground_truth.json"
                if not (base / "calib.json").is_file():
                    shutil.rmtree(where, ignore_errors=True)
                    checked("synth", where / "synth", "--lidar", r.lidar, "--camera", r.camera,
                            "--scene", r.scene, "--pairs", 1, "--seed", r.seed, "--format",
                            "bag1", "-q")  # fmt: skip
                    checked("preprocess", *sorted((where / "synth").glob("pair_*.bag")), base,
                            "-q")  # fmt: skip
                    for bag in (where / "synth").glob("pair_*.bag"):
                        bag.unlink()
            else:
                ensure, base, truth = where
                ensure()
            row = guess_only(case, base, truth, meta)
        except RuntimeError as exc:
            print(f"{case.name}: {exc}", file=sys.stderr, flush=True)
            continue
        if r is not None:
            shutil.rmtree(where, ignore_errors=True)
        t, a = row["guess_t_m"], row["guess_r_deg"]
        print(f"{case.name}: {'-' if t is None else f'{100 * t:.1f} cm / {a:.2f} deg'}, "
              f"ok {row['guess_flagged_ok']} ({row['guess_s']:.0f} s)", flush=True)  # fmt: skip


# ------------------------------------------------------------------------------ report phase


def code_version() -> str:
    """The commit the report runs at, ``+dirty`` when the work tree has changes."""
    repo = Path(__file__).resolve().parents[1]
    head = subprocess.run(["git", "-C", repo, "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()  # fmt: skip
    dirty = subprocess.run(["git", "-C", repo, "status", "--porcelain", "nbcalib"],
                           capture_output=True, text=True).stdout.strip()  # fmt: skip
    return head + ("+dirty" if dirty else "")


def axis_errors(T_est: np.ndarray, T_true: np.ndarray) -> list[float]:
    """``delta`` with ``exp(delta) @ T_est = T_true``: metres, then radians, camera axes."""
    return se3_log(T_true @ invert_T(T_est)).tolist()


def phase_report(args) -> None:
    """``nbcalib report`` on every calibration without a report of this code version."""
    root = Path(args.out)
    version = code_version()
    for case in sorted((root / "cases").glob(args.cases)):
        row_path, out_path = case / "row.json", case / "report.json"
        if not row_path.is_file():
            continue
        row = json.loads(row_path.read_text())
        if row.get("calibrate_exit") != 0:
            continue
        if out_path.is_file() and json.loads(out_path.read_text()).get("version") == version:
            continue
        work = case / "work"
        t0 = time.perf_counter()
        run = nbcalib("report", work)
        entry = {"version": version, "exit": run.returncode, "s": time.perf_counter() - t0}
        if run.returncode == 0:
            calib = json.loads((work / "calib.json").read_text())
            quality = calib["nbcalib"]["quality"]
            truth = read_ground_truth(truth_of(case, row))
            T_est = invert_T(pose_from_xyz_quat(calib["results"]["T_lidar_camera"]))
            entry |= {
                "verdict": quality["verdict"],
                "reasons": quality["reasons"],
                "uncertainty": quality["uncertainty"],
                "delta": axis_errors(T_est, truth),
            }
        else:
            entry["error"] = (run.stderr.strip().splitlines() or [""])[-1][:300]
        out_path.write_text(json.dumps(entry))
        print(f"{case.name}: {entry.get('verdict', 'report failed')} ({entry['s']:.0f} s)",
              flush=True)  # fmt: skip


def truth_of(case: Path, row: dict) -> Path:
    root = case.parents[1]
    if row["part"] == "synthetic":
        return root / "rigs" / row["rig"] / "synth" / "ground_truth.json"
    slug = case.name[len("real_") : -len(row["start"]) - 1]
    return root / "real" / slug / "reference.json"


# ------------------------------------------------------------------------------ guess phase


def guess_stats(case: Path) -> dict:
    """The automatic guess made again from the case's stored matches, with its statistics.

    In process (the pipeline's own correspondences and settings), so that a success test can be
    tuned on the stored guesses without matching again; the guess must equal the stored one.
    """
    from nbcalib.config import config_from_record
    from nbcalib.initial_guess.estimate import estimate_initial_guess
    from nbcalib.pipeline import Calibrator
    from nbcalib.workdir import WorkDir

    work = WorkDir(case / "work")
    calib = work.read_calib()
    cal = Calibrator(config_from_record(calib.record.config), workdir=work)
    corr, _, _ = cal._guess_correspondences()
    cfg, camera = cal.config.initial_guess, cal._camera()
    weights = corr.weights if cfg.confidence_weights else None
    guess = estimate_initial_guess(
        camera, corr.uv_camera, corr.points_lidar, cfg, seed=cal.config.seed, weights=weights
    )
    stored = calib.results.get("init_T_lidar_camera_auto")
    same = stored is not None and np.allclose(
        invert_T(pose_from_xyz_quat(stored)), guess.T_camera_lidar, atol=1e-6
    )
    return {
        "same_as_stored": bool(same),
        "success": bool(guess.success),
        "inliers": guess.n_inliers,
        "correspondences": guess.n_correspondences,
        "rms_px": guess.rms_px,
        "support": guess.support,
        "runner_up": guess.runner_up,
        "runner_up_shared": guess.runner_up_shared,
        "bound_m": guess.bound_m,
        "bound_deg": guess.bound_deg,
        "failure": guess.failure,
    }


def phase_guess(args) -> None:
    for case in sorted((Path(args.out) / "cases").glob("*_auto")):
        out = case / "guess.json"
        if out.is_file() or not (case / "row.json").is_file():
            continue
        stats = guess_stats(case)
        out.write_text(json.dumps(stats))
        row = json.loads((case / "row.json").read_text())
        print(f"{case.name}: {100 * row['guess_t_m']:.1f} cm / {row['guess_r_deg']:.2f} deg, "
              f"bound {100 * stats['bound_m']:.1f} cm / {stats['bound_deg']:.2f} deg, "
              f"ok {stats['success']}", flush=True)  # fmt: skip


# ------------------------------------------------------------------------------ analyse phase

FAMILY = {
    "pinhole": "pinhole",
    "plumb_bob": "pinhole",
    "rational_polynomial": "pinhole",
    "fisheye": "fisheye",
    "atan": "fisheye",
    "omnidir": "omni",
    "equirectangular": "omni",
}


def quality_of(row: dict, report: dict) -> str:
    """good / middle / bad: the issue's classes of a result's error."""
    t, r = row["t_m"], row["r_deg"]
    if t is None:
        return "none"
    if r > 1.0 or t > 0.10:
        return "bad"
    good = (t <= 0.01 and r <= 0.1) if row["part"] == "synthetic" else (t <= 0.05 and r <= 0.3)
    return "good" if good else "middle"


def groups_of(row: dict) -> list[str]:
    if row["part"] == "real":
        return ["real", f"real {row['group']}"]
    n = "single pair" if row["pairs"] == 1 else "several pairs"
    return ["synthetic", f"synthetic {n}", f"synthetic {FAMILY[row['camera']]}"]


def rejudged(case: Path, report: dict, overrides: dict) -> dict:
    """The report judged again under ``overrides`` of AssessConfig (tuning, not the CLI path)."""
    from dataclasses import replace

    from nbcalib.report.quality import load_quality, rejudge

    q = load_quality(case / "work" / "report" / "quality.npz")
    q = rejudge(q, replace(q.config, **overrides))
    return {**report, "verdict": q.verdict, "reasons": q.reasons, "uncertainty": q.uncertainty}


def load_cases(root: Path, overrides: dict) -> list[dict]:
    out = []
    for case in sorted((root / "cases").glob("*")):
        if not (case / "row.json").is_file():
            continue
        row = json.loads((case / "row.json").read_text())
        report = {}
        if (case / "report.json").is_file():
            report = json.loads((case / "report.json").read_text())
            if overrides and report.get("exit") == 0:
                report = rejudged(case, report, overrides)
        row["report"] = report
        row["class"] = quality_of(row, report)
        row["case"] = case.name
        out.append(row)
    return out


#: How far each real set's reference may be from the truth, 95 % (metres, degrees): the data's
#: README ("How far to trust it"). A stated interval bounds the error against the *truth*; against
#: a reference it is judged with this allowance added in quadrature (per axis 0.70 of the norm
#: bound, as for an isotropic Gaussian in three dimensions), and without it ("raw").
REFERENCE_TRUST = {
    "kitti-scan": (0.03, 0.3),  # "a few tenths of a degree and a few centimetres"
    "kitti-shot": (0.03, 0.3),
    "kitti-odometry": (0.03, 0.3),
    "pjlab": (0.03, 0.2),  # "overlays line up to a few pixels" (1920 px, f ~ 2000 px)
    "acfr": (0.05, 1.0),  # "score a calibrator with about 1 deg and 5 cm of tolerance"
    "waymo": (0.03, 0.2),  # "about 0.2 deg and a few cm" (no distortion model)
}


def covered(row: dict, reference: bool = True) -> tuple[list[bool], list[bool]] | None:
    """Per axis (6) and per norm (2): does the stated 95 % interval hold the error?

    On real sets with ``reference``, the reference's own uncertainty (:data:`REFERENCE_TRUST`)
    is added in quadrature.
    """
    rep = row["report"]
    if "delta" not in rep:
        return None
    u, d = rep["uncertainty"], np.abs(rep["delta"])
    half = np.r_[np.array(u["translation_cm"]) / 100.0, np.radians(u["rotation_deg"])]
    t_total, r_total = u["translation_total_cm"] / 100.0, u["rotation_total_deg"]
    if row["part"] == "real" and reference:
        ref_m, ref_deg = REFERENCE_TRUST[row["group"]]
        half = np.hypot(half, 0.70 * np.r_[[ref_m] * 3, [np.radians(ref_deg)] * 3])
        t_total, r_total = np.hypot(t_total, ref_m), np.hypot(r_total, ref_deg)
    axes = (d <= half).tolist()
    norms = [row["t_m"] <= t_total, row["r_deg"] <= r_total]
    return axes, norms


def coverage_table(rows: list[dict], half: str) -> list[dict]:
    table = {}
    for row in rows:
        if row["half"] != half:
            continue
        c = covered(row)
        if c is None:
            continue
        raw = covered(row, reference=False)
        for g in groups_of(row):
            t = table.setdefault(g, {"runs": 0, "axes": [], "norms": [], "ok_axes": [], "raw": []})
            t["runs"] += 1
            t["axes"] += c[0]
            t["norms"] += c[1]
            t["raw"] += raw[0]
            if row["report"]["verdict"] == "ok":
                t["ok_axes"] += c[0]
    return [
        {"group": g, "runs": t["runs"],
         "axis_coverage": float(np.mean(t["axes"])),
         "norm_coverage": float(np.mean(t["norms"])),
         "raw_axis_coverage": float(np.mean(t["raw"])),
         "ok_axis_coverage": float(np.mean(t["ok_axes"])) if t["ok_axes"] else None}
        for g, t in sorted(table.items())
    ]  # fmt: skip


def verdict_table(rows: list[dict], half: str) -> dict:
    """Counts of (part, error class, verdict); a failed calibrate or report is 'failed'."""
    counts = {}
    for row in rows:
        if row["half"] != half or row.get("guess_only"):
            continue
        if row.get("start") == "auto" and not row.get("guess_flagged_ok"):
            continue
        rep = row["report"]
        if row.get("calibrate_exit") == 0 and not rep:
            continue  # not reported yet
        verdict = rep.get("verdict", "report failed") if rep else "calibrate failed"
        key = f"{row['part']}|{row['class']}|{verdict}"
        counts[key] = counts.get(key, 0) + 1
    return counts


def guess_table(rows: list[dict], half: str) -> dict:
    """The success test against the paper's 1 deg / 0.5 m, per part, over the guesses phase."""
    table = {}
    for row in rows:
        if not row.get("guess_only") or row["half"] != half or row.get("guess_t_m") is None:
            continue
        out = table.setdefault(row["part"], {"guesses": 0, "false_ok": [], "good_refused": [],
                                             "good": 0, "within": 0, "ok": 0})  # fmt: skip
        t, r, ok = row["guess_t_m"], row["guess_r_deg"], row["guess_flagged_ok"]
        out["guesses"] += 1
        within = t <= 0.5 and r <= 1.0
        out["within"] += within
        out["ok"] += ok
        if ok and not within:
            out["false_ok"].append(f"{row['case']} ({100 * t:.1f} cm / {r:.2f} deg)")
        if t <= 0.1 and r <= 0.5:
            out["good"] += 1
            if not ok:
                out["good_refused"].append(f"{row['case']} ({100 * t:.1f} cm / {r:.2f} deg)")
    return table


def phase_analyse(args) -> None:
    overrides = {}
    for item in args.rejudge or []:
        key, value = item.split("=", 1)
        overrides[key] = float(value) if "." in value or "e" in value else int(value)
    rows = load_cases(Path(args.out), overrides)
    versions = sorted({r["report"].get("version", "-") for r in rows if r["report"]})
    print(f"{len(rows)} cases, reports of {', '.join(versions) or 'none'}"
          + (f", rejudged with {overrides} (not the CLI path)" if overrides else ""))  # fmt: skip
    summary = {"cases": len(rows), "rejudge": overrides}
    for half in ("tune", "check"):
        print(f"\n== {half} half ==")
        cov = coverage_table(rows, half)
        print(f"{'group':<28}{'runs':>5}{'axes':>8}{'norms':>8}{'axes of ok':>12}"
              f"{'axes raw':>10}")  # fmt: skip
        for c in cov:
            ok = "-" if c["ok_axis_coverage"] is None else f"{100 * c['ok_axis_coverage']:.1f}"
            print(f"{c['group']:<28}{c['runs']:>5}{100 * c['axis_coverage']:>8.1f}"
                  f"{100 * c['norm_coverage']:>8.1f}{ok:>12}"
                  f"{100 * c['raw_axis_coverage']:>10.1f}")  # fmt: skip
        verdicts = verdict_table(rows, half)
        print("\nverdicts (part | error class | verdict: count)")
        for key in sorted(verdicts):
            print(f"  {key}: {verdicts[key]}")
        guesses = guess_table(rows, half)
        for part, g in sorted(guesses.items()):
            print(f"\nguesses ({part}): {g['guesses']}, within 1 deg / 0.5 m {g['within']}, "
                  f"called ok {g['ok']}, false ok {len(g['false_ok'])} {g['false_ok']}, good "
                  f"(0.5 deg / 0.1 m) refused {len(g['good_refused'])} of {g['good']} "
                  f"{g['good_refused']}")  # fmt: skip
        summary[half] = {"coverage": cov, "verdicts": verdicts, "guesses": guesses}
    print(json.dumps(summary))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--out", required=True, help="folder of the cases (kept, resumable)")
    ap.add_argument("--rigs", type=int, default=80, help="synthetic rigs (seeds 0 .. N-1)")
    ap.add_argument("--no-real", dest="real", action="store_false", help="synthetic rigs only")
    ap.add_argument(
        "--phase",
        choices=("calibrate", "report", "guess", "guesses", "analyse", "all"),
        default="all",
    )
    ap.add_argument("--guess-rigs", type=int, default=240,
                    help="guesses phase: one-pair synthetic rigs (seeds 1000 ..)")  # fmt: skip
    ap.add_argument(
        "--cases",
        default="*",
        metavar="GLOB",
        help="report phase: only the cases whose folder matches (real_*: real data)",
    )
    ap.add_argument("--rejudge", nargs="*", metavar="KEY=VALUE",
                    help="analyse: judge the stored reports again with AssessConfig settings "
                    "(tuning; the figures that count come from nbcalib report)")  # fmt: skip
    args = ap.parse_args(argv)
    if args.phase in ("calibrate", "all"):
        phase_calibrate(args)
    if args.phase in ("report", "all"):
        phase_report(args)
    if args.phase in ("guess", "all"):
        phase_guess(args)
    if args.phase == "guesses":  # not in "all": hours of matching on its own
        phase_guesses(args)
    if args.phase in ("analyse", "all"):
        phase_analyse(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
