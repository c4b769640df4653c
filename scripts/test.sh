#!/usr/bin/env bash
# The whole test suite: set-up on first use, then every gtest and rostest of the package.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROVER_WS"
# Build and run the tests; catkin_make run_tests does not fail on test failures, so the
# result is read back with catkin_test_results (non-zero exit on any failure or error).
catkin_make run_tests -DPYTHON_EXECUTABLE=/usr/bin/python3 -j"$(nproc)" > "$ROVER_WS/test.log" 2>&1 || {
  tail -n 80 "$ROVER_WS/test.log"; echo "[rover] building or running the tests failed; log: $ROVER_WS/test.log" >&2; exit 1; }
grep -E '^\[( +OK|  FAILED|  PASSED|==========)|^(SUMMARY|\[ROSTEST\])|FAILURE|ERROR' "$ROVER_WS/test.log" | grep -v '^\[       OK' || true
/usr/bin/python3 "$ROVER_ROOT/scripts/test_summary.py" "$ROVER_WS/build/test_results"
