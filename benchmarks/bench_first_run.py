"""`nbcalib demo` on a first run (empty numba cache) and a second, side by side with older code.

Each code tree (this checkout, and ``--baseline`` commits checked out as git worktrees) runs
``python -m nbcalib demo`` in a fresh folder, first with its numba cache emptied (cold: what a
fresh install pays), then again (warm). The trees alternate so that the machine's state is
shared; one demo at a time. Prints a table and one JSON line.

Usage (from the repository root, in the project's virtualenv)::

    python benchmarks/bench_first_run.py --baseline 5f1a4c4
    python benchmarks/bench_first_run.py --runs 2        # this checkout only, twice
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FINISHED = re.compile(r"demo finished in ([\d.]+) s \(([\d.]+) s CPU; (.*)\)")
ERROR = re.compile(r'\{"translation_error_m": ([\d.e-]+), "rotation_error_deg": ([\d.e-]+)')


def clear_cache(tree: Path) -> None:
    for pattern in ("*.nbi", "*.nbc"):
        for path in (tree / "nbcalib").rglob(pattern):
            path.unlink()


def demo(tree: Path, out: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "nbcalib", "demo", str(out)],
        cwd=tree,
        env=env,
        capture_output=True,
        text=True,
    )
    wall = time.perf_counter() - t0
    text = proc.stdout + proc.stderr
    if proc.returncode != 0:
        raise SystemExit(f"demo failed in {tree}:\n{text[-2000:]}")
    finished, error = FINISHED.search(text), ERROR.search(text)
    stages = dict(
        (name.strip(), float(seconds))
        for name, seconds in re.findall(r"([a-z-]+) ([\d.]+) s", finished.group(3))
    )
    return {
        "wall_s": round(wall, 1),
        "cpu_s": float(finished.group(2)),
        "stages": stages,
        "translation_cm": round(100 * float(error.group(1)), 3),
        "rotation_deg": round(float(error.group(2)), 4),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", action="append", default=[], metavar="COMMIT")
    parser.add_argument("--runs", type=int, default=1, help="cold + warm pairs per tree")
    args = parser.parse_args()
    scratch = Path(tempfile.mkdtemp(prefix="nbcalib-first-run-"))
    trees = {"this checkout": ROOT}
    for commit in args.baseline:
        tree = scratch / f"tree-{commit}"
        subprocess.run(
            ["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), commit],
            check=True,
            capture_output=True,
        )
        trees[commit] = tree
    results: dict[str, list] = {name: [] for name in trees}
    try:
        for run in range(args.runs):
            for kind in ("cold", "warm"):
                for name, tree in trees.items():
                    if kind == "cold":
                        clear_cache(tree)
                    out = scratch / f"{kind}-{run}-{name.replace(' ', '_')}"
                    r = demo(tree, out)
                    r["kind"] = kind
                    results[name].append(r)
                    shutil.rmtree(out, ignore_errors=True)
                    print(
                        f"{name:15s} {kind}: {r['wall_s']:6.1f} s wall, {r['cpu_s']:6.1f} s CPU "
                        f"(main process), {r['translation_cm']:.2f} cm / {r['rotation_deg']:.3f} "
                        f"deg; {r['stages']}",
                        flush=True,
                    )
    finally:
        for tree in trees.values():
            if tree != ROOT:
                subprocess.run(
                    ["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                    capture_output=True,
                )
        shutil.rmtree(scratch, ignore_errors=True)
    print(json.dumps({"bench": "first_run", "results": results}))


if __name__ == "__main__":
    main()
