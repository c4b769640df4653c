"""Stamp and keyframe faults injected into a scenario, the same for rover_replay and for
rover_verifier_node: the node and rover_replay must give the same verdicts on them
(test/ros/test_node_faults.py).

A fault changes the stream of keyframe pose messages as a faulty driver or VIO would send it:
a stamp late or early (one, or two in a row), a clock that stops or steps back, a bad or
missing first keyframe (or two bad ones), a pose that is not finite, a message repeated. Messages keep their arrival order (a late stamp does not make
the message arrive late). inject() returns both forms of the faulty run:

  - `scenario`: for rover_replay, keyframes numbered in arrival order (what the node numbers
    them: a deleted keyframe shifts the numbers, a repeated message takes one), with the faulty
    stamps and poses, and the candidates renumbered to match;
  - `messages`: for rover_verifier_node, (bag time, topic, message) with the faulty header
    stamps; bag time is the original stamp, so that the order is the arrival order. Candidates
    name their keyframes by stamp, the stamp the faulty keyframe message carried (what
    loop_fusion would publish), or by number (by_number=True: a clock that stops leaves stamps
    that cannot name a keyframe).

FAULTS lists the faults of docs/failure-catalogue.md that concern stamps and keyframes."""
import copy
import math
import os
from dataclasses import dataclass

import numpy as np

from . import bag as rbag
from . import geometry as g


@dataclass
class KeyframeMessage:
    index: int        # the keyframe of the clean scenario it comes from
    stamp: float      # header stamp as sent
    T: np.ndarray     # pose as sent (4x4; may hold NaN or a non-unit rotation)
    arrival: float    # bag time
    quaternion_scale: float = 1.0  # != 1: the message's quaternion is scaled (not unit)


@dataclass
class Faulted:
    name: str
    scenario: object          # roverlib.scenario.Scenario for rover_replay
    messages: list            # (bag time, topic, message) for the node
    keyframe_rows: list       # keyframes.csv rows as sent
    yaws: list                # relative yaw of each candidate (from the clean match pose)


def _each(first, last, edit):
    """A fault that applies edit(message, first message of keyframe `first`) to the messages
    of keyframes first .. last-1 (clean indices)."""
    def f(msgs):
        ref = next((m for m in msgs if m.index == first), None)
        for m in msgs:
            if first <= m.index < last:
                edit(m, ref)
        return msgs
    return f


def late(k, dt):
    def edit(m, _):
        m.stamp += dt
    return _each(k, k + 1, edit)


def stamp_of(k, stamp_fn):
    def f(msgs):
        st = {m.index: m.stamp for m in msgs}
        for m in msgs:
            if m.index == k:
                m.stamp = stamp_fn(st)
        return msgs
    return f


def position(k, fn):
    def edit(m, _):
        m.T = m.T.copy()
        m.T[0, 3] = fn(m.T[0, 3])
    return _each(k, k + 1, edit)


def shift_from(k, dx):
    def edit(m, _):
        m.T = m.T.copy()
        m.T[0, 3] += dx
    return _each(k, float("inf"), edit)


def shifted_stamps_from(k, dt):
    """Every stamp from keyframe k on moved by dt (a clock that steps: dt < 0 goes back)."""
    def edit(m, _):
        m.stamp += dt
    return _each(k, float("inf"), edit)


def frozen_stretch(k, n):
    """Stamps of keyframes k .. k+n-1 equal to k's (a clock that stalls, then recovers)."""
    def edit(m, ref):
        m.stamp = ref.stamp
    return _each(k, k + n, edit)


def burst(k, n):
    """Keyframes k .. k+n-1 (and their candidates) arrive at once, at keyframe k's time."""
    def edit(m, ref):
        m.arrival = ref.arrival
    return _each(k, k + n, edit)


def deleted(k):
    def f(msgs):
        return [m for m in msgs if m.index != k]
    return f


def repeated(k):
    def f(msgs):
        out = []
        for m in msgs:
            out.append(m)
            if m.index == k:
                again = copy.copy(m)
                again.arrival += 0.01
                out.append(again)
        return out
    return f


def quaternion(k, scale):
    def edit(m, _):
        m.quaternion_scale = scale
    return _each(k, k + 1, edit)


def _all(*fault_list):
    """One fault made of several, applied in order."""
    def f(msgs):
        for fault in fault_list:
            msgs = fault(msgs)
        return msgs
    return f


