#!/usr/bin/env bash
# The main job: set-up on first use, then the demo (launch/demo.launch): a shipped bag
# (data/corridor) replayed into rover_verifier_node (ROVER) and an accept-all baseline, every
# verdict, and a summary against the labels, which is the last thing printed. Exit status 0
# after the summary, non-zero when the set-up, the launch or the replay failed.
# Arguments go to the launch file, e.g. rviz:=true, threshold:=0.5, bag:=/abs/path/scenario.bag,
# verbose:=false (docs/ros-api.md lists them).
#
# roslaunch starts a roscore (if none runs), the two verifier nodes and sets the replay's
# parameters; its own output goes to $ROVER_WS/demo_launch.log. The replay runs here in the
# foreground (replay_bag.py), so that its summary ends the demo and its exit status is the
# demo's; then the launch is shut down quietly.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/setup.sh"

log="$ROVER_WS/demo_launch.log"
rviz=0
for a in "$@"; do [ "$a" = "rviz:=true" ] && rviz=1; done
roslaunch --no-summary rover_loop_fusion demo.launch "$@" replay:=false > "$log" 2>&1 &
launch=$!
stop_launch() {
  kill -INT "$launch" 2>/dev/null || return 0
  wait "$launch" 2>/dev/null || true
}
trap stop_launch EXIT

# The replay starts once roslaunch has loaded the launch file (its parameters are on the
# parameter server); it then waits for the verifier nodes itself.
ready=0
for _ in $(seq 120); do
  if rosparam get /rover_demo/bag > /dev/null 2>&1; then ready=1; break; fi
  kill -0 "$launch" 2> /dev/null || break
  sleep 0.5
done
if [ "$ready" != 1 ]; then
  tail -n 20 "$log" >&2
  echo "[demo] roslaunch did not start the demo; log: $log" >&2
  exit 1
fi
[ "$rviz" = 1 ] && echo "[demo] rviz:=true: the demo ends when you close rviz"
/usr/bin/python3 "$ROVER_ROOT/scripts/replay_bag.py" __name:=rover_demo &
replay=$!
# Whichever ends first: the replay (the normal end), or roslaunch (a verifier node died).
first=""
wait -n -p first "$launch" "$replay" || true
if [ "$first" = "$launch" ]; then
  kill -INT "$replay" 2>/dev/null || true
  wait "$replay" 2>/dev/null || true
  sed 's/\x1b\[[0-9;]*m//g' "$log" | grep -E '\[(FATAL|ERROR)\]|process has died' >&2 || true
  echo "[demo] roslaunch stopped before the replay ended; log: $log" >&2
  exit 1
fi
rc=0
wait "$replay" || rc=$?
if [ "$rc" -ne 0 ]; then
  echo "[demo] the replay failed (exit status $rc); roslaunch's log: $log" >&2
elif [ "$rviz" = 1 ]; then
  wait "$launch" 2>/dev/null || true
fi
exit "$rc"
