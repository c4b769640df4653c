#!/usr/bin/env bash
# One command per benchmark family (README "Results"); builds the package and the Python venv
# on first use, then runs the family's script with the venv's Python:
#
#   ./scripts/bench.sh poc|real|posegraph|cost [--quick] [options of that script, --help]
#   ./scripts/bench.sh all [--quick]          every family, one after the other
#   ./scripts/bench.sh evaluate ...           scripts/evaluate.py (verdict log + labels -> AP, MR, ...)
#   ./scripts/bench.sh diagnostics DIR        scripts/verdict_diagnostics.py (why decisions went wrong)
#
# Results (tables, CSV, PNG) go to results/<family>/ (git-ignored).
set -euo pipefail
family="${1:-}"
case "$family" in
  poc|real|posegraph|cost|all|evaluate|diagnostics) shift ;;
  *) echo "usage: $0 poc|real|posegraph|cost|all|evaluate|diagnostics [options]" >&2; exit 2 ;;
esac
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
source "$ROVER_ROOT/scripts/venv.sh"
cd "$ROVER_ROOT"
if [ "$family" = evaluate ]; then exec "$ROVER_PYTHON" scripts/evaluate.py "$@"; fi
if [ "$family" = diagnostics ]; then exec "$ROVER_PYTHON" scripts/verdict_diagnostics.py "$@"; fi
if [ "$family" = all ]; then
  for f in poc real posegraph cost; do "$ROVER_PYTHON" "scripts/bench/$f.py" "$@"; done
  exit 0
fi
exec "$ROVER_PYTHON" "scripts/bench/$family.py" "$@"
