"""Does the report's uncertainty cover the real error as often as it says, and does its verdict
catch bad results? (issue 7, "Done when")

On synthetic pairs (nbcalib.synthetic; several LiDARs, camera models, scenes and seeds) the
script calibrates from a perturbed start with :func:`nbcalib.registration.refine.refine`, judges
the result with :func:`nbcalib.report.assess` (variance scale 1), and stores everything.

By default the pairs are of the size ``nbcalib demo`` makes (640 x 480 images, 1 s of LiDAR data,
the whole cloud on a 0.02 m voxel grid: :func:`nbcalib.odometry.voxel_deduplicate`
of the scans deskewed with the true trajectory, points nearer than 1 m dropped, as preprocess
does; intensities and image equalised) and fine registration runs with the default
``RefineConfig`` on serial kernels. ``--image-size 400x300 --max-points 20000 --duration 0.3``
gives small pairs like those of the first measurement (the cloud cut to the half-space in front
of the camera, then subsampled). Cases:

- ``normal``: start 2-5 cm and 0.3-1 degree from the truth (``--singles`` single pairs,
  ``--multi`` cases of ``--multi-pairs`` pairs);
- ``far_init``: start 30-45 cm and 6-10 degrees away ("initial guess and result far apart");
- ``few_points``: the cloud cut to 150 points in front of the camera ("too few points in view");
- ``mismatched``: the image of another scene ("image and LiDAR share no information");
- ``garbage``: a result 6-10 cm and 1.5-3 degrees off, not refined ("not at a minimum");
- ``odd_pair``: ``--multi-pairs`` pairs, the last with the image of another scene ("pairs
  disagree").

Analysis (``--analyse``, also run at the end): cases alternate between a *tuning* half and a
*check* half. The variance scale is chosen on the tuning half's normal cases that reached the
right basin (error < 5 cm and < 1 degree) so that 95 % of their per-axis errors fall inside the
stated 95 % intervals; coverage (per axis and of the error norms) and verdict accuracy are then
reported on the check half. A result counts as *bad* when it is a deliberately bad case or its
error exceeds 5 cm or 1 degree; the verdict is right when bad <=> "suspect".

Run:   python benchmarks/bench_report_coverage.py [--out DIR] [--quick]   (DIR: temp dir by default)
       python benchmarks/bench_report_coverage.py --analyse      # tables from stored cases
Resumable: stored cases are skipped (the settings are stored in DIR/settings.json and a resume
with other settings is refused). Times are CPU times of this process (user + sys); the last
line printed is one JSON object of the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import tempfile
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from nbcalib.metrics import pose_errors
from nbcalib.odometry import voxel_deduplicate
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
from nbcalib.report.quality import AXIS_NAMES, AssessConfig, assess, rejudge
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import invert_T, se3_exp, se3_log

GOOD_TRANSLATION = 0.05  # a result within 5 cm and 1 degree reached the right basin
GOOD_ROTATION_DEG = 1.0
#: the default refinement with serial kernels (the parallel ones burn CPU on a loaded machine)
REFINE = RefineConfig(parallel=False)
ASSESS = AssessConfig(scale=1.0)
PREPROCESS = PreprocessConfig()

LIDARS = ("livox", "spinning64", "spinning32", "spinning128", "spinning16")
CAMERAS = ("pinhole", "plumb_bob", "fisheye", "omnidir")
BAD_CAMERAS = ("pinhole", "plumb_bob", "fisheye", "omnidir", "rational_polynomial", "atan")


@dataclass(frozen=True)
class Settings:
    """How the pairs are made and how many cases there are (stored with the cases)."""

    image_size: tuple[int, int] = (640, 480)
    voxel_size: float = 0.02
    max_points: int = 0  # 0: the whole cloud; else the front half-space subsampled to this
    duration: float = 1.0
    singles: int = 20
    multi: int = 12
    multi_pairs: int = 3


def case_list(settings: Settings, quick: bool) -> list[dict]:
    """Every case: kind, rig (lidar, camera, scene, seed), pairs, perturbation seed."""
    cases = []
    n_single = 4 if quick else settings.singles
    for i in range(n_single):
        cases.append(
            dict(
                kind="normal",
                lidar=LIDARS[i % len(LIDARS)],
                camera=CAMERAS[(i // 2) % len(CAMERAS)],
                scene=("room", "street")[(i // 4) % 2],
                seed=100 + i,
                pairs=1,
            )
        )
    for i in range(2 if quick else settings.multi):
        cases.append(
            dict(
                kind="normal",
                lidar=LIDARS[i % len(LIDARS)],
                camera=CAMERAS[(i // 2) % len(CAMERAS)],
                scene=("room", "street")[(i // 4) % 2],
                seed=200 + i,
                pairs=settings.multi_pairs,
            )
        )
    bad = {"far_init": 3, "few_points": 2, "mismatched": 2, "garbage": 2, "odd_pair": 2}
    for b, (kind, count) in enumerate(bad.items()):
        for i in range(1 if quick else count):
            j = 3 * i + len(kind)  # spread over the rigs
            cases.append(
                dict(
                    kind=kind,
                    lidar=LIDARS[j % len(LIDARS)],
                    camera=BAD_CAMERAS[j % len(BAD_CAMERAS)],
                    scene=("room", "street")[i % 2],
                    seed=300 + 10 * b + i,
                    pairs=settings.multi_pairs if kind == "odd_pair" else 1,
                )
            )
    for k, case in enumerate(cases):
        case["name"] = (
            f"{k:02d}_{case['kind']}_{case['lidar']}_{case['camera']}_{case['scene']}"
            f"_{case['pairs']}p"
        )
        case["half"] = "tune" if k % 2 == 0 else "check"
    return cases


def make_pair(
    case: dict, pair: int, rng: np.random.Generator, settings: Settings
) -> tuple[RegistrationPair, dict]:
    """One synthetic pair as preprocess would make it, and its ground truth."""
    config = RigConfig(
        lidar=case["lidar"],
        camera=case["camera"],
        scene=case["scene"],
        seed=case["seed"],
        image_size=settings.image_size,
        duration=settings.duration,
    )
    seq = generate_sequence(config, pair=pair)
    points, intensities = seq.dense_cloud()
    far = np.linalg.norm(points, axis=1) >= PREPROCESS.min_distance
    points, intensities = voxel_deduplicate(
        points[far], intensities[far], voxel_size=settings.voxel_size
    )
    T = seq.T_camera_lidar
    if settings.max_points:
        # the half-space in front of the camera (a 360-degree cloud wastes most points otherwise)
        ahead = points @ T[2, :3] + T[2, 3] > 0.0
        points, intensities = points[ahead], intensities[ahead]
        if len(points) > settings.max_points:
            keep = np.sort(rng.choice(len(points), settings.max_points, replace=False))
            points, intensities = points[keep], intensities[keep]
    image = seq.image if seq.image.ndim == 2 else seq.image.mean(axis=2).astype(np.uint8)
    rp = RegistrationPair(
        seq.camera,
        equalize_image(image),
        points,
        equalize_point_intensities(intensities),
        name=f"{case['name']}#{pair}",
    )
    return rp, {"T_camera_lidar": T}


def random_delta(rng, translation_range, rotation_range_deg) -> np.ndarray:
    """A tangent vector with a random direction and magnitudes drawn from the ranges."""
    v = rng.standard_normal(3)
    w = rng.standard_normal(3)
    v *= rng.uniform(*translation_range) / np.linalg.norm(v)
    w *= math.radians(rng.uniform(*rotation_range_deg)) / np.linalg.norm(w)
    return np.concatenate([v, w])


def run_case(case: dict, settings: Settings) -> dict:
    """Build the case's pairs, calibrate, assess (scale 1); returns the stored record."""
    rng = np.random.default_rng(case["seed"])
    t0, c0 = time.perf_counter(), time.process_time()
    pairs, truth = [], None
    for p in range(case["pairs"]):
        pair, gt = make_pair(case, p, rng, settings)
        pairs.append(pair)
        truth = gt["T_camera_lidar"]
    kind = case["kind"]
    if kind == "few_points":  # 150 points in front of the camera
        cut = []
        for p in pairs:
            ahead = np.flatnonzero(p.points_lidar @ truth[2, :3] + truth[2, 3] > 0.0)
            keep = np.sort(rng.choice(ahead, min(150, ahead.size), replace=False))
            cut.append(
                replace(p, points_lidar=p.points_lidar[keep], intensities=p.intensities[keep])
            )
        pairs = cut
    if kind in ("mismatched", "odd_pair"):  # the image of another scene, same camera
        donor = RigConfig(
            lidar=case["lidar"],
            camera=case["camera"],
            scene="street" if case["scene"] == "room" else "room",
            seed=case["seed"] + 1000,
            image_size=settings.image_size,
            duration=0.1,
        )
        image = generate_sequence(donor).image
        image = equalize_image(image if image.ndim == 2 else image.mean(axis=2).astype(np.uint8))
        if kind == "mismatched":
            pairs = [replace(p, image=image) for p in pairs]
        else:  # only the last of several pairs
            pairs[-1] = replace(pairs[-1], image=image)
    t_data, c_data = time.perf_counter() - t0, time.process_time() - c0
    if kind == "far_init":
        delta = random_delta(rng, (0.30, 0.45), (6.0, 10.0))
    elif kind == "garbage":
        delta = random_delta(rng, (0.06, 0.10), (1.5, 3.0))
    else:
        delta = random_delta(rng, (0.02, 0.05), (0.3, 1.0))
    T_init = se3_exp(delta) @ truth
    t1, c1 = time.perf_counter(), time.process_time()
    if kind == "garbage":
        T_est, converged, outer, T_init_used = T_init, None, 0, None
    else:
        try:
            result = refine(pairs, T_init, REFINE)
            T_est, converged, outer = result.T_camera_lidar, result.converged, len(result.history)
        except ValueError as exc:  # e.g. no point in view at all
            print(f"  refine failed: {exc}", flush=True)
            T_est, converged, outer = T_init, False, 0
        T_init_used = T_init
    t_refine, c_refine = time.perf_counter() - t1, time.process_time() - c1
    t2, c2 = time.perf_counter(), time.process_time()
    quality = assess(
        pairs,
        T_est,
        T_init=T_init_used,
        config=REFINE,
        converged=converged,
        assess_config=ASSESS,
    )
    t_assess, c_assess = time.perf_counter() - t2, time.process_time() - c2
    errors = pose_errors(T_est, truth)
    return dict(
        case=case,
        T_true=truth,
        T_init=T_init,
        T_est=T_est,
        error_delta=se3_log(T_est @ invert_T(truth)),
        errors=errors,
        converged=converged,
        outer_iterations=outer,
        quality=quality,
        seconds=dict(data=t_data, refine=t_refine, assess=t_assess, total=time.perf_counter() - t0),
        cpu_seconds=dict(
            data=c_data, refine=c_refine, assess=c_assess, total=time.process_time() - c0
        ),
        points=[len(p.points_lidar) for p in pairs],
        visible_points=[int(v) for v in quality.visible_points],
        settings=asdict(settings),
        loadavg=Path("/proc/loadavg").read_text().split()[:3]
        if Path("/proc/loadavg").exists()
        else [],
    )