# name -> (what, the catalogue row, the fault as a function of the list of messages)
FAULTS = {
    "late_stamp": ("keyframe 100 stamped 1000 s late", "69", late(100, 1000.0)),
    "late_stamp_beyond_bound": ("keyframe 100 stamped 5e5 s late (beyond max_stamp_jump)", "69", late(100, 5e5)),
    "future_stamp": ("keyframe 100 stamped 4e9 s", "36", stamp_of(100, lambda st: 4e9)),
    "out_of_order_stamp": ("keyframe 100 stamped between keyframes 97 and 98", "6",
                           stamp_of(100, lambda st: 0.5 * (st[97] + st[98]))),
    "two_late_stamps": ("keyframes 100 and 101 stamped 1000 s late", "78", _all(late(100, 1000.0), late(101, 1000.0))),
    "clock_step_back": ("every stamp from keyframe 200 on 500 s earlier (a clock that steps back)", "78",
                        shifted_stamps_from(200, -500.0)),
    "late_stamp_onto_another": ("keyframe 100 stamped 10 s late, on keyframe 120's stamp", "81",
                                stamp_of(100, lambda st: st[120])),
    "frozen_stretch": ("every stamp from keyframe 200 on equal (a stalled clock)", "70", frozen_stretch(200, 10**9)),
    "frozen_with_glitch": ("every stamp from keyframe 200 on equal, and keyframe 250 stamped 1000 s late", "79",
                           _all(frozen_stretch(200, 10**9), late(250, 1000.0))),
    "repeated_keyframe": ("keyframe 100's message sent twice", "29", repeated(100)),
    "bad_first_keyframe": ("keyframe 0 at x = 5e7 m", "71", position(0, lambda x: 5e7)),
    "two_bad_first_keyframes": ("keyframes 0 and 1 at x = 5e7 m", "80",
                                _all(position(0, lambda x: 5e7), position(1, lambda x: 5e7 + 0.5))),
    "two_first_keyframes_off": ("keyframes 0 and 1 50 m off", "80",
                                _all(position(0, lambda x: x + 50.0), position(1, lambda x: x + 50.0))),
    "deleted_first_keyframe": ("keyframe 0 never sent", "71", deleted(0)),
    "huge_position": ("keyframe 100 at x + 1e30 m", "34", position(100, lambda x: x + 1e30)),
    "position_jump": ("keyframe 100 200 m off", "34", position(100, lambda x: x + 200.0)),
    "nan_pose": ("keyframe 100 with a NaN position", "1", position(100, lambda x: math.nan)),
    "non_unit_quaternion": ("keyframe 100 with |q| = 2", "2", quaternion(100, 2.0)),
    "relocation": ("every keyframe from 200 on 100 m away (the VIO relocated)", "35", shift_from(200, 100.0)),
}


def inject(s, name, by_number=False, candidates_before=False):
    """The scenario s (one sequence, keyframes in order) with the fault `name` of FAULTS."""
    return inject_all(s, name, [FAULTS[name][2]], by_number, candidates_before)


