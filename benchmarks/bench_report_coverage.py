"""Does the report's uncertainty cover the real error as often as it says, and does its verdict
catch bad results? (issue 7, "Done when")

On small synthetic pairs (nbcalib.synthetic; several LiDARs, camera models, scenes and seeds) the
script calibrates from a perturbed start with :func:`nbcalib.registration.refine.refine`, judges
the result with :func:`nbcalib.report.assess` (variance scale 1), and stores everything. Cases:

- ``normal``: start 2-4 cm and 0.3-1 degree from the truth (20 single pairs, 4 double pairs);
- ``far_init``: start 30-45 cm and 6-10 degrees away ("initial guess and result far apart");
- ``few_points``: the cloud cut to 150 points ("too few points in view");
- ``mismatched``: the image of another scene ("image and LiDAR share no information");
- ``garbage``: a result 6-10 cm and 1.5-3 degrees off, not refined ("not at a minimum").

Analysis (``--analyse``, also run at the end): cases alternate between a *tuning* half and a
*check* half. The variance scale is chosen on the tuning half's normal cases that reached the
right basin (error < 5 cm and < 1 degree) so that 95 % of their per-axis errors fall inside the
stated 95 % intervals; coverage (per axis and of the error norms) and verdict accuracy are then
reported on the check half. A result counts as *bad* when it is a deliberately bad case or its
error exceeds 5 cm or 1 degree; the verdict is right when bad <=> "suspect".

Run:   python benchmarks/bench_report_coverage.py [--out DIR] [--quick]   (DIR: temp dir by default)
       python benchmarks/bench_report_coverage.py --analyse      # tables from stored cases
Resumable: stored cases are skipped. The last line printed is one JSON object of the figures.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import platform
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from nbcalib.metrics import pose_errors
from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
from nbcalib.report.quality import AXIS_NAMES, AssessConfig, assess, rejudge
from nbcalib.synthetic import RigConfig, generate_sequence
from nbcalib.transforms import invert_T, se3_exp, se3_log

IMAGE_SIZE = (400, 300)
MAX_POINTS = 20000
GOOD_TRANSLATION = 0.05  # a result within 5 cm and 1 degree reached the right basin
GOOD_ROTATION_DEG = 1.0
#: the default refinement with serial kernels (the parallel ones burn CPU on a loaded machine)
#: and at most 6 outer iterations
REFINE = RefineConfig(max_outer=6, parallel=False)
ASSESS = AssessConfig(scale=1.0)

LIDARS = ("spinning16", "spinning32", "spinning64", "spinning128", "livox")
CAMERAS = ("pinhole", "plumb_bob", "fisheye", "omnidir", "rational_polynomial", "atan")


def case_list(quick: bool) -> list[dict]:
    """Every case: kind, rig (lidar, camera, scene, seed), pairs, perturbation seed."""
    cases = []
    n_single = 6 if quick else 20
    for i in range(n_single):
        cases.append(
            dict(
                kind="normal",
                lidar=LIDARS[i % len(LIDARS)],
                camera=CAMERAS[i % len(CAMERAS)],
                scene=("room", "street")[(i // 2) % 2],
                seed=100 + i,
                pairs=1,
            )
        )
    for i in range(1 if quick else 4):
        cases.append(
            dict(
                kind="normal",
                lidar=LIDARS[(i + 2) % len(LIDARS)],
                camera=CAMERAS[(i + 1) % len(CAMERAS)],
                scene=("street", "room")[i % 2],
                seed=200 + i,
                pairs=2,
            )
        )
    bad = {"far_init": 3, "few_points": 2, "mismatched": 2, "garbage": 2}
    for kind, count in bad.items():
        for i in range(1 if quick else count):
            j = 3 * i + len(kind)  # spread over the rigs
            cases.append(
                dict(
                    kind=kind,
                    lidar=LIDARS[j % len(LIDARS)],
                    camera=CAMERAS[j % len(CAMERAS)],
                    scene=("room", "street")[i % 2],
                    seed=300 + 10 * len(kind) + i,
                    pairs=1,
                )
            )
    for k, case in enumerate(cases):
        case["name"] = f"{k:02d}_{case['kind']}_{case['lidar']}_{case['camera']}_{case['scene']}"
        case["half"] = "tune" if k % 2 == 0 else "check"
    return cases


def make_pair(case: dict, pair: int, rng: np.random.Generator) -> tuple[RegistrationPair, dict]:
    """One small synthetic pair (subsampled cloud, small image) and its ground truth."""
    lidar = case["lidar"]
    config = RigConfig(
        lidar=lidar,
        camera=case["camera"],
        scene=case["scene"],
        seed=case["seed"],
        image_size=IMAGE_SIZE,
        duration=1.0 if lidar == "livox" else 0.3,
    )
    seq = generate_sequence(config, pair=pair)
    points, intensities = seq.dense_cloud()
    # the half-space in front of the camera (a 360-degree cloud wastes most points otherwise)
    T = seq.T_camera_lidar
    ahead = points @ T[2, :3] + T[2, 3] > 0.0
    points, intensities = points[ahead], intensities[ahead]
    if len(points) > MAX_POINTS:
        keep = rng.choice(len(points), MAX_POINTS, replace=False)
        points, intensities = points[keep], intensities[keep]
    image = seq.image if seq.image.ndim == 2 else seq.image.mean(axis=2).astype(np.uint8)
    rp = RegistrationPair(
        seq.camera,
        equalize_image(image),
        points,
        equalize_point_intensities(intensities),
        name=f"{case['name']}#{pair}",
    )
    return rp, {"T_camera_lidar": seq.T_camera_lidar}


def random_delta(rng, translation_range, rotation_range_deg) -> np.ndarray:
    """A tangent vector with a random direction and magnitudes drawn from the ranges."""
    v = rng.standard_normal(3)
    w = rng.standard_normal(3)
    v *= rng.uniform(*translation_range) / np.linalg.norm(v)
    w *= math.radians(rng.uniform(*rotation_range_deg)) / np.linalg.norm(w)
    return np.concatenate([v, w])


def run_case(case: dict, other_image=None) -> dict:
    """Build the case's pairs, calibrate, assess (scale 1); returns the stored record."""
    rng = np.random.default_rng(case["seed"])
    t0, c0 = time.perf_counter(), time.process_time()
    pairs, truth = [], None
    for p in range(case["pairs"]):
        pair, gt = make_pair(case, p, rng)
        pairs.append(pair)
        truth = gt["T_camera_lidar"]
    kind = case["kind"]
    if kind == "few_points":
        pairs = [
            replace(p, points_lidar=p.points_lidar[:150], intensities=p.intensities[:150])
            for p in pairs
        ]
    if kind == "mismatched":
        pairs = [replace(p, image=other_image) for p in pairs]
    t_data = time.perf_counter() - t0
    if kind == "far_init":
        delta = random_delta(rng, (0.30, 0.45), (6.0, 10.0))
    elif kind == "garbage":
        delta = random_delta(rng, (0.06, 0.10), (1.5, 3.0))
    else:
        delta = random_delta(rng, (0.02, 0.04), (0.3, 1.0))
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
        cpu_seconds=dict(refine=c_refine, assess=c_assess, total=time.process_time() - c0),
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
    """Variance scale putting ``confidence`` of the pooled per-axis |error| / sigma inside."""
    from scipy.stats import norm

    z = float(norm.ppf(0.5 + confidence / 2))
    ratios = []
    for r in records:
        sigma = rejudge(r["quality"], ASSESS).sigma
        ratios.extend(np.abs(r["error_delta"]) / sigma)
    return float((np.quantile(ratios, confidence) / z) ** 2)


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
            records.append(pickle.load(f))
    if not records:
        raise SystemExit(f"no stored cases in {out / 'cases'}")
    confidence = AssessConfig().confidence

    def basin_ok(r):
        return r["case"]["kind"] == "normal" and not is_bad(r)

    tune = [r for r in records if r["case"]["half"] == "tune"]
    check = [r for r in records if r["case"]["half"] == "check"]
    scale = tune_scale([r for r in tune if basin_ok(r)], confidence)
    acfg = replace(ASSESS, scale=scale)
    figures = dict(
        scale=scale,
        cases=len(records),
        pairs=int(sum(r["case"]["pairs"] for r in records)),
        coverage_check_basin_ok=coverage([r for r in check if basin_ok(r)], acfg),
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
    v_check, v_all = verdict_table(check, acfg), verdict_table(records, acfg)
    for key in ("accuracy", "caught_bad", "missed_bad", "false_alarms", "passed_good", "n"):
        figures[f"verdict_check_{key}"] = v_check[key]
        figures[f"verdict_all_{key}"] = v_all[key]
    cpu = [r["cpu_seconds"]["total"] for r in records]
    wall = [r["seconds"]["total"] for r in records]
    figures["cpu_seconds_total"] = float(np.sum(cpu))
    figures["wall_seconds_total"] = float(np.sum(wall))
    figures["assess_cpu_seconds_median"] = float(
        np.median([r["cpu_seconds"]["assess"] for r in records])
    )

    lines = case_table(v_all["rows"])
    print("\n".join(lines))
    print(json.dumps({k: v for k, v in figures.items()}, default=float))
    if section is not None:
        write_section(section, figures, lines, records)
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
        plural = "s" if r["case"]["pairs"] > 1 else ""
        lines.append(
            f"| {r['case']['name']} ({r['case']['pairs']} pair{plural})"
            f" | {r['case']['half']} | {100 * e['translation_error_m']:.1f} / "
            f"{e['rotation_error_deg']:.2f} | {u['translation_total_cm']:.1f} / "
            f"{u['rotation_total_deg']:.2f} | {q.verdict} ({'bad' if bad else 'good'}) | "
            f"{reasons[:160]} |"
        )
    return lines


def write_section(path: Path, figures: dict, lines: list[str], records: list[dict]) -> None:
    """The markdown section for docs/BENCHMARKS.md (numbers; the narrative is added by hand)."""

    def cov_row(name, c):
        if c.get("n", 0) == 0:
            return f"| {name} | 0 | - | - | - | - |"
        axes = " / ".join(f"{100 * c[a]:.0f}" for a in AXIS_NAMES)
        return (
            f"| {name} | {c['n']} | {axes} | {100 * c['per_axis_pooled']:.0f} % | "
            f"{100 * c['translation_total']:.0f} % | {100 * c['rotation_total']:.0f} % |"
        )

    loads = [r["loadavg"] for r in records if r["loadavg"]]
    text = [
        "## Report: uncertainty coverage and verdict accuracy (issue 7)",
        "",
        f"`python benchmarks/bench_report_coverage.py` ({time.strftime('%Y-%m-%d')}, "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; load average "
        f"during the run {loads[0][0] if loads else '?'} .. {loads[-1][0] if loads else '?'}).",
        f"{figures['cases']} cases, {figures['pairs']} synthetic pairs "
        f"({IMAGE_SIZE[0]} x {IMAGE_SIZE[1]} images, <= {MAX_POINTS} points each); "
        f"{figures['cpu_seconds_total']:.0f} s CPU, {figures['wall_seconds_total']:.0f} s wall; "
        f"assess() {figures['assess_cpu_seconds_median']:.1f} s CPU per case (median).",
        "",
        f"Variance scale tuned on the tuning half: **{figures['scale']:.3g}**.",
        "",
        "Coverage of the stated 95 % intervals (per axis tx/ty/tz/rx/ry/rz in %, pooled, and of "
        "the error norms):",
        "",
        "| cases | n | per axis % | pooled | |t| | |r| |",
        "|---|---|---|---|---|---|",
        cov_row("check half, right basin", figures["coverage_check_basin_ok"]),
        cov_row("check half, verdict ok", figures["coverage_check_verdict_ok"]),
        cov_row("check half, all normal", figures["coverage_check_all_normal"]),
        cov_row("tuning half, right basin", figures["coverage_tune_basin_ok"]),
        "",
        "Verdict (bad = deliberately bad case, or error > 5 cm or > 1 deg):",
        "",
        "| cases | n | accuracy | bad caught | bad missed | false alarms | good passed |",
        "|---|---|---|---|---|---|---|",
    ]
    for half in ("check", "all"):
        f = figures
        text.append(
            f"| {half} | {f[f'verdict_{half}_n']} | {100 * f[f'verdict_{half}_accuracy']:.0f} % "
            f"| {f[f'verdict_{half}_caught_bad']} | {f[f'verdict_{half}_missed_bad']} | "
            f"{f[f'verdict_{half}_false_alarms']} | {f[f'verdict_{half}_passed_good']} |"
        )
    text += ["", "Every case:", "", *lines, ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(text))
    print(f"wrote {path}")


def main():
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--out", type=Path, default=Path(tempfile.gettempdir()) / "nbcalib_report_bench"
    )
    ap.add_argument(
        "--section", type=Path, default=None, help="markdown tables (default: OUT/report.md)"
    )
    ap.add_argument("--quick", action="store_true", help="a handful of cases (smoke test)")
    ap.add_argument("--analyse", action="store_true", help="only analyse stored cases")
    args = ap.parse_args()
    args.section = args.section or args.out / "report.md"
    if not args.analyse:
        (args.out / "cases").mkdir(parents=True, exist_ok=True)
        cases = case_list(args.quick)
        images = {}
        for case in cases:
            path = args.out / "cases" / f"{case['name']}.pkl"
            if path.exists():
                continue
            other = None
            if case["kind"] == "mismatched":  # the image of another scene, same camera
                donor = dict(
                    case,
                    scene="street" if case["scene"] == "room" else "room",
                    seed=case["seed"] + 1000,
                    name=case["name"] + "_donor",
                )
                other = images.get(donor["name"])
                if other is None:
                    other = make_pair(donor, 0, np.random.default_rng(0))[0].image
            t0 = time.perf_counter()
            record = run_case(case, other)
            with open(path.with_suffix(".tmp"), "wb") as f:
                pickle.dump(record, f)
            os.replace(path.with_suffix(".tmp"), path)
            e, q = record["errors"], record["quality"]
            print(
                f"{case['name']}: error {100 * e['translation_error_m']:.1f} cm "
                f"{e['rotation_error_deg']:.2f} deg, {q.verdict} {q.reasons}, "
                f"{time.perf_counter() - t0:.0f} s wall, "
                f"{record['cpu_seconds']['total']:.0f} s CPU, load {record['loadavg']}",
                flush=True,
            )
    analyse(args.out, args.section)


if __name__ == "__main__":
    main()