# ------------------------------------------------------------------------------ analysis


def is_bad(record: dict) -> bool:
    """Ground truth of the verdict: a deliberately bad case or a result off by > 5 cm / 1 deg."""
    e = record["errors"]
    return (
        record["case"]["kind"] != "normal"
        or e["translation_error_m"] > GOOD_TRANSLATION
        or e["rotation_error_deg"] > GOOD_ROTATION_DEG
    )


def tune_scale(records: list[dict], confidence: float) -> float:
    """Smallest variance scale putting ``confidence`` of the pooled per-axis errors inside.

    The stated interval of an axis is ``z * sigma`` with the covariance ``scale * C + S`` (``S``
    the spread of per-pair optima, not scaled), so the fraction inside grows with the scale; the
    scale is found by bisection on its logarithm.
    """
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + confidence / 2))
    errors = np.array([np.abs(r["error_delta"]) for r in records])

    def inside(scale: float) -> float:
        sigma = np.array(
            [rejudge(r["quality"], replace(ASSESS, scale=scale)).sigma for r in records]
        )
        return float(np.mean(errors <= z * sigma))

    lo, hi = -3.0, 4.0  # log10 of the scale
    if inside(10.0**hi) < confidence:
        return 10.0**hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if inside(10.0**mid) < confidence else (lo, mid)
    return float(10.0**hi)