def inject_all(s, name, fault_list, by_number=False, candidates_before=False, repeats=None):
    """The scenario s with every fault of fault_list (functions of the list of messages: the
    makers above, late(), frozen_stretch(), burst(), ...), applied in order; `name` names the
    faulty run. candidates_before: each candidate message arrives CANDIDATE_DELAY before its
    query keyframe's message instead of after it (the node holds it until the keyframe comes).
    repeats: (first, last, times): the candidates whose query keyframe is in first .. last-1
    (clean indices) are sent `times` times each, one right after the other (a host that
    re-detects a loop, a bag played twice, a driver that retransmits), in both forms."""
    from . import scenario as rscenario
    msgs = [KeyframeMessage(k.index, k.stamp, k.T, k.stamp) for k in s.keyframes]
    for fault in fault_list:
        msgs = fault(msgs)
    number = {}  # clean index -> arrival number (the first message of it)
    for n, m in enumerate(msgs):
        number.setdefault(m.index, n)
    truth = {k.index: T for k, T in zip(s.keyframes, s.truth)} if s.truth is not None else None

    # rover_replay: keyframes numbered by arrival; candidates renumbered (a candidate naming a
    # keyframe never sent keeps a number no keyframe has: the number it would have had).
    clean = {k.index: k for k in s.keyframes}
    sequence = s.keyframes[0].sequence
    kfs = [rscenario.Keyframe(n, m.stamp, sequence, clean[m.index].T) for n, m in enumerate(msgs)]
    rows = []  # keyframes.csv as sent (a pose may be NaN, a quaternion not unit)
    for n, m in enumerate(msgs):
        q = g.matrix_to_quat(clean[m.index].T[:3, :3]) * m.quaternion_scale
        rows.append([str(n), f"{m.stamp:.9f}", str(sequence)] + [f"{v:.9f}" for v in m.T[:3, 3]] +
                    [f"{v:.9f}" for v in q])
    missing = sorted(set(clean) - set(number))

    def renumber(i):
        if i in number:
            return number[i]
        return len(msgs) + missing.index(i)

    def copies(c):
        if repeats and repeats[0] <= c.query < repeats[1]:
            return repeats[2]
        return 1

    sent_candidates = [c for c in s.candidates for _ in range(copies(c))]
    cands = []
    for c in sent_candidates:
        c2 = copy.copy(c)
        c2.query, c2.match = renumber(c.query), renumber(c.match)
        cands.append(c2)
    out = rscenario.Scenario(f"{s.name}+{name}", kfs, cands,
                             [truth[m.index] for m in msgs] if truth else None, dict(s.meta))
    yaws = [c.relative_yaw(clean[c.match].T) for c in sent_candidates]

    # the node: keyframe messages at their arrival time, candidates after their query keyframe
    sent = {}
    messages = []
    for n, m in enumerate(msgs):
        msg = rbag.keyframe_msg(m.stamp, m.T) if np.isfinite(m.T).all() else _raw_keyframe_msg(m.stamp, m.T)
        if m.quaternion_scale != 1.0:
            o = msg.pose.pose.orientation
            o.x, o.y, o.z, o.w = (v * m.quaternion_scale for v in (o.x, o.y, o.z, o.w))
        messages.append((m.arrival, rbag.KEYFRAME_TOPIC, msg))
        sent.setdefault(m.index, m)
    delay = -rbag.CANDIDATE_DELAY if candidates_before else rbag.CANDIDATE_DELAY
    for c, yaw in zip(sent_candidates, yaws):
        q, mt = sent.get(c.query), sent.get(c.match)
        q_stamp = q.stamp if q else clean[c.query].stamp
        m_stamp = mt.stamp if mt else clean[c.match].stamp
        qi, mi = (renumber(c.query), renumber(c.match)) if by_number else (-1, -1)
        arrival = (q.arrival if q else clean[c.query].stamp) + delay
        messages.append((arrival, rbag.CANDIDATE_TOPIC,
                         rbag.candidate_msg(q_stamp, m_stamp, c.T_rel, yaw, c.inliers,
                                            qi, mi)))
    messages.sort(key=lambda e: e[0])  # (stable: the copies of a candidate one after the other)
    return Faulted(name, out, messages, rows, yaws)


def write(f, directory):
    """The faulty scenario as a scenario directory for rover_replay: keyframes.csv as sent."""
    from . import scenario as rscenario
    os.makedirs(directory, exist_ok=True)
    if f.scenario.truth is not None:
        with open(os.path.join(directory, "groundtruth.csv"), "w") as out:
            out.write(rscenario.TRUTH_HEADER + "\n")
            for k, T in zip(f.scenario.keyframes, f.scenario.truth):
                out.write(",".join([str(k.index)] + [f"{v:.9f}" for v in rscenario._tq(T)]) + "\n")
    with open(os.path.join(directory, "keyframes.csv"), "w") as out:
        out.write(f"# scenario {f.scenario.name}\n" + rscenario.KEYFRAMES_HEADER + "\n")
        out.writelines(",".join(r) + "\n" for r in f.keyframe_rows)
    with open(os.path.join(directory, "candidates.csv"), "w") as out:
        out.write(rscenario.CANDIDATES_HEADER + "\n")
        for c, yaw in sorted(zip(f.scenario.candidates, f.yaws), key=lambda e: e[0].query):
            out.write(",".join([str(c.query), str(c.match)] + [f"{v:.9f}" for v in rscenario._tq(c.T_rel)] +
                               [f"{yaw:.9f}", str(c.inliers), str(c.label)]) + "\n")


def _raw_keyframe_msg(stamp, T):
    """A keyframe message whose pose is not finite (keyframe_msg would need a rotation)."""
    from nav_msgs.msg import Odometry
    m = Odometry()
    m.header.stamp = rbag.ros_time(stamp)
    m.header.frame_id = rbag.FRAME
    p = m.pose.pose
    p.position.x, p.position.y, p.position.z = (float(v) for v in T[:3, 3])
    p.orientation.w = 1.0
    return m
