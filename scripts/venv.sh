#!/usr/bin/env bash
# Python environment of the evaluation, the benchmarks and the Python tests: a venv in .venv/
# (git-ignored) on top of the system Python, which has the ROS modules, with the PyPI packages
# pinned in scripts/requirements.txt and this clone's roverlib (scripts/roverlib) installed in
# editable mode from setup.py, the package catkin_python_setup installs into the workspace too:
# `import roverlib` works in the venv with or without the workspace sourced. Source it (after
# scripts/setup.sh or on its own); it sets ROVER_PYTHON. Creates the venv on first use and
# reinstalls only when requirements.txt or setup.py changed (or the venv served another clone).
set -euo pipefail

ROVER_ROOT="${ROVER_ROOT:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}"
ROVER_VENV="${ROVER_VENV:-$ROVER_ROOT/.venv}"
export ROVER_ROOT ROVER_VENV

rover_venv() {
  local req="$ROVER_ROOT/scripts/requirements.txt" stamp="$ROVER_VENV/.requirements.sha256" want
  if ! dpkg-query -W -f='${Status}' python3-venv 2>/dev/null | grep -q "install ok installed"; then
    local sudo=""
    [ "$(id -u)" -ne 0 ] && sudo="sudo"
    echo "[rover] installing: python3-venv"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends python3-venv
  fi
  if [ ! -x "$ROVER_VENV/bin/python" ]; then
    echo "[rover] creating the Python venv $ROVER_VENV"
    /usr/bin/python3 -m venv --system-site-packages "$ROVER_VENV"
  fi
  want="$(sha256sum "$req" | cut -d' ' -f1)"
  if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "[rover] installing the Python packages of scripts/requirements.txt into $ROVER_VENV (a few minutes)"
    "$ROVER_VENV/bin/python" -m pip install -q --disable-pip-version-check -r "$req" \
        > "$ROVER_VENV/pip.log" 2>&1 || {
      tail -n 30 "$ROVER_VENV/pip.log"; echo "[rover] pip install failed; log: $ROVER_VENV/pip.log" >&2; return 1; }
    echo "$want" > "$stamp"
  fi
  # roverlib, editable: edits to scripts/roverlib take effect without a reinstall. setup.py reads
  # package.xml with catkin_pkg (the system Python's, which the venv sees).
  local lib_stamp="$ROVER_VENV/.roverlib.sha256"
  want="$(cat "$ROVER_ROOT/setup.py" "$ROVER_ROOT/package.xml" | sha256sum | cut -d' ' -f1) $ROVER_ROOT"
  if [ "$(cat "$lib_stamp" 2>/dev/null)" != "$want" ]; then
    echo "[rover] installing roverlib (setup.py, editable) into $ROVER_VENV"
    "$ROVER_VENV/bin/python" -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation \
        --use-pep517 -e "$ROVER_ROOT" > "$ROVER_VENV/pip-roverlib.log" 2>&1 || {
      tail -n 30 "$ROVER_VENV/pip-roverlib.log"
      echo "[rover] installing roverlib failed; log: $ROVER_VENV/pip-roverlib.log" >&2; return 1; }
    echo "$want" > "$lib_stamp"
  fi
  export ROVER_PYTHON="$ROVER_VENV/bin/python"
}

rover_venv