def coverage(records: list[dict], acfg: AssessConfig) -> dict:
    """Fraction of records whose error lies inside the stated intervals (per axis and norms)."""
    if not records:
        return {"n": 0}
    hits = {name: [] for name in AXIS_NAMES}
    hits["translation_total"], hits["rotation_total"] = [], []
    for r in records:
        q = rejudge(r["quality"], acfg)
        u = q.uncertainty
        half = np.concatenate(
            [np.array(u["translation_cm"]) / 100.0, np.radians(u["rotation_deg"])]
        )
        d = r["error_delta"]
        for a, name in enumerate(AXIS_NAMES):
            hits[name].append(abs(d[a]) <= half[a])
        hits["translation_total"].append(np.linalg.norm(d[:3]) <= u["translation_total_cm"] / 100.0)
        hits["rotation_total"].append(
            math.degrees(np.linalg.norm(d[3:])) <= u["rotation_total_deg"]
        )
    out = {k: float(np.mean(v)) for k, v in hits.items()}
    out["per_axis_pooled"] = float(np.mean([np.mean(hits[a]) for a in AXIS_NAMES]))
    out["n"] = len(records)
    return out


def verdict_table(records: list[dict], acfg: AssessConfig) -> dict:
    """Confusion counts and accuracy of the verdict, and the reasons given per case."""
    rows, tp, tn, fp, fn = [], 0, 0, 0, 0
    for r in records:
        q = rejudge(r["quality"], acfg)
        bad, suspect = is_bad(r), q.verdict == "suspect"
        tp += bad and suspect
        tn += (not bad) and (not suspect)
        fp += (not bad) and suspect
        fn += bad and not suspect
        rows.append((r, q, bad))
    n = max(len(records), 1)
    return dict(
        rows=rows,
        accuracy=(tp + tn) / n,
        caught_bad=tp,
        missed_bad=fn,
        false_alarms=fp,
        passed_good=tn,
        n=len(records),
    )


