#!/usr/bin/env bash
# The whole test suite: set-up on first use, then every gtest, rostest and pytest of the
# package, the core gtests again under ASan+UBSan, the concurrency tests (core and the
# loop_fusion adapter under its threading) under ThreadSanitizer, and a short fuzz run. Ends
# with 'rover tests: N passed, M failed, K skipped'; exit status 1 if any test failed, errored
# or could not run.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
# The Python tests (evaluation, benchmarks) need scikit-learn, evo, gtsam: a venv on top of
# the system Python (scripts/venv.sh), which keeps the ROS modules visible.
source "$ROVER_ROOT/scripts/venv.sh"
cd "$ROVER_WS"
# catkin_make run_tests builds and runs the gtests and rostests; it does not fail on test
# failures, which are read back from the JUnit files by test_summary.py below.
catkin_make run_tests -DPYTHON_EXECUTABLE=/usr/bin/python3 -j"$(nproc)" > "$ROVER_WS/test.log" 2>&1 || {
  tail -n 80 "$ROVER_WS/test.log"; echo "[rover] building or running the tests failed; log: $ROVER_WS/test.log" >&2; exit 1; }
grep -E '^\[( +OK|  FAILED|  PASSED|==========)|^(SUMMARY|\[ROSTEST\])|FAILURE|ERROR' "$ROVER_WS/test.log" | grep -v '^\[       OK' || true
# Python tools (simulator, evaluation): pytest writes JUnit XML next to catkin's results.
# Exit 1 = some tests failed (counted from the XML); anything else means pytest could not run.
pytest_rc=0
ROVER_WS="$ROVER_WS" "$ROVER_PYTHON" -m pytest -q -p no:cacheprovider "$ROVER_ROOT/test/python" \
  --junitxml="$ROVER_WS/build/test_results/rover_loop_fusion/pytest-python.xml" || pytest_rc=$?
# Hardening: the core gtests under ASan+UBSan and the concurrency tests under TSan (each in a
# second build space; scripts/sanitize.sh prints the time each took) and the libFuzzer targets
# (committed corpus + ROVER_FUZZ_SECONDS of fuzzing each). Their JUnit files join the summary.
results="$ROVER_WS/build/test_results/rover_loop_fusion"
hardening_rc=0
ROVER_WS="$ROVER_WS" ROVER_RESULTS="$results" "$ROVER_ROOT/scripts/sanitize.sh" asan tsan || hardening_rc=$?
ROVER_WS="$ROVER_WS" ROVER_RESULTS="$results" "$ROVER_ROOT/scripts/fuzz.sh" || hardening_rc=$?
summary_rc=0
/usr/bin/python3 "$ROVER_ROOT/scripts/test_summary.py" "$ROVER_WS/build/test_results" || summary_rc=$?
if [ "$pytest_rc" -gt 1 ]; then echo "[rover] pytest could not run (exit $pytest_rc)" >&2; exit 1; fi
# A sanitizer or fuzz build that failed to build writes no JUnit file: fail on its status too.
if [ "$hardening_rc" -ne 0 ] && [ "$summary_rc" -eq 0 ]; then exit 1; fi
exit "$summary_rc"
