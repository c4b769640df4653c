#!/usr/bin/env python3
"""rover_verifier_node and rover_replay against issue 22's reliability findings, each node started
by the test with its own parameters (node_reliability.test starts none):

- a repeated candidate (the same loop again), whose commit the verifier refuses: the node and
  rover_replay give it the same invalid_input verdict ("... refused to commit it"); neither
  reports it accepted."""
import csv
import math
import os
import subprocess
import sys
import tempfile
import unittest

import rospy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from test_node_hardening import Node  # noqa: E402
from roverlib import bag, bag_replay, scenario  # noqa: E402

PKG = "rover_loop_fusion"
ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def find_tool(name):
    for base in os.environ.get("CMAKE_PREFIX_PATH", "").split(":"):
        p = os.path.join(base, "lib", PKG, name)
        if base and os.path.exists(p):
            return p
    raise AssertionError(f"{name} not built")


def replay_rows(scenario_dir, *flags):
    """rover_replay's verdicts.csv rows on a scenario directory."""
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([find_tool("rover_replay"), "--scenario", scenario_dir, "--out", out, "--quiet"] +
                       [str(f) for f in flags], check=True, stdout=subprocess.DEVNULL)
        with open(os.path.join(out, "verdicts.csv")) as f:
            return list(csv.DictReader(f))


def node_verdicts(name, scenario_dir, params):
    """The verdicts of a rover_verifier_node started with `params` on the scenario's bag."""
    s = scenario.read(scenario_dir)
    bag_path = os.path.join(scenario_dir, "scenario.bag")
    bag.write_bag(s, bag_path)
    node = Node(name, dict({"optimize_period": 0.0}, **params))
    try:
        client = bag_replay.VerifierClient(node.name)
        bag_replay.play(bag_path, [client])
        return client.verdicts
    finally:
        node.stop()


class NodeReliability(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("node_reliability")

    def assertSameVerdicts(self, node, rows):
        """The node's verdicts and rover_replay's rows: the same candidates in the same order
        (keyframes numbered alike), the same reason, acceptance and score."""
        self.assertEqual(len(node), len(rows))
        for v, r in zip(node, rows):
            what = (f"{r['query_index']}->{r['match_index']}: rover_replay {r['reason']} {r['detail']!r}; "
                    f"node {v.reason} {v.detail!r}")
            self.assertEqual((v.query_index, v.match_index), (int(r["query_index"]), int(r["match_index"])), what)
            self.assertEqual((v.reason, int(v.accepted)), (r["reason"], int(r["accepted"])), what)
            if math.isnan(v.score):
                self.assertTrue(math.isnan(float(r["score"])), what)
            else:
                self.assertAlmostEqual(v.score, float(r["score"]), delta=1e-5, msg=what)

    def test_a_repeated_candidate_gets_the_same_verdict_from_the_node_and_rover_replay(self):
        # issue 22 item 4: the corridor's candidates of the first 250 keyframes, each proposed
        # twice in a row. The second of an accepted loop is accepted by verify() and refused
        # by commit() ("already in the graph"): rover_replay reported it accepted (TP counted
        # twice), the node invalid_input.
        s = scenario.read(os.path.join(ROOT, "data", "corridor"))
        s.keyframes = [k for k in s.keyframes if k.index < 250]
        s.truth = s.truth[:len(s.keyframes)]
        s.candidates = [c for c in s.candidates if c.query < 250 for _ in range(2)]
        with tempfile.TemporaryDirectory() as d:
            scenario.write(s, d)
            rows = replay_rows(d, "--time_budget_ms", 0)
            verdicts = node_verdicts("repeated", d, {"rover/time_budget_ms": 0.0})
        accepted = [r for r in rows if r["accepted"] == "1"]
        self.assertGreater(len(accepted), 3, "the scenario must hold accepted loops")
        keys = [(r["query_index"], r["match_index"]) for r in accepted]
        self.assertEqual(len(keys), len(set(keys)), "rover_replay reports a loop accepted twice")
        refused = [r for r in rows if "refused to commit it" in r["detail"]]
        self.assertEqual(len(refused), len(accepted), "every repeat of an accepted loop is refused")
        self.assertTrue(all(r["reason"] == "invalid_input" and "already in the graph" in r["detail"] for r in refused))
        self.assertSameVerdicts(verdicts, rows)
        self.assertEqual([v.detail.split("; but ")[-1] for v in verdicts if "refused to commit" in v.detail],
                         [r["detail"].split("; but ")[-1] for r in refused])


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "node_reliability", NodeReliability)
