#!/usr/bin/env bash
# Install nbcalib with its test dependencies, then lint and run the test suite.
# Usage: scripts/test.sh [extra pytest arguments]     (CI runs exactly this through .ci/run)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/env.sh
nbcalib_env dev
nbcalib_ensure_egl
nbcalib_clear_stale_numba_cache
export MPLBACKEND=Agg
echo "[nbcalib] ruff"
python -m ruff check .
python -m ruff format --check .
echo "[nbcalib] pytest"
# both cores, one test module per worker (its module-scoped fixtures made once);
# NBCALIB_TEST_WORKERS=0 runs the suite in this process
python -m pytest -n "${NBCALIB_TEST_WORKERS:-2}" --dist loadfile "$@"
