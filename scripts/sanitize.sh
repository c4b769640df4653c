#!/usr/bin/env bash
# The core gtests built with AddressSanitizer + UndefinedBehaviorSanitizer (ROVER_SANITIZE) in
# a second build space of the workspace ($ROVER_WS/build_sanitize), then run. Writes JUnit
# results for scripts/test_summary.py when ROVER_RESULTS is set. Needs scripts/setup.sh first.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WS="${ROVER_WS:-$ROOT/.ws}"
export PATH="/usr/bin:$PATH"
cd "$WS"
catkin_make --build build_sanitize -DCATKIN_DEVEL_PREFIX="$WS/devel_sanitize" -DROVER_SANITIZE=ON \
  -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo -j"$(nproc)" test_core \
  > "$WS/sanitize.log" 2>&1 || { tail -n 40 "$WS/sanitize.log"; echo "[rover] sanitizer build failed: $WS/sanitize.log" >&2; exit 1; }
out=()
[ -n "${ROVER_RESULTS:-}" ] && out=(--gtest_output="xml:$ROVER_RESULTS/gtest-test_core_asan_ubsan.xml")
ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
  "$WS/devel_sanitize/lib/rover_loop_fusion/test_core" "${out[@]}" > "$WS/sanitize_run.log" 2>&1 || {
  grep -E "ERROR|runtime error|FAILED|Sanitizer" "$WS/sanitize_run.log" | head -n 20
  echo "[rover] core tests under ASan/UBSan failed: $WS/sanitize_run.log" >&2; exit 1; }
echo "[rover] core tests under ASan+UBSan: $(grep -E '^\[  PASSED' "$WS/sanitize_run.log")"
