"""Is a refactor bit for bit? The same jobs through the CLI at two commits, their outputs compared.

A change that only moves code (issue 46) must not move a figure. This runs, at ``--base`` (a
git worktree made for it) and at this checkout, each through ``python -m nbcalib`` as a user
types it:

- ``nbcalib demo`` (its default scene): every product of its work directory byte for byte, and
  ``calib.json`` with its paths, timings and time stamps left out;
- ``nbcalib synth`` for seven LiDAR x camera x scene x seed rigs (every camera model), a
  two-pair ROS 2 bag and a camera ring: every file byte for byte (the synthetic golden digests);
- ``benchmarks/bench_bias.py --parts synthetic`` on three rigs (walk and near starts): every
  error, to the last digit.

Run:  python benchmarks/bench_bit_identity.py --base 43f53ae [--keep DIR]
Prints one line per comparison and exits 1 if anything differs.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RIGS = (
    ("livox", "pinhole", "room", 0),
    ("spinning64", "fisheye", "street", 1),
    ("spinning32", "omnidir", "room", 2),
    ("livox", "plumb_bob", "street", 3),
    ("spinning128", "equirectangular", "room", 1),
    ("spinning16", "atan", "street", 2),
    ("spinning64", "rational_polynomial", "room", 0),
)
BIAS_CASES = "livox:pinhole:room:1,spinning64:fisheye:street:2,spinning64:omnidir:room:1"
#: calib.json keys that hold when and how long, not what.
VOLATILE = {"seconds", "written", "result_times"}


def run_all(code: Path, out: Path) -> None:
    """The jobs with the nbcalib of ``code`` (its folder first on PYTHONPATH), into ``out``."""
    env = {**os.environ, "PYTHONPATH": str(code), "MPLBACKEND": "Agg", "NBCALIB_NO_WARMUP": "1"}

    def nbcalib(*args):
        subprocess.run([sys.executable, "-m", "nbcalib", *map(str, args)], env=env, check=True,
                       capture_output=True, cwd=out)  # fmt: skip

    nbcalib("demo", out / "demo", "-q")
    for lidar, camera, scene, seed in RIGS:
        folder = out / "synth" / f"{lidar}_{camera}_{scene}_{seed}"
        nbcalib("synth", folder, "--lidar", lidar, "--camera", camera, "--scene", scene,
                "--seed", seed, "-q")  # fmt: skip
    nbcalib("synth", out / "synth" / "bag2", "--pairs", 2, "--format", "bag2", "--seed", 5, "-q")
    nbcalib("synth", out / "synth" / "ring", "--cameras", "pinhole,fisheye", "--seed", 4, "-q")
    bias = subprocess.run(
        [sys.executable, str(code / "benchmarks" / "bench_bias.py"), "--parts", "synthetic",
         "--cases", BIAS_CASES, "--gaps", "1", "--keep", str(out / "bias")],
        env=env, check=True, capture_output=True, text=True, cwd=out,
    )  # fmt: skip
    (out / "bias.json").write_text(bias.stdout.strip().splitlines()[-1])


def digests(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def _plain(value, prefix: str):
    """``value`` without volatile keys, its paths relative to the run's folder."""
    if isinstance(value, dict):
        return {k: _plain(v, prefix) for k, v in value.items() if k not in VOLATILE}
    if isinstance(value, list):
        return [_plain(v, prefix) for v in value]
    if isinstance(value, str):
        return value.replace(prefix, "<run>/")
    return value


def _figures(value):
    """The bias benchmark's JSON without its timings."""
    if isinstance(value, dict):
        return {k: _figures(v) for k, v in value.items() if not k.endswith(("seconds", "_s"))}
    if isinstance(value, list):
        return [_figures(v) for v in value]
    return value


def compare(a: Path, b: Path) -> list[str]:
    """What differs between the runs in ``a`` and ``b`` (empty: bit for bit)."""
    found = []
    work_a, work_b = a / "demo" / "work", b / "demo" / "work"
    skip = {"calib.json", "nbcalib_config.yaml"}
    da = {k: v for k, v in digests(work_a).items() if k not in skip and "report" not in k}
    db = {k: v for k, v in digests(work_b).items() if k not in skip and "report" not in k}
    found += [f"demo: {k} differs" for k in sorted(set(da) | set(db)) if da.get(k) != db.get(k)]
    ca = _plain(json.loads((work_a / "calib.json").read_text()), f"{a}/")
    cb = _plain(json.loads((work_b / "calib.json").read_text()), f"{b}/")
    if ca != cb:
        found.append("demo: calib.json differs (paths, timings and time stamps left out)")
    print(f"demo: {len(da)} products and calib.json compared", flush=True)
    sa, sb = digests(a / "synth"), digests(b / "synth")
    found += [f"synth: {k} differs" for k in sorted(set(sa) | set(sb)) if sa.get(k) != sb.get(k)]
    print(f"synth: {len(sa)} files compared", flush=True)
    ja = _figures(json.loads((a / "bias.json").read_text()))
    jb = _figures(json.loads((b / "bias.json").read_text()))
    if ja != jb:
        found.append("bias: the synthetic runs' errors differ")
    print("bias: the synthetic runs' errors compared", flush=True)
    return found


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--base", required=True, help="the commit to compare with (e.g. 43f53ae)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the runs here")
    args = ap.parse_args(argv)
    top = args.keep or Path(tempfile.mkdtemp(prefix="nbcalib_identity_"))
    base_code = top / "base_code"
    if not base_code.exists():
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f",
                        str(base_code), args.base], check=True, capture_output=True)  # fmt: skip
    try:
        for name, code in (("base", base_code), ("head", ROOT)):
            out = top / name
            shutil.rmtree(out, ignore_errors=True)
            out.mkdir(parents=True)
            print(f"running the jobs at {name} ({code})", flush=True)
            run_all(code, out)
        found = compare(top / "base", top / "head")
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(base_code)],
                       capture_output=True)  # fmt: skip
        if args.keep is None:
            shutil.rmtree(top, ignore_errors=True)
    for line in found:
        print(line)
    print("bit for bit" if not found else f"{len(found)} differences")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
