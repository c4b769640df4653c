#!/usr/bin/env python3
"""Repeated candidate messages over both hosts (issue 45): every candidate of the shipped scenes
and of a relocation scene (the corridor's keyframes from 180 on shifted +100 m, its true
candidates and the false 204 -> 21) sent 1, 2, 3 and 10 times, interleaved (round after round
of all candidates: the copies of one query keyframe's candidates take turns). Copies are one
piece of evidence (core/verifier.h), so per candidate the result must be what it was sent once:
the first copy as sent once, each further copy what its first candidate got (a copy of a loop
accepted at verify refused, "already in the graph"); and rover_verifier_node = rover_replay =
evaluate.py (the node's verdict log read as each candidate's final verdict). Under the default
rule (decision metric) on every scene, and under the opt-in decision revisit on the relocation
scene and the corridor (repeats.test starts no node: the test starts one per run)."""
import csv
import importlib.util
import os
import re
import subprocess
import tempfile
import unittest

import rospy

from test_node_hardening import Node  # test/ros/, beside this file (rostest runs it as a program)
from test_node_reliability import assert_same_verdicts, find_tool
from roverlib import bag, bag_replay, metrics, repeats, scenario

PKG = "rover_loop_fusion"
ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
COUNTS = (1, 2, 3, 10)


def _evaluate_module():
    spec = importlib.util.spec_from_file_location("rover_evaluate", os.path.join(ROOT, "scripts", "evaluate.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


evaluate = _evaluate_module()


def scene(name):
    corridor = scenario.read(os.path.join(ROOT, "data", "corridor"))
    if name == "relocated":
        return repeats.relocated(corridor, 180, 100.0, (204, 21))
    return corridor if name == "corridor" else scenario.read(os.path.join(ROOT, "data", name))


def replay(scenario_dir, out, *flags):
    """rover_replay on a scenario directory: its verdicts.csv rows and its printed TP FP TN FN."""
    text = subprocess.run([find_tool("rover_replay"), "--scenario", scenario_dir, "--out", out, "--quiet"] +
                          [str(f) for f in flags], check=True, capture_output=True, text=True).stdout
    figures = tuple(int(x) for x in re.search(r"TP (\d+) FP (\d+) TN (\d+) FN (\d+)", text).groups())
    with open(os.path.join(out, "verdicts.csv")) as f:
        return list(csv.DictReader(f)), figures


def decisions(path, labels_path):
    """evaluate.py on a verdict log: each candidate's final verdict row (as it scores them,
    checked against the label file) and its decision figures."""
    rows = evaluate.final_verdicts(path, evaluate.read_verdict_rows(path))
    labels = evaluate.read_labels(labels_path)
    evaluate.check_correspondence(path, rows, labels_path, labels)
    j = metrics.join([r for _, r in rows], labels)
    d = metrics.decision_metrics(j["label"], j["accepted"])
    return [r for _, r in rows], (d["tp"], d["fp"], d["tn"], d["fn"])


class Repeats(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("repeats")

    def run_hosts(self, s, n, rule):
        """rover_replay and a node on s with every candidate sent n times: (rover_replay's rows,
        its printed TP FP TN FN, the node's verdicts, evaluate.py on the node's log: rows,
        figures; evaluate.py's figures on rover_replay's verdicts.csv)."""
        sn = repeats.repeated(s, n)
        with tempfile.TemporaryDirectory() as d:
            scenario.write(sn, d)
            out = os.path.join(d, "replay")
            rows, printed = replay(d, out, "--time_budget_ms", 0, "--decision", rule)
            log = os.path.join(d, "node_verdicts.csv")
            bag_path = os.path.join(d, "scenario.bag")
            bag.write_bag(sn, bag_path)
            node = Node(f"repeats_{rule}_{n}", {"optimize_period": 0.0, "rover/time_budget_ms": 0.0,
                                                 "rover/decision": rule, "verdict_log": log})
            try:
                client = bag_replay.VerifierClient(node.name)
                bag_replay.play(bag_path, [client])
                verdicts = client.current()
            finally:
                node.stop()
            labels = os.path.join(d, "candidates.csv")
            node_rows, node_figures = decisions(log, labels)
            _, replay_figures = decisions(os.path.join(out, "verdicts.csv"), labels)
        return rows, printed, verdicts, node_rows, node_figures, replay_figures

    def check(self, name, rule):
        s = scene(name)
        keys = [(c.query, c.match) for c in s.candidates]
        self.assertEqual(len(keys), len(set(keys)), f"{name}: pairs must be unique sent once")
        once = None
        for n in COUNTS:
            what = f"{name}, decision {rule}, sent {n} times"
            rows, printed, verdicts, node_rows, node_figures, replay_figures = self.run_hosts(s, n, rule)
            if once is None:
                self.assertEqual(n, 1)
                once = rows
            problems = repeats.check_copies(once, rows, n)
            self.assertEqual(problems, [], f"{what}: rover_replay: " + "; ".join(problems[:5]))
            assert_same_verdicts(self, verdicts, rows)
            # evaluate.py reads the node's whole log as each candidate's final verdict: the rows
            # of rover_replay, pair by pair in order, with the scores measured at verify.
            got, want = repeats.by_pair(node_rows), repeats.by_pair(rows)
            self.assertEqual(sorted(got), sorted(want), f"{what}: evaluate.py on the node's log")
            for key in want:
                self.assertEqual([(r["accepted"], r["reason"], repeats.score(r)) for r in got[key]],
                                 [(r["accepted"], r["reason"], repeats.score(r)) for r in want[key]],
                                 f"{what}: {key}: evaluate.py on the node's log")
            self.assertEqual(node_figures, replay_figures, f"{what}: evaluate.py on the node's log and on rover_replay's")
            self.assertEqual(replay_figures, printed, f"{what}: evaluate.py and rover_replay's own figures")
            if name == "relocated" and rule == "metric":
                # the false candidate counts once: nothing confirms it, and no true loop is lost
                # (each pair accepted by one of its rows at least; copies of an accepted loop
                # are refused)
                label = {(c.query, c.match): c.label for c in s.candidates}
                used = {key for key, rs in repeats.by_pair(rows).items() if any(r["accepted"] == "1" for r in rs)}
                self.assertEqual(used, {key for key, lab in label.items() if lab == 1}, what)


def _add(name, rule):
    def test(self):
        self.check(name, rule)
    test.__doc__ = f"{name} under decision {rule}: every candidate sent {', '.join(map(str, COUNTS))} times"
    setattr(Repeats, f"test_{name}_{rule}", test)


for _name in ("corridor", "warehouse", "euroc_mh05", "relocated"):
    _add(_name, "metric")
for _name in ("relocated", "corridor"):
    _add(_name, "revisit")


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "repeats", Repeats)