def analyse(out: Path, section: Path | None) -> dict:
    """Tune on one half, report on the other; print tables; write the markdown section."""
    records = []
    for path in sorted((out / "cases").glob("*.pkl")):
        with open(path, "rb") as f:
            record = pickle.load(f)
        # cases stored before Quality.pair_remeasured existed (none was measured again)
        q = record["quality"]
        q.__dict__.setdefault("pair_remeasured", np.zeros(len(q.names), dtype=np.int64))
        q.__dict__.setdefault("pair_hessians_raw", q.pair_hessians)
        records.append(record)
    if not records:
        raise SystemExit(f"no stored cases in {out / 'cases'}")
    confidence = AssessConfig().confidence

    def basin_ok(r):
        return r["case"]["kind"] == "normal" and not is_bad(r)

    tune = [r for r in records if r["case"]["half"] == "tune"]
    check = [r for r in records if r["case"]["half"] == "check"]
    scale = tune_scale([r for r in tune if basin_ok(r)], confidence)
    acfg = replace(ASSESS, scale=scale)
    good_check = [r for r in check if basin_ok(r)]
    figures = dict(
        scale=scale,
        # the same tuning on the other half: how much the scale depends on the cases
        scale_if_tuned_on_check=tune_scale(good_check, confidence) if good_check else None,
        cases=len(records),
        pairs=int(sum(r["case"]["pairs"] for r in records)),
        normal_cases=sum(r["case"]["kind"] == "normal" for r in records),
        normal_right_basin=sum(basin_ok(r) for r in records),
        coverage_check_basin_ok=coverage(good_check, acfg),
        coverage_check_basin_ok_1pair=coverage(
            [r for r in good_check if r["case"]["pairs"] == 1], acfg
        ),
        coverage_check_basin_ok_multi=coverage(
            [r for r in good_check if r["case"]["pairs"] > 1], acfg
        ),
        coverage_check_verdict_ok=coverage(
            [
                r
                for r in check
                if r["case"]["kind"] == "normal" and rejudge(r["quality"], acfg).verdict == "ok"
            ],
            acfg,
        ),
        coverage_check_all_normal=coverage(
            [r for r in check if r["case"]["kind"] == "normal"], acfg
        ),
        coverage_tune_basin_ok=coverage([r for r in tune if basin_ok(r)], acfg),
    )
    # the halves swapped: a second held-out figure, to show how much it depends on the cases
    if figures["scale_if_tuned_on_check"] is not None:
        figures["coverage_tune_basin_ok_swapped"] = coverage(
            [r for r in tune if basin_ok(r)],
            replace(ASSESS, scale=figures["scale_if_tuned_on_check"]),
        )
    else:
        figures["coverage_tune_basin_ok_swapped"] = {"n": 0}
    v_check, v_all = verdict_table(check, acfg), verdict_table(records, acfg)
    for key in ("accuracy", "caught_bad", "missed_bad", "false_alarms", "passed_good", "n"):
        figures[f"verdict_check_{key}"] = v_check[key]
        figures[f"verdict_all_{key}"] = v_all[key]
    figures["cpu_seconds_total"] = float(sum(r["cpu_seconds"]["total"] for r in records))
    figures["wall_seconds_total"] = float(sum(r["seconds"]["total"] for r in records))
    for what in ("refine", "assess"):
        for label, sel in (("1pair", lambda r: r["case"]["pairs"] == 1), ("multi", None)):
            chosen = [
                r["cpu_seconds"][what]
                for r in records
                if (sel(r) if sel else r["case"]["pairs"] > 1)
            ]
            figures[f"{what}_cpu_seconds_median_{label}"] = (
                float(np.median(chosen)) if chosen else None
            )
    loads = [float(r["loadavg"][0]) for r in records if r["loadavg"]]
    figures["load_min"] = min(loads) if loads else None
    figures["load_max"] = max(loads) if loads else None
    figures["settings"] = records[0].get("settings")

    lines = case_table(v_all["rows"])
    print("\n".join(lines))
    print(json.dumps({k: v for k, v in figures.items()}, default=float))
    if section is not None:
        write_section(section, figures, lines)
    return figures


