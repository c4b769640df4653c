"""Plays a scenario bag into rover_verifier_node instances and scores what they did.

The player (play()) publishes the bag's keyframe poses and loop candidates like rosbag play,
with two differences that make a replay deterministic whatever the machine's load:
  - it starts once every verifier node is connected to both topics (rosbag play's
    --wait-for-subscribers waits for one subscriber);
  - before each keyframe it waits until every node has given a verdict on every candidate
    that could be decided so far, so that each candidate is verified against the keyframes
    up to its query keyframe, as loop_fusion does (rosbag play at a fixed rate can run ahead
    of a busy node). A candidate published before its keyframe still waits in the node.
Afterwards it calls each node's ~optimize service for the final trajectories.

Scoring (score()): verdicts against the labels of the scenario directory next to the bag and
the ATE (SE(3)-aligned position RMSE, Umeyama) of the odometry, of loop_fusion's optimisation
with the loops each node accepted and of the verifier's own estimate against the ground truth.

Needs rospy and the package's generated messages (source devel/setup.bash)."""
import bisect
import collections
import os
import threading
import time

import numpy as np

from . import alignment
from . import bag as rbag
from . import reasons
from . import scenario as rscenario


class ReplayError(RuntimeError):
    pass


class VerifierClient:
    """One rover_verifier_node: its verdicts and its ~optimize service."""

    def __init__(self, node):
        import rospy
        from rover_loop_fusion.msg import LoopVerdict
        self.node = node.rstrip("/")
        # LoopVerdict.msg: every candidate gets one final verdict; a held one first gets a
        # deferred verdict (final: false), a used loop may later get a revoking one.
        self.messages = []  # every verdict message, in arrival order
        self.verdicts = []  # the final verdict of each candidate (no revocations), in arrival order
        self.pending = {}  # (query stamp, match stamp) -> deferred verdicts of candidates still held
        self.revoked = set()  # keys of loops revoked after their accepting verdict
        self.result = None  # the Optimize response after play()
        self._cond = threading.Condition()
        self._sub = rospy.Subscriber(self.node + "/loop_verdicts", LoopVerdict, self._on_verdict,
                                     queue_size=100000)

    def _on_verdict(self, msg):
        with self._cond:
            self.messages.append(msg)
            key = verdict_key(msg)
            if not msg.final:
                self.pending.setdefault(key, []).append(msg)
            elif msg.decision == "revoke":
                self.revoked.add(key)
            else:
                if msg.decision in ("release", "drop") and self.pending.get(key):
                    self.pending[key].pop(0)  # the held candidate this decision ends
                    if not self.pending[key]:
                        del self.pending[key]
                self.verdicts.append(msg)
            self._cond.notify_all()

    def current(self):
        """Each candidate's verdict: its final one or, while it is held, its deferred one (a
        revocation since is in `revoked`: score() counts such a loop as not used)."""
        with self._cond:
            return list(self.verdicts) + [v for held in self.pending.values() for v in held]

    def wait_verdicts(self, n, timeout):
        """Waits until n candidates have a verdict (final, or deferred while held); False on
        timeout."""
        import rospy
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.verdicts) + sum(len(h) for h in self.pending.values()) < n:
                left = deadline - time.monotonic()
                if left <= 0 or rospy.is_shutdown():
                    return False
                self._cond.wait(min(left, 0.5))
        return True

    def connected(self):
        return self._sub.get_num_connections() > 0

    def optimize(self, keyframe_messages, timeout=60.0):
        """Calls ~optimize until the node has received every keyframe message published."""
        import rospy
        from rover_loop_fusion.srv import Optimize
        name = self.node + "/optimize"
        try:
            rospy.wait_for_service(name, timeout)
        except rospy.ROSException as e:
            raise ReplayError(f"{name}: {e}")
        call = rospy.ServiceProxy(name, Optimize)
        deadline = time.monotonic() + timeout
        while True:
            r = call()
            if r.keyframe_messages >= keyframe_messages or time.monotonic() > deadline:
                break
            time.sleep(0.05)
        if r.keyframe_messages < keyframe_messages:
            raise ReplayError(f"{self.node} received {r.keyframe_messages} of {keyframe_messages} keyframe messages")
        self.result = r
        return r


