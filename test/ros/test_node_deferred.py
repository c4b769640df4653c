#!/usr/bin/env python3
"""rover_verifier_node with held candidates (node_deferred.test starts no node; the test starts
its own, with the default ~relocalisation: confirm).

A corridor driven twice with one VIO relocation between the passes (a 50 m jump: the verifier
starts a new segment, which no loop ties to the first pass yet): candidates between the passes
have no trajectory prior, so each is held (a deferred verdict, final false). Three true ones
that agree are released together (decision release, accepted), a look-alike held before them is
dropped (decision drop, reason unconfirmed), a later true loop is verified against the prior at
once. A third pass after a second relocation leaves one candidate held when the node gets
SIGINT: it gets its final verdict then. Every candidate has exactly one final verdict, every
loop in use exactly one accepting verdict, and the node's loop_fusion stand-in holds exactly the
used loops."""
import os
import signal
import tempfile
import unittest

import rospy
from visualization_msgs.msg import MarkerArray

from test_node_hardening import Node, Verdicts, candidate, keyframe, publishers, wait_until  # test/ros/, beside this file
from rover_loop_fusion.srv import Optimize

PKG = "rover_loop_fusion"


def first_pass(i):
    """Stamp and VIO x of keyframe i of the first pass (0.5 m apart along x)."""
    return 1.0 + i, 0.5 * i


def second_pass(j):
    """The same places again; the VIO relocated by 50 m in y."""
    return 100.0 + j, 0.5 * j


def third_pass(j):
    return 200.0 + j, 0.5 * j


class Markers:
    def __init__(self, node):
        self.msgs = []
        self.sub = rospy.Subscriber(node + "/loop_markers", MarkerArray, self.msgs.append, queue_size=None)


class NodeDeferred(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("node_deferred")

    def test_held_candidates_get_one_final_verdict_and_released_loops_enter_the_graph(self):
        log = tempfile.NamedTemporaryFile(suffix=".csv", delete=False).name
        os.unlink(log)
        node = Node("deferred", {"optimize_period": 0.0, "candidate_timeout": 30.0, "verdict_log": log})
        try:
            verdicts = Verdicts(node.name)
            markers = Markers(node.name)
            self.assertTrue(verdicts.connected())
            kf, cand = publishers(node.name)

            def send(c, n):
                cand.publish(c)
                self.assertTrue(verdicts.wait(n, 60.0), f"{len(verdicts.msgs)} of {n} verdicts: "
                                f"{[(v.reason, v.detail) for v in verdicts.msgs]}")

            for i in range(60):
                kf.publish(keyframe(*first_pass(i)))
            for j in range(5):
                kf.publish(keyframe(second_pass(j)[0], second_pass(j)[1], 50.0))
            lookalike = candidate(second_pass(4)[0], first_pass(24)[0])  # claims to be 10 m further on
            send(lookalike, 1)
            true_ones = []
            for j in range(5, 13):
                kf.publish(keyframe(second_pass(j)[0], second_pass(j)[1], 50.0))
                if j >= 10:
                    true_ones.append(candidate(second_pass(j)[0], first_pass(j)[0]))
                    send(true_ones[-1], len(true_ones) + 1 + (4 if j == 12 else 0))
            for j in range(13, 21):
                kf.publish(keyframe(second_pass(j)[0], second_pass(j)[1], 50.0))
            later = candidate(second_pass(20)[0], first_pass(20)[0])
            send(later, 9)

            v = verdicts.msgs
            key = lambda m: (round(m.query_stamp.to_sec()), round(m.match_stamp.to_sec()))  # noqa: E731
            # held: the look-alike and the three true ones, each with a deferred verdict first
            for m in v[:4]:
                self.assertEqual((m.reason, m.final, m.accepted, m.decision), ("deferred", False, False, "verify"),
                                 m.detail)
            self.assertEqual([key(m) for m in v[:4]], [key(c) for c in [lookalike] + true_ones])
            # confirmed by the third: released together, the look-alike dropped
            released, dropped = v[4:7], v[7]
            self.assertEqual([key(m) for m in released], [key(c) for c in true_ones])
            for m in released:
                self.assertEqual((m.reason, m.final, m.accepted, m.decision), ("accepted", True, True, "release"),
                                 m.detail)
            self.assertEqual(key(dropped), key(lookalike))
            self.assertEqual((dropped.reason, dropped.final, dropped.accepted, dropped.decision),
                             ("unconfirmed", True, False, "drop"), dropped.detail)
            # tied now: the next true loop is verified against the prior at once
            self.assertEqual((v[8].reason, v[8].final, v[8].decision), ("accepted", True, "verify"), v[8].detail)

            # The node's loop_fusion stand-in holds the three released loops and the later one.
            optimize = rospy.ServiceProxy(node.name + "/optimize", Optimize)
            self.assertEqual(optimize().loops, 4)

            # Markers: the released loops' amber markers turn green (same id), the dropped one red.
            self.assertTrue(wait_until(lambda: len(markers.msgs) >= 9))
            held_ids = [a.markers[-1].id for a in markers.msgs[:4]]
            for a, held_id, ns in zip(markers.msgs[4:8], held_ids[1:] + held_ids[:1],
                                      ["accepted_loops"] * 3 + ["rejected_loops"]):
                self.assertEqual([(mk.action, mk.ns, mk.id) for mk in a.markers],
                                 [(2, "held_loops", held_id), (2, "held_loops_score", held_id),
                                  (0, ns, held_id), (0, ns + "_score", held_id)])

            # A third pass after another relocation: one candidate held when SIGINT comes.
            for j in range(16):
                kf.publish(keyframe(third_pass(j)[0], third_pass(j)[1], 100.0))
            last = candidate(third_pass(15)[0], first_pass(15)[0])
            send(last, 10)
            self.assertEqual(verdicts.msgs[9].reason, "deferred", verdicts.msgs[9].detail)
            node.proc.send_signal(signal.SIGINT)
            self.assertEqual(node.wait_exit(60.0), 0)
            self.assertTrue(verdicts.wait(11, 30.0), f"{len(verdicts.msgs)} of 11 verdicts")
            final = verdicts.msgs[10]
            self.assertEqual(key(final), key(last))
            self.assertEqual((final.reason, final.final, final.decision), ("unconfirmed", True, "drop"))
            self.assertIn("still held when the node was shut down", final.detail)

            # Every candidate: exactly one final verdict; every used loop: one accepting verdict.
            finals, accepting = {}, {}
            for m in verdicts.msgs:
                finals[key(m)] = finals.get(key(m), 0) + m.final
                accepting[key(m)] = accepting.get(key(m), 0) + m.accepted
            self.assertEqual(sorted(finals.values()), [1] * 6)
            self.assertEqual(sorted(accepting.values()), [0, 0, 1, 1, 1, 1])
            # The CSV log: the same verdicts, with final and decision.
            with open(log) as f:
                rows = [line.rstrip("\n") for line in f if line.strip()]
            self.assertTrue(rows[0].endswith(",detail,final,decision"), rows[0])
            self.assertEqual([r.rsplit(",", 2)[1:] for r in rows[1:]],
                             [["0", "verify"]] * 4 + [["1", "release"]] * 3 + [["1", "drop"], ["1", "verify"],
                                                                              ["0", "verify"], ["1", "drop"]])
        finally:
            node.stop()
            if os.path.exists(log):
                os.unlink(log)


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "node_deferred", NodeDeferred)
