#!/usr/bin/env python3
"""rover_verifier_node and rover_replay on every stamp and keyframe fault of
docs/failure-catalogue.md (issue 22: one stamp policy, in one place; issue 45: the faults that
combine): the shipped corridor with one fault each (roverlib.faults: one late stamp, two in a
row, a late stamp on another keyframe's stamp, a future stamp, a clock that stops, steps back or
stops and glitches, a repeated or deleted message, one or two bad first poses, a NaN or huge
pose, a jump, a relocation), replayed into a node started by the test and through rover_replay,
with every candidate message sent just after its query keyframe's and, again, just before it
(the node holds it until the keyframe comes). Both hosts must give the same verdicts, candidate
by candidate, and refuse the same keyframes (node_faults.test starts no node); no true loop is
lost beyond those that name the keyframes at fault (AT_FAULT).

Candidates name their keyframes by stamp, as the shipped bags do, except on the stopped clock,
where a stamp names several keyframes: there by number."""
import os
import tempfile
import unittest

import rospy

from test_node_hardening import Node  # test/ros/, beside this file (rostest runs it as a program)
from test_node_reliability import assert_same_verdicts, by_index, by_stamp, replay_rows
from roverlib import bag, bag_replay, faults, scenario

PKG = "rover_loop_fusion"
ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BY_NUMBER = {"frozen_stretch", "frozen_with_glitch"}
# The keyframes (clean indices) at fault, whose true loops a fault may cost: a keyframe refused
# (a bad pose or stamp, or one of the jump_confirmations - 1 a relocation or a new clock costs).
# Every other true loop of the clean run must be accepted. A stamp fault that is told apart (late
# stamps, a stopped clock, a repeat) costs none (issue 22 items 1, 2: a late stamp cost 3 true
# loops in the node, a stopped clock 26 of 31; issue 45: two late stamps 31 of 31 in the node
# with candidates before their keyframes, a stop with a glitch 12 of 31 in both).
AT_FAULT = {
    "late_stamp": set(), "two_late_stamps": set(), "frozen_stretch": set(), "frozen_with_glitch": set(),
    "repeated_keyframe": set(),
    "clock_step_back": {200, 201},  # refused until jump_confirmations confirm the new clock
    # Keyframe 100 on keyframe 120's stamp: from keyframe 120 on the stamp names 120, so a later
    # candidate that names keyframe 100 by it (340 -> 100) is verified against keyframe 120.
    "late_stamp_onto_another": {100},
    "late_stamp_beyond_bound": {100}, "future_stamp": {100}, "out_of_order_stamp": {100}, "huge_position": {100},
    "position_jump": {100}, "nan_pose": {100}, "non_unit_quaternion": {100},
}
# Faults that cost keyframe 0, whose loss is bounded by the decision, not by intake (failure
# catalogue row 71: without keyframe 0 a look-alike is the first loop after a 240 m lap): as many
# true loops as without keyframe 0 (rover_replay on deleted_first_keyframe), and every candidate
# that names a bad first keyframe invalid_input, "discredited" (not held without a prior).
FIRST_POSE = {"bad_first_keyframe": {0}, "two_bad_first_keyframes": {0, 1}, "two_first_keyframes_off": {0, 1},
              "deleted_first_keyframe": set()}
# Candidates not compared between the hosts: they name a keyframe by a stamp two keyframes carry
# (rover_replay names keyframes by number).
NOT_COMPARED = {"late_stamp_onto_another": {100}}
# Faults after which look-alikes get in (failure catalogue rows 35, 71): without keyframe 0 the
# lap's first true loop (into keyframe 0) is lost and a look-alike 1 m away is the first loop
# after 240 m (2 false); a relocation's released group of look-alikes (8 false). Named limits of
# the decision (issue 19), not of keyframe intake: every other fault lets no false loop in.
LOOKALIKES_IN = {"bad_first_keyframe", "two_bad_first_keyframes", "two_first_keyframes_off",
                 "deleted_first_keyframe", "relocation"}