class _Decidable:
    """Mirrors rover_verifier_node's rule: a candidate is decided as soon as its query keyframe
    has arrived (by arrival number), or a keyframe message with its query stamp has arrived;
    otherwise it waits (up to the node's candidate_timeout: stamps need not increase, so no stamp
    is ever passed). A stamp of a keyframe stamped late (a later message is stamped before it) names
    the query keyframe only once the node's wait for a keyframe carrying it in order is over."""

    RECENT = 100  # the node's kRecentKept

    def __init__(self, tolerance):
        self.tol_us = int(round(tolerance * 1e6))
        self.count = 0
        self.stamps = []  # of the keyframe messages, sorted
        self.recent = collections.deque(maxlen=self.RECENT)
        self.late = set()  # stamps of keyframe messages a later message was stamped before

    def keyframe(self, msg):
        self.count += 1
        k = rbag.stamp_key(msg.header.stamp)
        self.late.update(r for r in self.recent if r > k)
        self.recent.append(k)
        bisect.insort(self.stamps, k)

    def __call__(self, msg):
        if msg.query_index >= 0:
            return msg.query_index < self.count
        k = rbag.stamp_key(msg.query_stamp)
        i = bisect.bisect_left(self.stamps, k - self.tol_us)
        j = bisect.bisect_right(self.stamps, k + self.tol_us)
        if i == j:
            return False
        return j - i > 1 or self.stamps[i] not in self.late


def play(bag_path, clients, rate=0.0, connect_timeout=60.0, step_timeout=60.0, final_timeout=60.0,
         stamp_tolerance=1e-3, keyframe_topic=None, candidate_topic=None, progress=None, keyframes_first=False):
    """Publishes the bag's keyframe poses and candidates into the nodes of `clients`.

    rate > 0: also paced at `rate` x the bag's time (for watching in rviz); 0: as fast as the
    nodes verify. keyframe_topic / candidate_topic: publish there instead of the bag's topics.
    keyframes_first: before a candidate, wait until every node has received the keyframe messages
    published before it (topics are not ordered with each other: a candidate may otherwise overtake
    the keyframes just before it, e.g. the one that shows an earlier keyframe was stamped late).
    Returns (keyframe messages, candidate messages) published. Raises ReplayError when a node
    does not connect or stops answering."""
    import rospy
    from nav_msgs.msg import Odometry
    from rover_loop_fusion.msg import LoopCandidate
    try:
        messages = rbag.read_bag(bag_path)
    except Exception as e:  # rosbag raises its own exceptions, OSError, ValueError, ...
        raise ReplayError(f"cannot read the bag {bag_path}: {e}") from e
    pubs = {}
    plan = []
    for t, topic, msg in messages:
        if msg._type == "nav_msgs/Odometry":
            kind, cls, topic = "kf", Odometry, keyframe_topic or topic
        elif msg._type == "rover_loop_fusion/LoopCandidate":
            kind, cls, topic = "cand", LoopCandidate, candidate_topic or topic
        else:
            continue  # a recorded run holds other topics too
        if topic not in pubs:
            pubs[topic] = rospy.Publisher(topic, cls, queue_size=100000)
        plan.append((t, kind, pubs[topic], msg))
    if not plan:
        raise ReplayError(f"{bag_path}: no keyframe poses or loop candidates")

    deadline = time.monotonic() + connect_timeout
    while not all(p.get_num_connections() >= len(clients) for p in pubs.values()) or \
            not all(c.connected() for c in clients):
        if rospy.is_shutdown():
            raise ReplayError("shut down before the verifier nodes subscribed")
        if time.monotonic() > deadline:
            raise ReplayError("the verifier nodes did not subscribe to " + ", ".join(sorted(pubs)) +
                              f" within {connect_timeout:.0f} s")
        time.sleep(0.05)

    decidable = _Decidable(stamp_tolerance)
    waiting = collections.deque()  # candidates published before they could be decided
    n_kf = n_decidable = n_cand = synced = 0
    start_wall, start_bag = time.monotonic(), plan[0][0].to_sec()
    for t, kind, pub, msg in plan:
        if rospy.is_shutdown():
            raise ReplayError("shut down")
        if rate > 0:
            delay = (t.to_sec() - start_bag) / rate - (time.monotonic() - start_wall)
            if delay > 0:
                time.sleep(delay)
        if kind == "kf":
            for c in clients:
                if not c.wait_verdicts(n_decidable, step_timeout):
                    raise ReplayError(f"{c.node}: {len(c.verdicts)} verdicts on {n_decidable} decidable "
                                      f"candidates after {step_timeout:.0f} s")
            pub.publish(msg)
            n_kf += 1
            decidable.keyframe(msg)
            for _ in range(len(waiting)):
                m = waiting.popleft()
                if decidable(m):
                    n_decidable += 1
                else:
                    waiting.append(m)
            if progress and n_kf % 100 == 0:
                progress(n_kf, n_cand)
        else:
            if keyframes_first and n_kf > synced:
                for c in clients:
                    c.optimize(n_kf, step_timeout)
                synced = n_kf
            pub.publish(msg)
            n_cand += 1
            if decidable(msg):
                n_decidable += 1
            else:
                waiting.append(msg)
    for c in clients:
        if not c.wait_verdicts(n_cand, final_timeout):
            raise ReplayError(f"{c.node}: {len(c.verdicts)} verdicts on {n_cand} candidates after "
                              f"{final_timeout:.0f} s")
    for c in clients:
        c.optimize(n_kf)
    return n_kf, n_cand


