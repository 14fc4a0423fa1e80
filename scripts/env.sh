# Sourced by scripts/test.sh and scripts/demo.sh: make a Python environment with nbcalib installed.
#
# Uses the active virtualenv or conda environment if there is one; otherwise creates ./.venv
# (Python >= 3.10 from $PYTHON, python3 or python). Installs nbcalib in editable mode with the
# extras named as the first argument.
nbcalib_env() {
  local extras="$1"
  if [ -z "${VIRTUAL_ENV:-}" ] && [ -z "${CONDA_PREFIX:-}" ]; then
    local py="${PYTHON:-$(command -v python3 || command -v python)}"
    if [ ! -x .venv/bin/python ]; then
      echo "[nbcalib] creating virtual environment .venv with $py"
      "$py" -m venv .venv
    fi
    # shellcheck disable=SC1091
    source .venv/bin/activate
  fi
  echo "[nbcalib] installing nbcalib[$extras] into $(python -c 'import sys; print(sys.prefix)')"
  python -m pip install -qq --upgrade pip
  python -m pip install -qq -e ".[$extras]"
}
