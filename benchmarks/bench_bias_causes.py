"""Where the real data's walk comes from (issue 28): three tests on the sets of bench_bias.py.

``bench_bias.py`` measures how far fine registration walks from each real set's reference. This
script asks *why*, in-process with the code ``nbcalib calibrate`` runs (:func:`refine` on the
pairs of each preprocessed work directory, default settings), on the work directories that
``bench_bias.py --parts real --keep DIR`` left in ``DIR/real``:

1. **Systematic or random.** The walk of every set as a vector in the reference camera's frame
   (camera centre moved right / down / forward, cm; rotation about those axes, deg). Per group
   of sets (one rig), the mean and the spread of each component over its frames: a mean much
   larger than its spread is an offset shared by every frame of the rig (the reference, the
   sensors' models or timing), a spread much larger than the mean is each frame's own error.
2. **The camera's focal length.** The walk again with ``fx, fy`` scaled by ``--scales`` (the
   principal point and distortion kept): an error of the intrinsics that the extrinsic has to
   absorb shows as a walk that vanishes at some scale other than 1, with a lower NID there.
3. **Can the cost tell?** From each of ``--perturbations`` starts 1 deg / 5 cm from the reference
   (the starts of bench_bias.py), the run's end against the walk's end, both on the cost built
   at the walk's end (its visible points and regions): when the run from afar ends on a cost as
   low as the walk's, or lower, the pair holds no information that prefers the walk's end, and
   no optimiser can bring the run back.

``--set KEY=VALUE`` (repeatable) changes a fine-registration setting (a field of
:class:`~nbcalib.registration.config.RefineConfig`) for every run, so that a lever that is a
setting is measured on the same inputs; ``--parts synthetic`` adds the synthetic cases that
``bench_bias.py --keep DIR`` left (their walk and their start 1.5 deg / 7 cm off, as there).

Run:  python benchmarks/bench_bias.py --parts real --keep DIR         # the inputs, once
      python benchmarks/bench_bias_causes.py DIR [--scales 0.99,1.01] [--sets acfr,waymo]
      python benchmarks/bench_bias_causes.py DIR --parts synthetic,real --scales "" \
          --perturbations 3 --set nelder_mead_init_step=0.02          # a lever
Prints the tables, then one JSON line with every figure.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from bench_bias import DATA, offset_start, real_sets

from nbcalib.camera import create_camera
from nbcalib.config import CalibrationConfig, set_values
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.registration.config import RefineConfig
from nbcalib.registration.costs import build_cost
from nbcalib.registration.refine import RegistrationPair, refine
from nbcalib.transforms import invert_T, pose_error, so3_log
from nbcalib.workdir import WorkDir

AXES = ("right", "down", "forward")


def load_pairs(work: Path) -> list[RegistrationPair]:
    """The pairs ``nbcalib calibrate`` registers (camera and files of the work directory)."""
    wd = WorkDir(work)
    camera = wd.require_preprocessed().camera_model()
    return [
        RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name)
        for p in wd.load_pairs()
    ]


def scaled(pairs, scale: float) -> list[RegistrationPair]:
    """The pairs with the camera's focal lengths times ``scale``."""
    if scale == 1.0:
        return pairs
    cam = pairs[0].camera
    intrinsics = np.array(cam.intrinsics, dtype=np.float64)
    intrinsics[:2] *= scale
    camera = create_camera(cam.model, intrinsics, cam.distortion_coeffs, cam.width, cam.height)
    return [RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name) for p in pairs]


def walk_vector(T, T_ref) -> tuple[np.ndarray, np.ndarray]:
    """Camera centre moved (cm) and rotation (deg), both in the reference camera's axes."""
    centre = invert_T(T)[:3, 3] - invert_T(T_ref)[:3, 3]
    rotation = np.degrees(so3_log(T[:3, :3] @ T_ref[:3, :3].T))
    return 100.0 * T_ref[:3, :3] @ centre, rotation


def errors(T, T_ref) -> tuple[float, float]:
    dt, dr = pose_error(invert_T(T), invert_T(T_ref))
    return 100.0 * float(dt), float(dr)


def run_set(group, name, work: Path, T_ref, args, config: RefineConfig) -> dict:
    pairs = load_pairs(work)
    row: dict = {"group": group, "set": name}
    walk = refine(pairs, T_ref, config).T_camera_lidar
    t, w = walk_vector(walk, T_ref)
    row["walk"] = dict(zip(("cm", "deg"), errors(walk, T_ref)), t_cm=t.tolist(), w_deg=w.tolist())
    # 2. the focal length
    row["scales"] = {}
    for s in args.scales:
        ps = scaled(pairs, s)
        T = refine(ps, T_ref, config).T_camera_lidar
        cost, _ = build_cost(ps, T, config)
        row["scales"][f"{s:g}"] = dict(zip(("cm", "deg"), errors(T, T_ref)), nid=cost.value(T))
    cost, _ = build_cost(pairs, walk, config)
    row["scales"]["1"] = {**row["walk"], "nid": cost.value(walk)}
    # 3. can the cost tell? every run judged on the cost built at the walk's end
    rng = np.random.default_rng([args.seed, 28])  # bench_bias.py's starts
    row["near"] = []
    for _ in range(args.perturbations):
        T = refine(pairs, offset_start(T_ref, 1.0, 0.05, rng), config).T_camera_lidar
        cm, deg = errors(T, T_ref)
        row["near"].append(
            {"cm": cm, "deg": deg, "nid": cost.value(T), "better": cm < 5.0 and deg < 1.0}
        )
    row["walk"]["nid"] = cost.value(walk)
    return row


