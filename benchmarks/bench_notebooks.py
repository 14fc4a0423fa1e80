"""Wall time of each teaching notebook run as a script, as a learner runs it (or in quick mode).

    python benchmarks/bench_notebooks.py            # full mode: the learner's data sizes
    python benchmarks/bench_notebooks.py --quick    # NBCALIB_NOTEBOOK_QUICK=1, as the tests
    python benchmarks/bench_notebooks.py 06 07      # only notebooks whose name starts so

Each notebook runs in its own Python process (``python notebooks/NN_name.py``, interpreter
start-up and imports included) in a temporary folder, with a non-interactive matplotlib backend
and 3-D views rendered off screen as still images. The full mode uses whatever matcher the
machine has (the learned one when its models are there); one notebook at a time, on an idle
machine. Prints a Markdown table; exits 1 if a notebook fails.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("only", nargs="*", help="name prefixes of the notebooks to run")
    parser.add_argument("--quick", action="store_true", help="the tests' quick mode")
    args = parser.parse_args(argv)
    notebooks = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.py"))
    if args.only:
        notebooks = [nb for nb in notebooks if nb.stem.startswith(tuple(args.only))]
    env = dict(os.environ, MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true")
    env.pop("NBCALIB_NOTEBOOK_QUICK", None)
    if args.quick:
        env["NBCALIB_NOTEBOOK_QUICK"] = "1"
    mode = "quick" if args.quick else "full"
    print(f"| notebook | {mode} mode, wall |\n|---|---|")
    total, failed = 0.0, []
    for notebook in notebooks:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            run = subprocess.run(
                [sys.executable, str(notebook)], cwd=tmp, env=env, capture_output=True, text=True
            )
            seconds = time.perf_counter() - t0
        total += seconds
        status = "" if run.returncode == 0 else f" (FAILED, exit {run.returncode})"
        if run.returncode:
            failed.append((notebook.stem, run.stderr.strip().splitlines()[-1:]))
        print(f"| {notebook.stem} | {seconds:.1f} s{status} |", flush=True)
    print(f"| **all {len(notebooks)}** | **{total:.0f} s** |")
    for stem, last in failed:
        print(f"{stem}: {' '.join(last)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
