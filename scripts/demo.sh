#!/usr/bin/env bash
# Install nbcalib with every extra, then run the main job: `nbcalib demo`, a seeded synthetic
# scene calibrated end to end (synth -> preprocess -> find-matches -> initial-guess -> calibrate
# -> report), with the error against the ground truth.
# Usage: scripts/demo.sh [WORKDIR]     (default: ./nbcalib_demo)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
source scripts/env.sh
nbcalib_env all
nbcalib_clear_stale_numba_cache
nbcalib demo "${1:-nbcalib_demo}"
