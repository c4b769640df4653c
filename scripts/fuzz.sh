#!/usr/bin/env bash
# libFuzzer targets (fuzz/): build with clang, replay the committed corpus (regression), then
# fuzz each target for ROVER_FUZZ_SECONDS (default 20; CI) from a copy of the corpus.
# Writes JUnit results for scripts/test_summary.py when ROVER_RESULTS is set. Crashes go to
# $ROVER_WS/fuzz/artifacts/. By hand, longer and keeping what it finds:
#   ROVER_FUZZ_SECONDS=600 scripts/fuzz.sh --merge
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WS="${ROVER_WS:-$ROOT/.ws}"
BUILD="$WS/fuzz"
SECONDS_EACH="${ROVER_FUZZ_SECONDS:-20}"
MERGE=0
[ "${1:-}" = "--merge" ] && MERGE=1
export PATH="/usr/bin:$PATH"
CXX_FUZZ="$(command -v clang++-14 || command -v clang++ || true)"
[ -n "$CXX_FUZZ" ] || { echo "[rover] clang++ not found (apt-get install clang-14 libclang-rt-14-dev)" >&2; exit 1; }

mkdir -p "$BUILD/artifacts"
(cmake -S "$ROOT/fuzz" -B "$BUILD" -DCMAKE_CXX_COMPILER="$CXX_FUZZ" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
   > "$BUILD/build.log" 2>&1 && make -C "$BUILD" -j"$(nproc)" >> "$BUILD/build.log" 2>&1) || {
  tail -n 40 "$BUILD/build.log"; echo "[rover] fuzz build failed: $BUILD/build.log" >&2; exit 1; }

cases=()  # "name|ok|message"
for target in fuzz_verifier_api fuzz_scenario_parser; do
  corpus="$ROOT/fuzz/corpus/$target"
  log="$BUILD/$target.regression.log"
  if "$BUILD/$target" -runs=0 -artifact_prefix="$BUILD/artifacts/$target-" "$corpus" > "$log" 2>&1; then
    cases+=("$target.corpus_regression|1|$(ls "$corpus" | wc -l) committed inputs")
  else
    cases+=("$target.corpus_regression|0|$(tail -n 30 "$log")")
  fi
  work="$BUILD/corpus-$target"
  rm -rf "$work" && cp -r "$corpus" "$work"
  log="$BUILD/$target.fuzz.log"
  if "$BUILD/$target" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=4096 \
       -artifact_prefix="$BUILD/artifacts/$target-" "$work" > "$log" 2>&1; then
    cases+=("$target.fuzz_${SECONDS_EACH}s|1|$(grep -o 'Done [0-9]* runs.*' "$log" | tail -1)")
    if [ "$MERGE" = 1 ]; then
      "$BUILD/$target" -merge=1 "$corpus" "$work" > "$BUILD/$target.merge.log" 2>&1
      echo "[rover] $target: $(grep MERGE-OUTER "$BUILD/$target.merge.log" | tail -1)"
    fi
  else
    cases+=("$target.fuzz_${SECONDS_EACH}s|0|$(tail -n 40 "$log")")
  fi
done

failed=0
for c in "${cases[@]}"; do
  IFS='|' read -r name ok msg <<< "$c"
  if [ "$ok" = 1 ]; then echo "[rover] fuzz $name: ok ($msg)"; else echo "[rover] fuzz $name: FAILED"; echo "$msg"; failed=1; fi
done
if [ -n "${ROVER_RESULTS:-}" ]; then
  mkdir -p "$ROVER_RESULTS"
  /usr/bin/python3 - "$ROVER_RESULTS/fuzz.xml" "${cases[@]}" <<'PY'
import sys
from xml.sax.saxutils import escape
out, cases = sys.argv[1], sys.argv[2:]
rows = []
for c in cases:
    name, ok, msg = c.split("|", 2)
    body = "" if ok == "1" else f'<failure message="{escape(msg[:200], {chr(34): "&quot;"})}">{escape(msg)}</failure>'
    rows.append(f'<testcase classname="fuzz" name="{escape(name)}">{body}</testcase>')
open(out, "w").write(f'<testsuite name="fuzz" tests="{len(rows)}">' + "".join(rows) + "</testsuite>\n")
PY
fi
exit "$failed"
