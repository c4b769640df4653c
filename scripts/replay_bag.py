#!/usr/bin/env python3
"""Plays a scenario bag into rover_verifier_node (and an accept-all baseline node) and prints
a summary against the labels: candidates, verdicts per reason (gate, score, ...) and label,
precision, recall, and the ATE of the odometry, of loop_fusion's optimisation with every loop
(accept-all) and with the verified loops. The demo's replay (launch/demo.launch; scripts/demo.sh
runs it in the foreground): exits 0 after the summary, 1 with "[replay] FAILED: why" when the
bag or the labels cannot be read or a verifier node does not answer.

Private parameters:
  ~bag        the bag (scripts/roverlib/bag.py: /vins_estimator/keyframe_pose + /loop_fusion/loop_candidates)
  ~labels     scenario directory with candidates.csv / groundtruth.csv ('' = the bag's directory)
  ~verifier   the verifying node (default /rover_verifier)
  ~baseline   the accept-all node ('' = none)
  ~rate       > 0: pace at rate x bag time (rviz); 0 (default): as fast as the nodes verify
  ~verbose    print every verdict of ~verifier (default true)

Run with /usr/bin/python3 after sourcing the workspace (roslaunch does both)."""
import os
import sys


import rospy  # noqa: E402

from roverlib import bag_replay  # noqa: E402


def failed(why):
    print(f"[replay] FAILED: {why}", file=sys.stderr, flush=True)
    return 1


def main():
    rospy.init_node("rover_replay_bag", disable_signals=False)
    bag = rospy.get_param("~bag")
    labels_dir = rospy.get_param("~labels", "") or bag_replay.default_labels_dir(bag)
    verifier = rospy.get_param("~verifier", "/rover_verifier")
    baseline = rospy.get_param("~baseline", "")
    rate = float(rospy.get_param("~rate", 0.0))
    verbose = bool(rospy.get_param("~verbose", True))

    clients = [bag_replay.VerifierClient(verifier)]
    if baseline:
        clients.append(bag_replay.VerifierClient(baseline))
    print(f"[replay] {bag} -> {', '.join(c.node for c in clients)}"
          + (f"; labels {labels_dir}" if labels_dir else "; no labels"), flush=True)
    try:
        labels, truth = bag_replay.load_labels(labels_dir) if labels_dir else ({}, {})
    except (OSError, ValueError, IndexError) as e:
        return failed(f"cannot read the labels in {labels_dir}: {e}")
    try:
        n_kf, n_cand = bag_replay.play(
            bag, clients, rate=rate,
            progress=lambda k, c: print(f"[replay] {k} keyframes, {c} candidates", flush=True))
    except bag_replay.ReplayError as e:
        return failed(str(e))
    scores = [bag_replay.score(c, labels, truth) for c in clients]
    if verbose:
        print(f"[replay] verdicts of {clients[0].node} ({scores[0].verifier}):")
        for v in sorted(clients[0].current(), key=lambda v: (v.query_stamp, v.match_stamp)):
            print(bag_replay.verdict_line(v, labels.get(bag_replay.verdict_key(v), -1)))
    print(f"[replay] {n_kf} keyframe poses, {n_cand} loop candidates replayed from {os.path.basename(bag)}")
    print(bag_replay.summary_text(scores[0], scores[1] if baseline else None), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
