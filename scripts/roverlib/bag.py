"""Scenario directories as rosbags, what rover_verifier_node replays.

A scenario bag holds two topics, the ones rover_verifier_node subscribes to by default and
the ones a recorded run of VINS-Fusion with the patched loop_fusion holds:

  /vins_estimator/keyframe_pose   nav_msgs/Odometry: one per keyframe, header.stamp = the
                                  keyframe's stamp, frame "world", pose = the VIO pose
  /loop_fusion/loop_candidates    rover_loop_fusion/LoopCandidate: keyframes named by stamp
                                  (query_index = match_index = -1), relative pose, relative
                                  yaw [rad] (loop_fusion's: the difference of world yaws,
                                  geometry.loop_yaw), inliers; recorded right after its query keyframe

The labels stay in the scenario directory next to the bag (candidates.csv: label per
candidate; groundtruth.csv: ground truth per keyframe; keyframes.csv gives the stamps that
tie both to the bag's messages). See docs/scenario-format.md.

Needs the ROS Python modules (/usr/bin/python3) and this package's generated messages
(source the workspace's devel/setup.bash)."""
import math
import os

import numpy as np

from . import geometry as g

KEYFRAME_TOPIC = "/vins_estimator/keyframe_pose"
CANDIDATE_TOPIC = "/loop_fusion/loop_candidates"
BAG_NAME = "scenario.bag"
FRAME = "world"
# Bag time of a candidate after its query keyframe's (loop_fusion publishes a candidate after
# the keyframe pose it was detected on).
CANDIDATE_DELAY = 1e-3


def ros_time(stamp):
    """rospy.Time of a stamp in seconds, rounded to the nanosecond (rospy's from_sec truncates)."""
    import rospy
    secs = math.floor(stamp)
    nsecs = int(round((stamp - secs) * 1e9))
    if nsecs >= 1000000000:
        secs, nsecs = secs + 1, nsecs - 1000000000
    return rospy.Time(int(secs), nsecs)


def stamp_key(t):
    """Key of a stamp (seconds or rospy.Time) for matching messages, verdicts and labels [us]."""
    if hasattr(t, "to_nsec"):
        return int(round(t.to_nsec() / 1000.0))
    return int(round(float(t) * 1e6))


def _pose_msg(T):
    from geometry_msgs.msg import Pose
    p = Pose()
    p.position.x, p.position.y, p.position.z = (float(v) for v in T[:3, 3])
    q = g.matrix_to_quat(T[:3, :3])
    p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = (float(v) for v in q)
    return p


def keyframe_msg(stamp, T):
    """nav_msgs/Odometry as vins_estimator publishes a keyframe pose."""
    from nav_msgs.msg import Odometry
    m = Odometry()
    m.header.stamp = ros_time(stamp)
    m.header.frame_id = FRAME
    m.pose.pose = _pose_msg(T)
    return m


def candidate_msg(query_stamp, match_stamp, T_rel, relative_yaw, inliers=-1, query_index=-1,
                  match_index=-1):
    """rover_loop_fusion/LoopCandidate: keyframes by stamp (indices -1) unless indices are given."""
    from rover_loop_fusion.msg import LoopCandidate
    m = LoopCandidate()
    m.header.stamp = ros_time(query_stamp)
    m.header.frame_id = FRAME
    m.query_index, m.match_index = int(query_index), int(match_index)
    m.query_stamp, m.match_stamp = ros_time(query_stamp), ros_time(match_stamp)
    m.relative_pose = _pose_msg(T_rel)
    m.relative_yaw = float(relative_yaw)
    m.inliers = int(inliers)
    return m


def scenario_messages(s):
    """(bag time [s], topic, message) of a Scenario, in bag order."""
    sequences = {k.sequence for k in s.keyframes}
    if len(sequences) > 1:
        raise ValueError(f"{s.name}: keyframes of sequences {sorted(sequences)}; a bag for "
                         "rover_verifier_node holds one session (its ~sequence parameter)")
    stamp = {k.index: k.stamp for k in s.keyframes}
    vio = {k.index: k.T for k in s.keyframes}
    out = [(k.stamp, KEYFRAME_TOPIC, keyframe_msg(k.stamp, k.T)) for k in s.keyframes]
    for c in s.candidates:
        if c.query not in stamp or c.match not in stamp:
            raise ValueError(f"{s.name}: candidate {c.query} -> {c.match} names an unknown keyframe")
        out.append((stamp[c.query] + CANDIDATE_DELAY, CANDIDATE_TOPIC,
                    candidate_msg(stamp[c.query], stamp[c.match], c.T_rel, c.relative_yaw(vio[c.match]),
                                  c.inliers)))
    out.sort(key=lambda e: e[0])  # stable: a candidate stays after its keyframe
    return out