def synthetic_cases(keep: Path):
    """(name, work directory, ground truth, seed) of each synthetic case bench_bias.py kept."""
    for folder in sorted(keep.iterdir()):
        work, gt = folder / "work", folder / "synth" / "ground_truth.json"
        parts = folder.name.split("_")
        if (work / "calib.json").is_file() and gt.is_file() and parts[-1].startswith("g"):
            yield folder.name, work, gt, int(parts[3])


def run_synthetic(name, work: Path, gt: Path, seed: int, config: RefineConfig) -> dict:
    """The walk from the truth and the run from 1.5 deg / 7 cm (bench_bias.py's start)."""
    pairs, T_true = load_pairs(work), read_ground_truth(gt)
    rng = np.random.default_rng([seed, 28])
    row = {"set": name}
    for kind, T0 in (("walk", T_true), ("near", offset_start(T_true, 1.5, 0.07, rng))):
        cm, deg = errors(refine(pairs, T0, config).T_camera_lidar, T_true)
        row[kind] = {"cm": cm, "deg": deg}
    return row


def print_synthetic(rows) -> dict:
    walk = [r["walk"] for r in rows]
    near = [r["near"] for r in rows]
    within = sum(n["cm"] <= 1.0 and n["deg"] <= 0.1 for n in near)
    out = {
        "cases": len(rows),
        "walk_median": [float(np.median([w[k] for w in walk])) for k in ("cm", "deg")],
        "walk_max": [float(np.max([w[k] for w in walk])) for k in ("cm", "deg")],
        "near_median": [float(np.median([n[k] for n in near])) for k in ("cm", "deg")],
        "near_within": within,
    }
    print("\n### Synthetic: walk from the truth, run from 1.5 deg / 7 cm\n")
    print(
        "| cases | walk median (max) cm / deg | from 1.5 deg / 7 cm, median "
        "| within 1 cm / 0.1 deg |"
    )
    print("|---:|---|---|---:|")
    print(
        f"| {len(rows)} | {out['walk_median'][0]:.2f} / {out['walk_median'][1]:.3f} "
        f"(max {out['walk_max'][0]:.2f} / {out['walk_max'][1]:.3f}) | "
        f"{out['near_median'][0]:.2f} / {out['near_median'][1]:.3f} | {within} / {len(rows)} |"
    )
    for r in rows:
        for kind in ("walk", "near"):
            if r[kind]["cm"] > 1.0 or r[kind]["deg"] > 0.1:
                print(f"- {r['set']} {kind}: {r[kind]['cm']:.2f} cm / {r[kind]['deg']:.3f} deg")
    return out