def case_table(rows) -> list[str]:
    """Markdown table: one line per case."""
    lines = [
        "| case | half | error cm / deg | stated 95 % cm / deg | verdict (truth) | reasons |",
        "|---|---|---|---|---|---|",
    ]
    for r, q, bad in rows:
        e, u = r["errors"], q.uncertainty
        reasons = "; ".join(q.reasons) if q.reasons else "-"
        lines.append(
            f"| {r['case']['name']} | {r['case']['half']} | "
            f"{100 * e['translation_error_m']:.2f} / {e['rotation_error_deg']:.3f} | "
            f"{u['translation_total_cm']:.2f} / {u['rotation_total_deg']:.3f} | "
            f"{q.verdict} ({'bad' if bad else 'good'}) | {reasons[:160]} |"
        )
    return lines


def write_section(path: Path, figures: dict, lines: list[str]) -> None:
    """The markdown tables for docs/BENCHMARKS.md (numbers; the narrative is added by hand)."""

    def cov_row(name, c):
        if c.get("n", 0) == 0:
            return f"| {name} | 0 | - | - | - | - |"
        axes = " / ".join(f"{100 * c[a]:.0f}" for a in AXIS_NAMES)
        return (
            f"| {name} | {c['n']} | {axes} | {100 * c['per_axis_pooled']:.0f} % | "
            f"{100 * c['translation_total']:.0f} % | {100 * c['rotation_total']:.0f} % |"
        )

    f = figures
    st = f["settings"] or {}
    size = st.get("image_size", ("?", "?"))
    points = "whole cloud" if not st.get("max_points") else f"<= {st['max_points']} points in front"
    text = [
        f"{f['cases']} cases, {f['pairs']} synthetic pairs ({size[0]} x {size[1]} images, "
        f"{st.get('duration', '?')} s of LiDAR, voxel {st.get('voxel_size', '?')} m, {points}); "
        f"{f['normal_right_basin']} of {f['normal_cases']} normal cases in the right basin. "
        f"CPU {f['cpu_seconds_total']:.0f} s in all ({f['wall_seconds_total']:.0f} s wall, "
        f"1-minute load {f['load_min']} .. {f['load_max']}); median CPU per case: refine "
        f"{f['refine_cpu_seconds_median_1pair']:.1f} s (1 pair) / "
        f"{f['refine_cpu_seconds_median_multi'] or 0:.1f} s (multi), assess "
        f"{f['assess_cpu_seconds_median_1pair']:.1f} s / "
        f"{f['assess_cpu_seconds_median_multi'] or 0:.1f} s.",
        "",
        f"Variance scale tuned on the tuning half: **{f['scale']:.3g}** (the same tuning on the "
        f"check half would give {f['scale_if_tuned_on_check'] or float('nan'):.3g}).",
        "",
        "Coverage of the stated 95 % intervals (per axis tx/ty/tz/rx/ry/rz in %, pooled, and of "
        "the error norms):",
        "",
        "| cases | n | per axis % | pooled | |t| | |r| |",
        "|---|---|---|---|---|---|",
        cov_row("check half, right basin", f["coverage_check_basin_ok"]),
        cov_row("... of which 1 pair", f["coverage_check_basin_ok_1pair"]),
        cov_row("... of which several pairs", f["coverage_check_basin_ok_multi"]),
        cov_row("check half, verdict ok", f["coverage_check_verdict_ok"]),
        cov_row("check half, all normal", f["coverage_check_all_normal"]),
        cov_row("tuning half, right basin", f["coverage_tune_basin_ok"]),
        cov_row(
            "halves swapped: tuning half, right basin, check half's scale",
            f["coverage_tune_basin_ok_swapped"],
        ),
        "",
        "Verdict (bad = deliberately bad case, or error > 5 cm or > 1 deg):",
        "",
        "| cases | n | accuracy | bad caught | bad missed | false alarms | good passed |",
        "|---|---|---|---|---|---|---|",
    ]
    for half in ("check", "all"):
        text.append(
            f"| {half} | {f[f'verdict_{half}_n']} | {100 * f[f'verdict_{half}_accuracy']:.0f} % "
            f"| {f[f'verdict_{half}_caught_bad']} | {f[f'verdict_{half}_missed_bad']} | "
            f"{f[f'verdict_{half}_false_alarms']} | {f[f'verdict_{half}_passed_good']} |"
        )
    text += ["", "Every case:", "", *lines, ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(text))
    print(f"wrote {path}")


