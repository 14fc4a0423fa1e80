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
  # editable installs from pyproject.toml need pip >= 21.3; a newer pip is not fetched otherwise
  if ! python -c 'import sys, pip; sys.exit(int(pip.__version__.split(".")[0]) < 22)' 2>/dev/null; then
    python -m pip install -qq --upgrade pip
  fi
  python -m pip install -qq -e ".[$extras]"
}

# numba's cache checks only each kernel's own source file, so a kernel that calls a changed
# kernel in another module would keep running stale machine code. When any module that
# compiles kernels (nbcalib/kernels/ and the modules importing its JIT helpers) changes, drop
# every cached kernel.
nbcalib_clear_stale_numba_cache() {
  local stamp
  stamp=$( { ls nbcalib/kernels/*.py; grep -rl --include='*.py' "kernels._jit import" nbcalib; } \
    | sort -u | xargs cat | python -c "import hashlib, sys; print(hashlib.sha256(sys.stdin.buffer.read()).hexdigest()[:16])")
  if [ "$(cat .numba_kernels_stamp 2>/dev/null)" != "$stamp" ]; then
    find nbcalib -name '*.nbi' -delete -o -name '*.nbc' -delete
    echo "$stamp" > .numba_kernels_stamp
  fi
}

# The notebooks' 3-D views render off screen through VTK's EGL window, which needs Mesa's EGL
# and DRI drivers (no X server). Install them with apt when we may; otherwise say how.
nbcalib_ensure_egl() {
  [ "$(uname -s)" = Linux ] || return 0
  python -c 'import ctypes; ctypes.CDLL("libEGL.so.1")' 2>/dev/null && return 0
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo -n"
  if command -v apt-get >/dev/null && $sudo true 2>/dev/null; then
    echo "[nbcalib] installing libegl1 libgl1-mesa-dri (off-screen 3-D views in the notebooks)"
    if ! { $sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq \
      libegl1 libgl1-mesa-dri >/dev/null; }; then
      echo "[nbcalib] warning: could not install libegl1 libgl1-mesa-dri" >&2
    fi
  else
    echo "[nbcalib] warning: no libEGL.so.1; the notebooks' 3-D views need: apt install libegl1 libgl1-mesa-dri" >&2
  fi
}