def print_tables(rows) -> dict:
    out = {}
    groups = list(dict.fromkeys(r["group"] for r in rows))
    print("\n### 1. The walk's components (reference camera axes): mean +- spread over frames\n")
    head = " | ".join(f"{a} cm" for a in AXES) + " | " + " | ".join(f"about {a} deg" for a in AXES)
    print(f"| rig | frames | {head} |")
    print("|---|---:|" + "---|" * 6)
    for g in groups:
        sel = [r for r in rows if r["group"] == g]
        t = np.array([r["walk"]["t_cm"] for r in sel])
        w = np.array([r["walk"]["w_deg"] for r in sel])
        cells = [f"{m:+.2f} +- {s:.2f}" for m, s in zip(t.mean(0), t.std(0))]
        cells += [f"{m:+.3f} +- {s:.3f}" for m, s in zip(w.mean(0), w.std(0))]
        out[g] = {
            "frames": len(sel),
            "t_mean_cm": t.mean(0).tolist(),
            "t_std_cm": t.std(0).tolist(),
            "w_mean_deg": w.mean(0).tolist(),
            "w_std_deg": w.std(0).tolist(),
        }
        print(f"| {g} | {len(sel)} | {' | '.join(cells)} |")
    scales = sorted({s for r in rows for s in r["scales"]}, key=float)
    print("\n### 2. The walk with the focal length scaled: median cm / deg (median NID)\n")
    print("| rig | " + " | ".join(f"fx, fy x {s}" for s in scales) + " |")
    print("|---|" + "---|" * len(scales))
    for g in groups:
        sel = [r for r in rows if r["group"] == g]
        cells = []
        for s in scales:
            v = [r["scales"][s] for r in sel if s in r["scales"]]
            cm, deg = np.median([x["cm"] for x in v]), np.median([x["deg"] for x in v])
            nid = np.median([x["nid"] for x in v])
            out[g][f"scale_{s}"] = {"median_cm": cm, "median_deg": deg, "median_nid": nid}
            cells.append(f"{cm:.2f} / {deg:.3f} ({nid:.4f})")
        print(f"| {g} | {' | '.join(cells)} |")
    print("\n### 3. Runs from 1 deg / 5 cm, judged on the cost built at the walk's end\n")
    print(
        "| rig | walk: median cm / deg | runs | their end: median cm / deg | better in both "
        "| cost at their end <= at the walk's end |"
    )
    print("|---|---|---:|---|---:|---:|")
    for g in [*groups, "all"]:
        sel = [r for r in rows if g in ("all", r["group"])]
        near = [(n, r["walk"]["nid"]) for r in sel for n in r["near"]]
        walk = [r["walk"] for r in sel]
        w_cm, w_deg = (float(np.median([w[k] for w in walk])) for k in ("cm", "deg"))
        cells = {"walk_median": [w_cm, w_deg], "near_runs": len(near)}
        text = f"| {'**all**' if g == 'all' else g} | {w_cm:.2f} / {w_deg:.3f} | {len(near)} |"
        if near:
            n_cm, n_deg = (float(np.median([n[k] for n, _ in near])) for k in ("cm", "deg"))
            better = sum(n["better"] for n, _ in near)
            low = sum(n["nid"] <= w for n, w in near)
            cells.update(near_median=[n_cm, n_deg], better=better, as_low=low)
            text += f" {n_cm:.2f} / {n_deg:.3f} | {better} | {low} |"
        else:
            text += " | | |"
        out.setdefault(g, {}).update(cells)
        print(text)
    return out


def parse_args(argv=None):
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("keep", type=Path, help="bench_bias.py's --keep folder (its real/ inputs)")
    ap.add_argument("--data", type=Path, default=DATA, help="the real-data folder")
    ap.add_argument("--sets", default="", help="only sets whose name contains one of these")
    ap.add_argument("--scales", default="0.99,1.01", help="focal-length scales besides 1")
    ap.add_argument("--perturbations", type=int, default=3, help="starts per set")
    ap.add_argument("--seed", type=int, default=0, help="seed of the starts (bench_bias.py's)")
    ap.add_argument("--parts", default="real", help="real, synthetic or both")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a fine-registration setting for every run (RefineConfig field; repeatable)",
    )
    args = ap.parse_args(argv)
    args.scales = [float(s) for s in args.scales.split(",") if s and float(s) != 1.0]
    return args


def refine_config(settings) -> RefineConfig:
    """RefineConfig() with ``KEY=VALUE`` settings (values read as JSON, else as strings)."""
    values = {}
    for item in settings:
        key, _, text = item.partition("=")
        try:
            values[f"refine.{key}"] = json.loads(text)
        except json.JSONDecodeError:
            values[f"refine.{key}"] = text
    return set_values(CalibrationConfig(), values).refine


def main(argv=None) -> int:
    args = parse_args(argv)
    parts = set(args.parts.split(","))
    config = refine_config(args.set)
    wanted = [s for s in args.sets.split(",") if s]
    result, t0 = {"settings": args.set}, time.perf_counter()
    if "synthetic" in parts:
        syn = []
        for name, work, gt, seed in synthetic_cases(args.keep):
            if wanted and not any(w in name for w in wanted):
                continue
            syn.append(run_synthetic(name, work, gt, seed, config))
            print(f"{name}: {syn[-1]}", file=sys.stderr, flush=True)
        result["synthetic"] = {"summary": print_synthetic(syn), "rows": syn}
    if "real" in parts and not args.data.is_dir():
        print(f"real data not found at {args.data}: skipped", file=sys.stderr)
    elif "real" in parts:
        result["real"] = real_part(args, config, wanted)
    print(f"{time.perf_counter() - t0:.0f} s")
    print(json.dumps(result))
    return 0


def real_part(args, config: RefineConfig, wanted) -> dict:
    rows = []
    for group, name, _, calib in real_sets(args.data):
        if wanted and not any(w in name for w in wanted):
            continue
        work = args.keep / "real" / name.replace(" ", "_").replace("+", "")
        if not (work / "calib.json").is_file():
            print(f"{name}: no work directory {work} (bench_bias.py --keep)", file=sys.stderr)
            continue
        row = run_set(group, name, work, read_ground_truth(calib), args, config)
        rows.append(row)
        w = row["walk"]
        print(
            f"{name}: walk {w['cm']:.2f} cm / {w['deg']:.3f} deg, t {np.round(w['t_cm'], 2)} cm, "
            f"w {np.round(w['w_deg'], 3)} deg",
            file=sys.stderr,
            flush=True,
        )
    return {"summary": print_tables(rows), "rows": rows}


if __name__ == "__main__":
    raise SystemExit(main())