def parse_size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    d = Settings()
    ap.add_argument(
        "--out", type=Path, default=Path(tempfile.gettempdir()) / "nbcalib_report_bench"
    )
    ap.add_argument(
        "--section", type=Path, default=None, help="markdown tables (default: OUT/report.md)"
    )
    ap.add_argument("--quick", action="store_true", help="a handful of cases (smoke test)")
    ap.add_argument("--analyse", action="store_true", help="only analyse stored cases")
    ap.add_argument("--image-size", type=parse_size, default=d.image_size, metavar="WxH")
    ap.add_argument("--voxel-size", type=float, default=d.voxel_size, help="dense cloud voxel, m")
    ap.add_argument(
        "--max-points",
        type=int,
        default=d.max_points,
        help="0: the whole cloud; else its front half-space subsampled to this many points",
    )
    ap.add_argument("--duration", type=float, default=d.duration, help="LiDAR seconds per pair")
    ap.add_argument("--singles", type=int, default=d.singles, help="normal one-pair cases")
    ap.add_argument("--multi", type=int, default=d.multi, help="normal multi-pair cases")
    ap.add_argument("--multi-pairs", type=int, default=d.multi_pairs, help="pairs of those")
    args = ap.parse_args()
    args.section = args.section or args.out / "report.md"
    if not args.analyse:
        settings = Settings(
            image_size=tuple(args.image_size),
            voxel_size=args.voxel_size,
            max_points=args.max_points,
            duration=args.duration,
            singles=args.singles,
            multi=args.multi,
            multi_pairs=args.multi_pairs,
        )
        (args.out / "cases").mkdir(parents=True, exist_ok=True)
        stored = args.out / "settings.json"
        wanted = json.loads(json.dumps(asdict(settings)))
        if stored.exists() and json.loads(stored.read_text()) != wanted:
            raise SystemExit(
                f"{args.out} holds cases made with other settings ({stored.read_text().strip()});"
                " use another --out"
            )
        stored.write_text(json.dumps(wanted) + "\n")
        for case in case_list(settings, args.quick):
            path = args.out / "cases" / f"{case['name']}.pkl"
            if path.exists():
                continue
            record = run_case(case, settings)
            with open(path.with_suffix(".tmp"), "wb") as f:
                pickle.dump(record, f)
            os.replace(path.with_suffix(".tmp"), path)
            e, q, c = record["errors"], record["quality"], record["cpu_seconds"]
            print(
                f"{case['name']}: error {100 * e['translation_error_m']:.2f} cm "
                f"{e['rotation_error_deg']:.3f} deg, stated "
                f"{q.uncertainty['translation_total_cm']:.2f} cm "
                f"{q.uncertainty['rotation_total_deg']:.3f} deg (scale 1), {q.verdict} "
                f"{q.reasons}, CPU {c['total']:.0f} s (refine {c['refine']:.0f}, assess "
                f"{c['assess']:.0f}), {record['seconds']['total']:.0f} s wall, "
                f"load {record['loadavg']}",
                flush=True,
            )
    analyse(args.out, args.section)


if __name__ == "__main__":
    main()
