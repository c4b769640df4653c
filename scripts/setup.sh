#!/usr/bin/env bash
# Shared set-up for scripts/demo.sh and scripts/test.sh: installs the Debian 12 packages this
# package needs, then builds it in a catkin workspace kept in .ws/ (git-ignored) inside the
# clone. Safe to run again: only missing packages are installed and a built workspace is only
# rebuilt incrementally.
#
#   source scripts/setup.sh            install, build, source devel/setup.bash; sets ROVER_ROOT, ROVER_WS
#   scripts/setup.sh --print-packages  print the Debian packages it installs, one a line; change nothing
#
# What it installs is derived, never listed here: every dependency of package.xml (rosdep keys)
# mapped through scripts/debian12-packages.yaml, plus that file's toolchain and hardening lists.
# test/python/test_dependencies.py checks the two against each other.
# Ubuntu 20.04 + ROS Noetic: rosdep install --from-paths . --ignore-src (docs/testing.md).
set -euo pipefail

ROVER_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ROVER_WS="${ROVER_WS:-$ROVER_ROOT/.ws}"
export ROVER_ROOT ROVER_WS
# The ROS Python modules live in the system Python; a pyenv/conda python3 first on PATH
# breaks catkin and pluginlib's CMake hooks.
export PATH="/usr/bin:$PATH"

# The Debian packages for the package in directory $1 (default: this clone), sorted. Fails,
# naming the key, when a package.xml dependency has no entry in the mapping or a mapping line
# cannot be read. Plain bash and sed: it runs before anything is installed.
rover_debian_packages() {
  local root="${1:-$ROVER_ROOT}"
  local xml="$root/package.xml" map="$root/scripts/debian12-packages.yaml"
  local line section="" n=0 bad=0 key
  local -A by_key=()
  local pkgs=()
  while IFS= read -r line || [ -n "$line" ]; do
    n=$((n + 1))
    line="${line%%#*}"
    [[ "$line" =~ ^[[:space:]]*$ ]] && continue
    if [[ "$line" =~ ^([a-z_]+):[[:space:]]*$ ]]; then
      section="${BASH_REMATCH[1]}"
    elif [[ "$line" =~ ^([a-z_]+):[[:space:]]*\[([^]]*)\][[:space:]]*$ ]]; then
      section=""
      pkgs+=(${BASH_REMATCH[2]//,/ })
    elif [ "$section" = keys ] && [[ "$line" =~ ^[[:space:]]+([A-Za-z0-9_.+-]+):[[:space:]]*\[([^]]*)\][[:space:]]*$ ]]; then
      by_key["${BASH_REMATCH[1]}"]="${BASH_REMATCH[2]//,/ }"
    else
      echo "[rover] $map:$n: cannot read '$line' (expected 'key: [package, ...]' on one line)" >&2
      bad=1
    fi
  done < "$map"
  for key in $(sed -n 's|.*<\([a-z_]*depend\)\( [^>]*\)\{0,1\}>[[:space:]]*\([^<[:space:]]*\)[[:space:]]*</\1>.*|\3|p' "$xml"); do
    if [[ -v by_key["$key"] ]]; then
      pkgs+=(${by_key["$key"]})
    else
      echo "[rover] package.xml depends on '$key', which has no Debian 12 packages in $map" >&2
      bad=1
    fi
  done
  [ "$bad" -eq 0 ] || return 1
  printf '%s\n' "${pkgs[@]}" | sort -u
}

rover_install_deps() {
  local wanted missing=() p
  wanted="$(rover_debian_packages)"
  for p in $wanted; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "[rover] installing: ${missing[*]}"
  local sudo=""
  [ "$(id -u)" -ne 0 ] && sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

rover_build() {
  mkdir -p "$ROVER_WS/src"
  [ -e "$ROVER_WS/src/rover_loop_fusion" ] || ln -s "$ROVER_ROOT" "$ROVER_WS/src/rover_loop_fusion"
  echo "[rover] building the catkin workspace $ROVER_WS"
  # -DROVER_WERROR=ON: our C++ builds without a warning (-std=c++14 -Wall -Wextra, CMakeLists.txt)
  (cd "$ROVER_WS" && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release \
      -DROVER_WERROR=ON -j"$(nproc)" "$@" > "$ROVER_WS/build.log" 2>&1) || {
    tail -n 60 "$ROVER_WS/build.log"
    echo "[rover] build failed; full log: $ROVER_WS/build.log" >&2
    return 1
  }
  # catkin's setup scripts read unset variables.
  set +u
  # shellcheck disable=SC1091
  source "$ROVER_WS/devel/setup.bash"
  set -u
}

if [ "${BASH_SOURCE[0]}" = "$0" ] && [ "${1:-}" = "--print-packages" ]; then
  rover_debian_packages
  exit
fi
rover_install_deps
rover_build