def write_messages(messages, path):
    """Writes (bag time, topic, message) to a bag (bz2 chunks: small, and reproducible)."""
    import rosbag
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with rosbag.Bag(path, "w", compression=rosbag.Compression.BZ2) as bag:
        for t, topic, msg in messages:
            bag.write(topic, msg, ros_time(t))


def write_bag(s, path):
    """Writes a Scenario as a bag; returns (keyframes, candidates) written."""
    messages = scenario_messages(s)
    write_messages(messages, path)
    n_kf = sum(1 for _, topic, _ in messages if topic == KEYFRAME_TOPIC)
    return n_kf, len(messages) - n_kf


def read_bag(path, topics=None):
    """[(bag time as rospy.Time, topic, message)] of a bag, in bag order."""
    import rosbag
    with rosbag.Bag(path) as bag:
        return [(t, topic, msg) for topic, msg, t in bag.read_messages(topics=topics)]


# ---- the malformed-messages bag (test/data/malformed) ------------------------------------------

def malformed_messages(seed=0):
    """A corridor run (2 laps) with every kind of bad input rover_verifier_node must survive.

    Returns (messages, expectations): messages as for write_messages; expectations one dict
    per candidate message: name, query_stamp, match_stamp (what its verdict reports), expect
    ('invalid_input', 'decided' = any verdict but invalid_input, 'rejected' for a false loop),
    why."""
    from . import scenes
    s = scenes.make_scene("corridor", sigma=0.05, seed=seed, n_true=12, n_false=6, laps=2)
    kfs = s.keyframes
    st = [k.stamp for k in kfs]
    msgs, expect = [], []
    nan = float("nan")

    def kf(i, T=None, stamp=None, t=None):
        stamp = st[i] if stamp is None else stamp
        msgs.append((stamp if t is None else t, KEYFRAME_TOPIC, keyframe_msg(stamp, kfs[i].T if T is None else T)))

    def cand(name, q_stamp, m_stamp, T_rel, yaw, t, want, why, qi=-1, mi=-1, report=None):
        msgs.append((t, CANDIDATE_TOPIC, candidate_msg(q_stamp, m_stamp, T_rel, yaw, 40, qi, mi)))
        rq, rm = report if report else (q_stamp, m_stamp)
        expect.append(dict(name=name, query_stamp=rq, match_stamp=rm, expect=want, why=why))

    REFUSED = {20, 30, 60}  # keyframes sent malformed below
    by_query = {c.query: c for c in s.candidates}
    early = next(c for c in s.candidates if c.label == 1 and 150 < c.query < 200)
    nan_T = kfs[20].T.copy()
    nan_T[0, 3] = nan
    T_id = np.eye(4)
    arrival = 0  # rover_verifier_node numbers keyframe messages in arrival order
    index_of = {}
    for i in range(len(kfs)):
        extra = 0.0
        if i == early.query:  # the candidate is recorded before its keyframe
            cand("before_its_keyframe", st[i], st[early.match], early.T_rel,
                 early.relative_yaw(kfs[early.match].T), st[i] - 0.2, "decided",
                 "waits for its keyframe, then is verified")
        if i == 20:
            kf(i, T=nan_T)
            why = "NaN position"
        elif i == 30:
            T = kfs[i].T.copy()
            msgs.append((st[i], KEYFRAME_TOPIC, keyframe_msg(st[i], T)))
            msgs[-1][2].pose.pose.orientation.w *= 2.0  # |q| != 1
            why = "non-unit quaternion"
        elif i == 60:
            msgs.append((st[i], KEYFRAME_TOPIC, keyframe_msg(st[i], kfs[i].T)))
            o = msgs[-1][2].pose.pose.orientation
            o.x = o.y = o.z = o.w = 0.0
            why = "zero quaternion"
        else:
            kf(i)
            why = None
        index_of[i] = arrival
        arrival += 1
        if i == 40:  # the same keyframe again
            kf(i, t=st[i] + 0.01)
            arrival += 1
            extra = 0.01
        if i == 50:  # a keyframe older than the newest one
            kf(i, stamp=(st[48] + st[49]) / 2, t=st[i] + 0.01)
            arrival += 1
            extra = 0.01
        t = st[i] + 0.02 + extra
        c = by_query.get(i)
        if c is not None and c is not early and not {c.query, c.match} & REFUSED:
            want = "rejected" if c.label == 0 else "decided"
            cand(f"{'true' if c.label else 'false'}_{i}", st[i], st[c.match], c.T_rel,
                 c.relative_yaw(kfs[c.match].T), t, want, "a regular candidate")
        # bad candidates, each at its own query keyframe (none of them is a regular one)
        if i == 70:
            cand("unknown_query_stamp", st[i] + 0.25, st[5], T_id, 0.0, t, "invalid_input",
                 "no keyframe has that stamp")
        if i == 72:
            T = T_id.copy()
            T[1, 3] = nan
            cand("nan_relative_pose", st[i], st[5], T, 0.0, t, "invalid_input", "NaN in the relative pose")
        if i == 74:
            msgs.append((t, CANDIDATE_TOPIC, candidate_msg(st[i], st[5], T_id, 0.0, 40)))
            msgs[-1][2].relative_pose.orientation.w = 2.0
            expect.append(dict(name="non_unit_relative_quaternion", query_stamp=st[i], match_stamp=st[5],
                               expect="invalid_input", why="|q| = 2"))
        if i == 76:
            cand("names_a_refused_keyframe", st[20], st[5], T_id, 0.0, t, "invalid_input",
                 "keyframe 20 had a NaN position")
        if i == 78:
            cand("loop_to_itself", st[i], st[i], T_id, 0.0, t, "invalid_input", "query == match")
        if i == 80:
            cand("match_newer_than_query", st[60 - 5], st[i], T_id, 0.0, t, "invalid_input",
                 "the match must be the older keyframe")
        if i == 82:
            T = T_id.copy()
            T[0, 3] = 100.0
            cand("implausible_translation", st[i], st[5], T, 0.0, t, "invalid_input", "100 m")
        if i == 84:
            cand("zero_stamps", 0.0, 0.0, T_id, 0.0, t, "invalid_input", "stamps never set")
        if i == 86:
            T = T_id.copy()
            T[0, 3] = 0.1
            cand("keyframes_by_index", 0.0, 0.0, T, nan, t, "decided",
                 "named by arrival number, yaw NaN (taken from the pose)",
                 qi=index_of[i], mi=index_of[2], report=(st[i], st[2]))
        if i == 88:
            cand("keyframe_never_comes", st[-1] + 100.0, st[5], T_id, 0.0, t, "invalid_input",
                 "waits candidate_timeout, then invalid_input")
        if i == 90:
            cand("match_stamp_unknown", st[i], st[5] + 0.3, T_id, 0.0, t, "invalid_input",
                 "no keyframe has the match stamp")
    msgs.sort(key=lambda e: e[0])
    return msgs, expect


