#!/usr/bin/env bash
# Compiles every source of ours that includes Ceres (-fsyntax-only, -std=c++14 -Wall -Wextra
# -Werror) against the headers of another Ceres, e.g. 1.14 (Ubuntu 20.04 / ROS Noetic), which
# this machine does not have installed: the check of rover_loop_fusion/core/ceres_compat.h that
# docs/testing.md describes. Not part of scripts/test.sh (it needs a Ceres source checkout).
#
#   scripts/check_ceres_headers.sh CERES_SOURCE_DIR     e.g. a checkout of tag 1.14.0, outside the clone
#
# A Ceres source tree has no ceres/internal/config.h (its CMake generates it): a minimal one
# (CERES_USE_OPENMP) goes into a temporary directory; Eigen and glog come from the system.
# Prints the Ceres version the sources were checked against and one line per source; exit
# status 1 if any of them does not compile.
set -euo pipefail
ceres="${1:?usage: $0 CERES_SOURCE_DIR}"
[ -f "$ceres/include/ceres/version.h" ] || { echo "$ceres/include/ceres/version.h not found" >&2; exit 2; }
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cxx="${CXX:-g++}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/ceres/internal"
if [ ! -f "$ceres/include/ceres/internal/config.h" ]; then
  printf '#pragma once\n#define CERES_USE_OPENMP\n' > "$tmp/ceres/internal/config.h"
fi
flags=(-std=c++14 -Wall -Wextra -Werror -fsyntax-only -I"$root" -I"$tmp" -I"$ceres/include" -isystem /usr/include/eigen3)
printf '#include <ceres/version.h>\n' > "$tmp/version.cpp"
macros="$("$cxx" "${flags[@]/-fsyntax-only/-E}" -dM "$tmp/version.cpp")"
version() { sed -n "s/^#define CERES_VERSION_$1 //p" <<< "$macros"; }
echo "Ceres $(version MAJOR).$(version MINOR).$(version REVISION) from $ceres/include"
rc=0 n=0
cd "$root"
for src in rover_loop_fusion/*/*.cpp test/core/*.cpp fuzz/*.cpp; do
  # only the sources that include Ceres, and only through this checkout's headers
  deps="$("$cxx" "${flags[@]/-fsyntax-only/-M}" "$src" 2>/dev/null || true)"
  grep -qF "$ceres/include/ceres/ceres.h" <<< "$deps" || continue
  n=$((n + 1))
  if out="$("$cxx" "${flags[@]}" "$src" 2>&1)"; then
    echo "ok      $src"
  else
    echo "FAILED  $src"; echo "$out" | head -n 20; rc=1
  fi
done
[ "$n" -gt 0 ] || { echo "no source includes $ceres/include/ceres/ceres.h" >&2; exit 1; }
exit "$rc"
