#!/usr/bin/env bash
# Install nbcalib with every extra, then run the main job.
# Usage: scripts/demo.sh
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/env.sh
nbcalib_env all
nbcalib_clear_stale_numba_cache
nbcalib --help
nbcalib selfcheck
