#!/usr/bin/env python3
"""rover_verifier_node survives a bag of malformed messages (test/data/malformed, made by
scripts/make_shipped_data.py: NaN and non-unit keyframe poses, duplicate and out-of-order
keyframes, candidates with unknown, refused, zero or never-arriving stamps, NaN and non-unit
relative poses, a loop to itself, a match newer than its query, an implausible translation,
a candidate recorded before its keyframe, keyframes named by number) and gives exactly one
verdict per candidate: the one expected.csv lists, with a ROS_WARN for every refused
keyframe and every invalid_input verdict; regular candidates in between are still verified."""
import os
import threading
import time
import unittest

import rospkg
import rospy
from rosgraph_msgs.msg import Log

PKG = "rover_loop_fusion"
ROOT = rospkg.RosPack().get_path(PKG)

from roverlib import bag as rbag  # noqa: E402
from roverlib import bag_replay  # noqa: E402

DATA = os.path.join(ROOT, "test", "data", "malformed")
REFUSED_KEYFRAMES = 5  # NaN position, |q| = 2, q = 0, a duplicate, an out-of-order stamp


class MalformedBag(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("malformed_bag")
        cls.node = "/rover_verifier"
        cls.warnings = []
        cls.lock = threading.Lock()
        # Straight from the node's /rosout publisher (rostest runs no rosout aggregator).
        sub = rospy.Subscriber("/rosout", Log, cls.on_log, queue_size=10000)
        deadline = time.monotonic() + 30.0
        while not any(getattr(c, "callerid_pub", "") == cls.node for c in sub.impl.connections):
            if time.monotonic() > deadline:
                raise RuntimeError(f"not connected to the /rosout publisher of {cls.node}")
            time.sleep(0.05)
        cls.client = bag_replay.VerifierClient(cls.node)
        cls.n_kf, cls.n_cand = bag_replay.play(os.path.join(DATA, "malformed.bag"), [cls.client])
        cls.expected = rbag.read_expected(DATA)
        cls.by_key = {}
        for v in cls.client.verdicts:
            cls.by_key.setdefault(bag_replay.verdict_key(v), []).append(v)

    @classmethod
    def on_log(cls, m):
        if m.name == cls.node and m.level == Log.WARN:
            with cls.lock:
                cls.warnings.append(m.msg)

    def expected_verdict(self, e):
        key = (rbag.stamp_key(e["query_stamp"]), rbag.stamp_key(e["match_stamp"]))
        vs = self.by_key.get(key, [])
        self.assertEqual(len(vs), 1, f"{e['name']}: {len(vs)} verdicts")
        return vs[0]

    def test_the_node_keeps_running(self):
        r = self.client.result  # the ~optimize call after the bag
        self.assertTrue(r.success, r.message)
        self.assertEqual(r.keyframe_messages, self.n_kf)
        self.assertEqual(r.keyframes, self.n_kf - REFUSED_KEYFRAMES)
        self.assertEqual(r.candidates_waiting, 0)
        self.assertEqual(len(r.pose_graph.poses), r.keyframes)
        self.assertGreater(r.loops, 0)

    def test_one_verdict_per_candidate_as_expected(self):
        self.assertEqual(self.n_cand, len(self.expected))
        self.assertEqual(len(self.client.verdicts), self.n_cand)
        for e in self.expected:
            v = self.expected_verdict(e)
            what = f"{e['name']} ({e['why']}): {v.reason}: {v.detail}"
            self.assertTrue(v.detail, what)
            self.assertEqual(v.header.frame_id, "world", what)
            self.assertEqual(v.verifier, "rover_loop_fusion/TrajectoryPriorVerifier", what)
            if e["expect"] == "invalid_input":
                self.assertEqual(v.reason, "invalid_input", what)
                self.assertFalse(v.accepted, what)
            elif e["expect"] == "rejected":
                self.assertFalse(v.accepted, what)
            else:
                self.assertEqual(e["expect"], "decided")
                self.assertNotEqual(v.reason, "invalid_input", what)
                if v.reason in ("accepted", "score_above_threshold"):  # decided by the trial solve
                    self.assertTrue(v.converged, what)
                self.assertGreaterEqual(v.query_index, 0, what)

    def test_waiting_candidates(self):
        by_name = {e["name"]: self.expected_verdict(e) for e in self.expected}
        self.assertIn("candidate_timeout", by_name["keyframe_never_comes"].detail)
        early = by_name["before_its_keyframe"]
        self.assertTrue(early.accepted, early.detail)  # a true loop, verified once its keyframe came
        self.assertIn("refused", by_name["names_a_refused_keyframe"].detail)
        self.assertIn("NaN", by_name["names_a_refused_keyframe"].detail.replace("not finite", "NaN"))

    def test_regular_candidates_after_the_malformed_ones_are_verified(self):
        regular = [e for e in self.expected if e["why"] == "a regular candidate"]
        self.assertGreater(len(regular), 5)
        verdicts = [self.expected_verdict(e) for e in regular]
        self.assertTrue(any(v.accepted for v in verdicts[-5:]), "true loops at the end are accepted")

    def test_a_warning_for_every_refused_keyframe_and_invalid_verdict(self):
        n_invalid = sum(1 for v in self.client.verdicts if v.reason == "invalid_input")
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            with self.lock:
                refused = [w for w in self.warnings if "keyframe message" in w and "refused" in w]
                invalid = [w for w in self.warnings if "invalid_input" in w and "REJECTED" in w]
            if len(refused) >= REFUSED_KEYFRAMES and len(invalid) >= n_invalid:
                break
            time.sleep(0.1)
        self.assertEqual(len(refused), REFUSED_KEYFRAMES, refused)
        self.assertEqual(len(invalid), n_invalid, invalid)
        for kind in ("not finite", "unit quaternion", "duplicate", "out of order"):
            self.assertTrue(any(kind in w for w in refused), f"no warning says '{kind}': {refused}")


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "malformed_bag", MalformedBag)