class NodeFaults(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("node_faults")
        cls.clean = scenario.read(os.path.join(ROOT, "data", "corridor"))
        clean_rows = replay_rows(os.path.join(ROOT, "data", "corridor"), "--time_budget_ms", 0)
        cls.clean_tp = cls.true_accepted(cls.clean, clean_rows)
        cls.clean_accepted = [(int(r["query_index"]), int(r["match_index"])) for r in clean_rows if r["accepted"] == "1"]

    @staticmethod
    def true_accepted(s, rows):
        """(true, false) loops accepted in verdicts.csv rows of scenario s."""
        label = {(c.query, c.match): c.label for c in s.candidates}
        acc = [label.get((int(r["query_index"]), int(r["match_index"]))) for r in rows if r["accepted"] == "1"]
        return acc.count(1), acc.count(0)

    def run_fault(self, name, before):
        f = faults.inject(self.clean, name, by_number=name in BY_NUMBER, candidates_before=before)
        with tempfile.TemporaryDirectory() as d:
            faults.write(f, d)
            rows = replay_rows(d, "--time_budget_ms", 0)
            bag_path = os.path.join(d, "faulty.bag")
            bag.write_messages(f.messages, bag_path)
            node = Node(f"faults_{name}_{'before' if before else 'after'}",
                        {"optimize_period": 0.0, "rover/time_budget_ms": 0.0})
            try:
                client = bag_replay.VerifierClient(node.name)
                bag_replay.play(bag_path, [client], keyframes_first=True)  # the hosts see the same order
                verdicts = client.current()
                log = node.output()
            finally:
                node.stop()
        return f, rows, verdicts, log

    def check(self, name, before):
        f, rows, verdicts, log = self.run_fault(name, before)
        when = f"{name}, candidates {'before' if before else 'after'} their keyframes"
        self.assertEqual(len(rows), len(self.clean.candidates), when)
        key = by_index if name in BY_NUMBER else by_stamp
        skip = NOT_COMPARED.get(name, set())
        if skip:
            stamps = {round(k.stamp * 1e6) for k in f.scenario.keyframes}  # (every query keyframe was sent)
            clean_stamp = {k.index: round(k.stamp * 1e6) for k in self.clean.keyframes}
            keep = {clean_stamp[c.query] for c in self.clean.candidates if not {c.query, c.match} & skip}
            self.assertTrue(keep <= stamps, when)
            verdicts = [v for v in verdicts if by_stamp(v=v) in keep]
            rows = [r for r in rows if by_stamp(r=r) in keep]
        # Where the hosts verified one candidate against different keyframes, their graphs differ by
        # that loop: the later scores differ a little, not the decisions.
        assert_same_verdicts(self, verdicts, rows, key=key, scores=not skip)
        tp, fp = self.true_accepted(f.scenario, rows)
        at_fault = AT_FAULT.get(name)
        if at_fault is not None:
            naming = {(c.query, c.match) for c in self.clean.candidates if c.label == 1 and {c.query, c.match} & at_fault}
            allowed = sum(1 for q, m in self.clean_accepted if (q, m) in naming)
            self.assertGreaterEqual(tp, self.clean_tp[0] - allowed, f"{when}: true loops lost beyond the keyframes at "
                                    f"fault {sorted(at_fault)} ({tp} of {self.clean_tp[0]})")
        if name in FIRST_POSE:
            without_first = faults.inject(self.clean, "deleted_first_keyframe")
            with tempfile.TemporaryDirectory() as d:
                faults.write(without_first, d)
                reference = self.true_accepted(without_first.scenario, replay_rows(d, "--time_budget_ms", 0))[0]
            self.assertEqual(tp, reference, f"{when}: true loops beside those without keyframe 0")
            bad = FIRST_POSE[name]
            naming = [r for r in rows if {int(r["query_index"]), int(r["match_index"])} & bad]
            self.assertEqual(len(naming), sum(1 for c in self.clean.candidates if {c.query, c.match} & bad), when)
            for r in naming:
                self.assertEqual(r["reason"], "invalid_input", f"{when}: {r['query_index']}->{r['match_index']}")
                self.assertIn("discredited", r["detail"], when)
        if name not in LOOKALIKES_IN:
            self.assertEqual(fp, 0, f"{when}: false loops accepted")
        return f, rows, verdicts, log


def _add(name, before):
    def test(self):
        self.check(name, before)
    when = "before" if before else "after"
    test.__doc__ = (f"{name}: {faults.FAULTS[name][0]}, candidates {when} their keyframes (failure catalogue row "
                    f"{faults.FAULTS[name][1]})")
    setattr(NodeFaults, f"test_{name}_candidates_{when}", test)


for _name in faults.FAULTS:
    for _before in (False, True):
        _add(_name, _before)


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "node_faults", NodeFaults)
