#!/usr/bin/env bash
# The main job: set-up on first use, then the demo. Extra arguments go to the demo.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
exec "$ROVER_WS/devel/lib/rover_loop_fusion/rover_cli_demo" "$@"
