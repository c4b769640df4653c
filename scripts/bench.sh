#!/usr/bin/env bash
# One command per benchmark family (docs/results.md); builds the package and the Python venv
# on first use, then runs the family's script (scripts/bench/) with the venv's Python:
#
#   ./scripts/bench.sh poc|real|posegraph [--split test|tuning] [--quick] [options, --help]
#   ./scripts/bench.sh cost|long_replay|fault_replay [--quick] [options, --help]
#   ./scripts/bench.sh all [--quick]          poc, real, posegraph, cost, one after the other
#   ./scripts/bench.sh agreement [--quick] ... the condensed trial's decisions against the full trial's
#                                             on every family (scripts/bench/agreement.py)
#   ./scripts/bench.sh identity build|run|compare  every family's verdicts, timing aside, for two builds
#   ./scripts/bench.sh cost_ab save DIR | run --old DIR  the cost benchmark of two builds in turn, verdicts
#                                             compared, summed verify_ms side by side (scripts/bench/cost_ab.py)
#   ./scripts/bench.sh robustness [--split test|tuning] [--set K=V]  the +-10 % threshold and gate
#                                             settings per case, recall spread (scripts/bench/robustness.py)
#   ./scripts/bench.sh targets [--poc DIR ...]  the project's targets per case from the runs above, beside
#                                             the peers, with the causes of each miss (scripts/bench/targets.py)
#   ./scripts/bench.sh sweep ...              scripts/threshold_sweep.py (tuning cases only)
#   ./scripts/bench.sh evaluate ...           scripts/evaluate.py (verdict log + labels -> AP, MR, ...)
#   ./scripts/bench.sh diagnostics DIR        scripts/verdict_diagnostics.py (why decisions went wrong)
#
# Cases come from roverlib/splits.py: the test split by default (what the docs report).
# Results (tables, summary.csv, PNG) go to results/<family>/ (git-ignored).
set -euo pipefail
family="${1:-}"
case "$family" in
  poc|real|posegraph|cost|cost_ab|long_replay|fault_replay|agreement|identity|robustness|targets|all|sweep|evaluate|diagnostics) shift ;;
  *) echo "usage: $0 poc|real|posegraph|cost|cost_ab|long_replay|fault_replay|agreement|identity|robustness|targets|all|sweep|evaluate|diagnostics [options]" >&2; exit 2 ;;
esac
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
source "$ROVER_ROOT/scripts/venv.sh"
cd "$ROVER_ROOT"
case "$family" in
  evaluate) exec "$ROVER_PYTHON" scripts/evaluate.py "$@" ;;
  diagnostics) exec "$ROVER_PYTHON" scripts/verdict_diagnostics.py "$@" ;;
  sweep) exec "$ROVER_PYTHON" scripts/threshold_sweep.py "$@" ;;
  all) for f in poc real posegraph cost; do "$ROVER_PYTHON" "scripts/bench/$f.py" "$@"; done ;;
  *) exec "$ROVER_PYTHON" "scripts/bench/$family.py" "$@" ;;
esac
