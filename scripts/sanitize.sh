#!/usr/bin/env bash
# The sanitizer builds, each in a second build space of the workspace, and their tests:
#   asan  the core gtests with AddressSanitizer + UndefinedBehaviorSanitizer (ROVER_SANITIZE;
#         $ROVER_WS/build_sanitize, devel_sanitize)
#   tsan  with ThreadSanitizer (ROVER_TSAN; build_tsan, devel_tsan): the core concurrency gtests
#         (test/core/test_concurrency.cpp, built alone as test_core_concurrency)
#         and the adapter stress test (loop_fusion's keyframe and optimisation threads with ROS
#         spinners, against a private rosmaster); third-party suppressions in test/tsan.supp
# Usage: scripts/sanitize.sh [asan] [tsan]   (no argument: both). Prints the time each took;
# writes JUnit results for scripts/test_summary.py when ROVER_RESULTS is set. Needs
# scripts/setup.sh first.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WS="${ROVER_WS:-$ROOT/.ws}"
export PATH="/usr/bin:$PATH"
modes=("$@")
[ ${#modes[@]} -eq 0 ] && modes=(asan tsan)
cd "$WS"

# build SPACE OPTION LOG TARGET...: one build space of the package with a sanitizer on.
build() {
  local space="$1" option="$2" log="$3"
  shift 3
  catkin_make --build "build_$space" -DCATKIN_DEVEL_PREFIX="$WS/devel_$space" "-D$option=ON" \
    -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=RelWithDebInfo -j"$(nproc)" "$@" > "$log" 2>&1 || {
    tail -n 40 "$log"; echo "[rover] $option build failed: $log" >&2; return 1; }
}

# junit NAME OUTPUT_XML: a gtest that died without writing its XML (a sanitizer report ends
# the process) still counts as a failed test in the summary.
junit_failure() {
  [ -n "${ROVER_RESULTS:-}" ] || return 0
  mkdir -p "$ROVER_RESULTS"
  printf '<?xml version="1.0"?>\n<testsuite name="%s" tests="1" failures="1"><testcase classname="sanitizer" name="%s"><failure message="sanitizer report or crash, see %s"/></testcase></testsuite>\n' \
    "$1" "$1" "$2" > "$ROVER_RESULTS/gtest-$1.xml"
}

# run_gtest NAME LOG COMMAND...: runs a gtest binary with its JUnit output in ROVER_RESULTS.
run_gtest() {
  local name="$1" log="$2"
  shift 2
  local out=()
  [ -n "${ROVER_RESULTS:-}" ] && out=(--gtest_output="xml:$ROVER_RESULTS/gtest-$name.xml")
  if "$@" "${out[@]}" > "$log" 2>&1; then
    echo "[rover] $name: $(grep -E '^\[  PASSED' "$log")"
    return 0
  fi
  grep -E "ERROR|WARNING: ThreadSanitizer|runtime error|FAILED|SUMMARY" "$log" | head -n 20
  [ -f "${ROVER_RESULTS:-/nonexistent}/gtest-$name.xml" ] || junit_failure "$name" "$log"
  echo "[rover] $name failed: $log" >&2
  return 1
}

# A test binary of a sanitizer build loads that build's core library, not the workspace's
# (LD_LIBRARY_PATH from devel/setup.bash comes before the binary's RUNPATH): else the library
# goes unchecked, and Eigen's allocators, which differ under ASan, mix across the two.
asan() {
  build sanitize ROVER_SANITIZE "$WS/sanitize.log" test_core
  LD_LIBRARY_PATH="$WS/devel_sanitize/lib:${LD_LIBRARY_PATH:-}" \
    ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    run_gtest test_core_asan_ubsan "$WS/sanitize_run.log" "$WS/devel_sanitize/lib/rover_loop_fusion/test_core"
}

tsan() {
  build tsan ROVER_TSAN "$WS/tsan.log" test_core_concurrency rover_test_adapter_stress rover_loop_fusion_plugins
  export TSAN_OPTIONS="suppressions=$ROOT/test/tsan.supp halt_on_error=1 second_deadlock_stack=1"
  local rc=0
  LD_LIBRARY_PATH="$WS/devel_tsan/lib:${LD_LIBRARY_PATH:-}" run_gtest test_core_concurrency_tsan \
    "$WS/tsan_core_run.log" "$WS/devel_tsan/lib/rover_loop_fusion/test_core_concurrency" || rc=1
  # The adapter stress test needs a master and the indoor YAML in /loop_fusion/rover (as
  # adapter_stress.test gives it), and pluginlib must load the TSan build of the plugins:
  # devel_tsan first on the search paths.
  (
    set +u
    # shellcheck disable=SC1091
    source "$WS/devel_tsan/setup.bash"
    set -u
    port="$(/usr/bin/python3 -c 'import socket; s = socket.socket(); s.bind(("localhost", 0)); print(s.getsockname()[1])')"
    export ROS_MASTER_URI="http://localhost:$port"
    rosmaster --core -p "$port" > "$WS/tsan_master.log" 2>&1 &
    master=$!
    trap 'kill $master 2>/dev/null; wait $master 2>/dev/null || true' EXIT
    for _ in $(seq 100); do rosparam list > /dev/null 2>&1 && break; sleep 0.2; done
    rosparam load "$ROOT/config/rover_template.yaml" /loop_fusion/rover  # the template, then the override
    rosparam load "$ROOT/config/rover_indoor.yaml" /loop_fusion/rover
    run_gtest adapter_stress_tsan "$WS/tsan_stress_run.log" \
      "$WS/devel_tsan/lib/rover_loop_fusion/rover_test_adapter_stress" __name:=loop_fusion
  ) || rc=1
  return $rc
}

status=0
for mode in "${modes[@]}"; do
  start=$SECONDS
  case "$mode" in
    asan) asan || status=1 ;;
    tsan) tsan || status=1 ;;
    *) echo "usage: $0 [asan] [tsan]" >&2; exit 2 ;;
  esac
  echo "[rover] sanitizer $mode: $((SECONDS - start)) s (build and run)"
done
exit $status
