#!/usr/bin/env bash
# The main job: set-up on first use, then the demo (launch/demo.launch): a shipped bag replayed
# into rover_verifier_node (ROVER) and an accept-all baseline, and a summary against the labels.
# Extra arguments go to roslaunch, e.g. rviz:=true, threshold:=0.5, bag:=/abs/path/scenario.bag.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
exec roslaunch --no-summary rover_loop_fusion demo.launch "$@"