def write_malformed(directory, seed=0):
    """test/data/malformed: malformed.bag + expected.csv (one row per candidate message)."""
    msgs, expect = malformed_messages(seed)
    os.makedirs(directory, exist_ok=True)
    write_messages(msgs, os.path.join(directory, "malformed.bag"))
    with open(os.path.join(directory, "expected.csv"), "w") as f:
        f.write("# rover_verifier_node on malformed.bag: the verdict expected for each candidate message\n"
                "# (made by scripts/make_shipped_data.py; matched to verdicts by query/match stamp)\n")
        f.write("name,query_stamp,match_stamp,expect,why\n")
        for e in expect:
            f.write(f"{e['name']},{e['query_stamp']:.9f},{e['match_stamp']:.9f},{e['expect']},{e['why']}\n")
    return msgs, expect


def read_expected(directory):
    rows = []
    with open(os.path.join(directory, "expected.csv")) as f:
        lines = [l.strip() for l in f if l.strip() and not l.startswith("#")]
    header = lines[0].split(",")
    for line in lines[1:]:
        vals = line.split(",", len(header) - 1)
        r = dict(zip(header, vals))
        r["query_stamp"], r["match_stamp"] = float(r["query_stamp"]), float(r["match_stamp"])
        rows.append(r)
    return rows
