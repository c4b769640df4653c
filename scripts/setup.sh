#!/usr/bin/env bash
# Shared set-up for scripts/demo.sh and scripts/test.sh: installs what is missing from the
# distribution's packages, then builds this package in a catkin workspace kept in .ws/
# (git-ignored) inside the clone. Safe to run again: a built workspace is only rebuilt
# incrementally. Source it; it sets ROVER_ROOT and ROVER_WS and sources devel/setup.bash.
set -euo pipefail

ROVER_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
ROVER_WS="${ROVER_WS:-$ROVER_ROOT/.ws}"
export ROVER_ROOT ROVER_WS
# The ROS Python modules live in the system Python; a pyenv/conda python3 first on PATH
# breaks catkin and pluginlib's CMake hooks.
export PATH="/usr/bin:$PATH"

# Debian 12 ships ROS 1 as ros-*/lib*-dev/python3-ros* packages; Ubuntu 20.04 users have
# ROS Noetic from packages.ros.org (see README) and get the rest from apt as well.
ROVER_DEPS=(
  catkin ros-core-dev pluginlib-dev libtf2-dev libtf2-ros-dev libtf2-eigen-dev
  libceres-dev libeigen3-dev libopencv-dev libgtest-dev googletest
  python3-nav-msgs
  python3-rosbag python3-roslaunch python3-rostest python3-rosnode python3-rostopic
  python3-numpy python3-pytest rosbash
  clang-14 libclang-rt-14-dev
)

rover_install_deps() {
  local missing=()
  for p in "${ROVER_DEPS[@]}"; do
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
  (cd "$ROVER_WS" && catkin_make -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release \
      -j"$(nproc)" "$@" > "$ROVER_WS/build.log" 2>&1) || {
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

rover_install_deps
rover_build