# ---- scoring ----------------------------------------------------------------------------------

def load_labels(scenario_dir):
    """(labels, truth): labels[(query key, match key)] = 1 / 0 / -1 for each candidate of
    candidates.csv, truth[stamp key] = 4x4 ground-truth pose (empty without groundtruth.csv).
    Keys: bag.stamp_key of the keyframes' stamps."""
    s = rscenario.read(scenario_dir)
    stamp = {k.index: k.stamp for k in s.keyframes}
    labels = {}
    for c in s.candidates:
        if c.query in stamp and c.match in stamp:
            labels[(rbag.stamp_key(stamp[c.query]), rbag.stamp_key(stamp[c.match]))] = c.label
    truth = {}
    if s.truth is not None:
        for k, T in zip(s.keyframes, s.truth):
            if T is not None:
                truth[rbag.stamp_key(k.stamp)] = T
    return labels, truth


def verdict_key(v):
    return rbag.stamp_key(v.query_stamp), rbag.stamp_key(v.match_stamp)


def ate(path, truth):
    """SE(3)-aligned position RMSE [m] of a nav_msgs/Path against truth (by stamp), as
    roverlib.alignment computes it; NaN if fewer than 3 poses match or they cannot be aligned."""
    est, ref = [], []
    for p in path.poses:
        T = truth.get(rbag.stamp_key(p.header.stamp))
        if T is not None:
            est.append([p.pose.position.x, p.pose.position.y, p.pose.position.z])
            ref.append(T[:3, 3])
    if len(est) < 3:
        return float("nan")
    try:
        return alignment.ate(np.array(ref).T, np.array(est).T, "se3")
    except alignment.AlignmentError:
        return float("nan")


Score = collections.namedtuple("Score", "candidates accepted rejected tp fp tn fn unlabelled precision recall "
                                        "reasons threshold verifier ate_odometry ate_pose_graph ate_estimate "
                                        "reason_labels")


def score(client, labels, truth):
    tp = fp = tn = fn = unlabelled = 0
    by_reason = collections.Counter()
    reason_labels = collections.Counter()  # (reason, label 1 / 0 / -1) -> verdicts
    thresholds = set()
    verdicts = client.current()
    accepted = 0
    for v in verdicts:
        used = v.accepted and verdict_key(v) not in client.revoked
        accepted += used
        reason = "revoked" if v.accepted and not used else v.reason
        by_reason[reason] += 1
        if np.isfinite(v.threshold):
            thresholds.add(round(v.threshold, 6))
        label = labels.get(verdict_key(v), -1)
        reason_labels[(reason, label)] += 1
        if label == 1:
            tp += used
            fn += not used
        elif label == 0:
            fp += used
            tn += not used
        else:
            unlabelled += 1
    r = client.result
    return Score(len(verdicts), accepted, len(verdicts) - accepted, tp, fp, tn, fn, unlabelled,
                 tp / (tp + fp) if tp + fp else float("nan"), tp / (tp + fn) if tp + fn else float("nan"),
                 dict(by_reason), sorted(thresholds), verdicts[0].verifier if verdicts else "",
                 ate(r.odometry, truth) if r else float("nan"), ate(r.pose_graph, truth) if r else float("nan"),
                 ate(r.estimate, truth) if r and r.estimate.poses else float("nan"), dict(reason_labels))


def verdict_line(v, label):
    lab = {1: "true ", 0: "false"}.get(label, "  ?  ")
    score_text = f"{v.score:6.3f} m" if np.isfinite(v.score) else "       -"
    return (f"  {v.query_index:5d} -> {v.match_index:5d}  {lab}  {'ACCEPT' if v.accepted else 'reject'}  "
            f"{v.reason:<22s} score {score_text}  {v.elapsed_ms:6.2f} ms")


def _ratio(x):
    """A precision or recall; '-' for none (no decisions to take it from)."""
    return f"{x:.3f}" if np.isfinite(x) else "-"


def reason_table(s):
    """Verdicts per reason, one column per label present (true / false / unlabelled)."""
    columns = [(lab, name) for lab, name in ((1, "true"), (0, "false"), (-1, "unlabelled"))
               if any(l == lab for _, l in s.reason_labels)]
    order = list(reasons.NOTES) + sorted({r for r, _ in s.reason_labels} - set(reasons.NOTES))
    rows = [(f"{r} ({reasons.NOTES[r]})" if r in reasons.NOTES else r,
             [s.reason_labels.get((r, lab), 0) for lab, _ in columns])
            for r in order if any(s.reason_labels.get((r, lab), 0) for lab, _ in columns)]
    width = max([len(name) + 2 for name, _ in rows] + [len("verdicts by reason")])
    lines = ["  " + "verdicts by reason".ljust(width) + "".join(f"{name:>7s}" for _, name in columns)]
    lines += ["    " + name.ljust(width - 2) + "".join(f"{n:7d}" for n in counts) for name, counts in rows]
    return lines


def summary_text(verified, accept_all=None):
    """The demo's summary: the verifying node's verdicts (per reason and label) and the ATE of
    every trajectory."""
    s = verified
    thr = ", ".join(f"{t:g}" for t in s.threshold) or "-"
    lines = [
        f"summary: {s.candidates} candidates ({s.tp + s.fn} true, {s.fp + s.tn} false"
        + (f", {s.unlabelled} unlabelled" if s.unlabelled else "") + f"): accepted {s.accepted}, rejected {s.rejected}",
    ] + reason_table(s) + [
        f"  true positives {s.tp}, false positives {s.fp}, true negatives {s.tn}, false negatives {s.fn}",
        f"  precision {_ratio(s.precision)}, recall {_ratio(s.recall)} (threshold {thr} m)",
    ]
    if np.isfinite(s.ate_odometry):
        ates = [f"odometry {s.ate_odometry:.3f}"]
        if accept_all is not None:
            ates.append(f"accept-all (loop_fusion) {accept_all.ate_pose_graph:.3f}")
        ates.append(f"verified (loop_fusion) {s.ate_pose_graph:.3f}")
        if np.isfinite(s.ate_estimate):
            ates.append(f"verifier estimate {s.ate_estimate:.3f}")
        lines.append("  ATE [m]: " + " | ".join(ates))
    else:
        lines.append("  ATE: no ground truth (groundtruth.csv) for these keyframes")
    if accept_all is not None:
        lines.append(f"  accept-all: accepted {accept_all.accepted} of {accept_all.candidates} "
                     f"(false positives {accept_all.fp}, precision {_ratio(accept_all.precision)})")
    return "\n".join(lines)


def default_labels_dir(bag_path):
    """The scenario directory of a bag: the directory it is in, if it holds candidates.csv."""
    d = os.path.dirname(os.path.abspath(bag_path))
    return d if os.path.exists(os.path.join(d, "candidates.csv")) else ""
