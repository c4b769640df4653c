"""Scenario bags (scripts/roverlib/bag.py): what rover_verifier_node replays. The messages carry
exactly the scenario's numbers, candidates follow their query keyframe, the same seed gives the
same bytes, and the shipped bags under data/ and test/data/ are what their committed command
makes."""
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, script, shared_data
from roverlib import bag, datasets, geometry as g, real_data, scenario, scenes

make_shipped_data = script("make_shipped_data.py")


def pose_of(p):
    return g.pose_from_tq([p.position.x, p.position.y, p.position.z],
                          [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w])


def test_bag_holds_the_scenario_in_replay_order(tmp_path):
    s = scenes.make_scene("room", 0.05, seed=2, n_true=10, n_false=10)
    path = str(tmp_path / "room.bag")
    assert bag.write_bag(s, path) == (len(s.keyframes), 20)
    msgs = bag.read_bag(path)
    kfs = [(t, m) for t, topic, m in msgs if topic == bag.KEYFRAME_TOPIC]
    cands = [(t, m) for t, topic, m in msgs if topic == bag.CANDIDATE_TOPIC]
    assert len(kfs) == len(s.keyframes) and len(cands) == 20
    for (t, m), k in zip(kfs, s.keyframes):
        assert m._type == "nav_msgs/Odometry" and m.header.frame_id == "world"
        assert m.header.stamp == t == bag.ros_time(k.stamp)
        assert np.allclose(pose_of(m.pose.pose), k.T, atol=1e-12)
    stamp = {k.index: k.stamp for k in s.keyframes}
    last_keyframe = {}  # candidate message id -> stamp of the keyframe message before it
    newest = None
    for _, topic, m in msgs:
        if topic == bag.KEYFRAME_TOPIC:
            newest = m.header.stamp
        else:
            last_keyframe[id(m)] = newest
    for (t, m), c in zip(cands, sorted(s.candidates, key=lambda c: c.query)):
        assert m._type == "rover_loop_fusion/LoopCandidate"
        assert (m.query_index, m.match_index) == (-1, -1)  # named by stamp
        assert m.query_stamp == m.header.stamp == bag.ros_time(stamp[c.query])
        assert m.match_stamp == bag.ros_time(stamp[c.match])
        assert np.allclose(pose_of(m.relative_pose), c.T_rel, atol=1e-12)
        assert m.relative_yaw == pytest.approx(c.relative_yaw(s.keyframes[c.match].T))
        assert m.inliers == c.inliers
        # recorded right after its query keyframe, before the next one
        assert last_keyframe[id(m)] == m.query_stamp
        assert t > m.query_stamp


def test_candidate_message_yaw_is_loop_fusions_on_a_tilted_body():
    """The candidate message's relative_yaw is loop_fusion's (the difference of world yaws), as
    candidates.csv's; on this tilted body the relative rotation's yaw is 9 deg away from it."""
    s, c = scenes.tilted_loop()
    (m,) = [m for _, topic, m in bag.scenario_messages(s) if topic == bag.CANDIDATE_TOPIC]
    world = g.wrap(g.yaw_of(s.truth[c.query][:3, :3]) - g.yaw_of(s.truth[c.match][:3, :3]))
    assert m.relative_yaw == pytest.approx(world, abs=1e-12)
    assert abs(m.relative_yaw - g.yaw_of(c.T_rel[:3, :3])) > np.radians(5.0)


def test_same_seed_same_bytes(tmp_path):
    for name in ("a", "b"):
        bag.write_bag(scenes.make_scene("corridor", 0.05, seed=5, n_true=5, n_false=5), str(tmp_path / f"{name}.bag"))
    assert (tmp_path / "a.bag").read_bytes() == (tmp_path / "b.bag").read_bytes()


def test_stamps_round_to_the_nanosecond():
    t = bag.ros_time(1403636579.763555527)
    assert (t.secs, abs(t.nsecs - 763555527) <= 120) == (1403636579, True)
    assert bag.ros_time(1000.9999999999).to_nsec() == 1001 * 10**9
    assert bag.stamp_key(t) == bag.stamp_key(1403636579.763555527)


def test_one_session_per_bag():
    s = scenes.make_scene("room", 0.05, seed=2, n_true=2, n_false=2)
    s.keyframes[-1].sequence = 2
    with pytest.raises(ValueError, match="one session"):
        bag.scenario_messages(s)


def test_simulate_bag_option_and_own_trajectory(tmp_path):
    """simulate.py --bag writes the bag from the files it wrote; --estimate/--groundtruth takes
    any TUM pair (here EuRoC's, which --real euroc_mh01 reads too: the same scenario)."""
    est, gt = real_data.SEQUENCES["euroc_mh01"][:2]
    with shared_data():
        est, gt = datasets.data_path(est), datasets.data_path(gt)
    simulate = os.path.join(ROOT, "scripts", "simulate.py")
    common = ["--true", "5", "--false", "5", "--bag"]
    subprocess.run([sys.executable, simulate, "--estimate", est, "--groundtruth", gt, "--out", str(tmp_path / "own")] + common,
                   check=True, capture_output=True)
    subprocess.run([sys.executable, simulate, "--real", "euroc_mh01", "--out", str(tmp_path / "ref")] + common,
                   check=True, capture_output=True)
    own, ref = scenario.read(str(tmp_path / "own")), scenario.read(str(tmp_path / "ref"))
    assert [k.stamp for k in own.keyframes] == [k.stamp for k in ref.keyframes]
    assert [(c.query, c.match, c.label) for c in own.candidates] == [(c.query, c.match, c.label) for c in ref.candidates]
    msgs = bag.read_bag(str(tmp_path / "own" / "scenario.bag"))
    assert sum(topic == bag.CANDIDATE_TOPIC for _, topic, _ in msgs) == 10
    # scenario_to_bag.py on the directory writes the same bag
    subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "scenario_to_bag.py"), str(tmp_path / "own"),
                    "--out", str(tmp_path / "again.bag")], check=True, capture_output=True)
    assert (tmp_path / "again.bag").read_bytes() == (tmp_path / "own" / "scenario.bag").read_bytes()


def fields(p):
    """A geometry_msgs/Pose as numbers (malformed ones too: NaN, zero quaternions)."""
    return [p.position.x, p.position.y, p.position.z, p.orientation.x, p.orientation.y, p.orientation.z,
            p.orientation.w]


def _same_messages(a, b):
    assert len(a) == len(b)
    for (ta, topic_a, ma), (tb, topic_b, mb) in zip(a, b):
        assert (ta, topic_a, ma._type) == (tb, topic_b, mb._type)
        if ma._type == "nav_msgs/Odometry":
            assert ma.header.stamp == mb.header.stamp
            np.testing.assert_allclose(fields(ma.pose.pose), fields(mb.pose.pose), atol=1e-9)
        else:
            assert (ma.query_stamp, ma.match_stamp, ma.query_index, ma.match_index, ma.inliers) == \
                (mb.query_stamp, mb.match_stamp, mb.query_index, mb.match_index, mb.inliers)
            np.testing.assert_allclose(fields(ma.relative_pose), fields(mb.relative_pose), atol=1e-9)
            np.testing.assert_allclose(ma.relative_yaw, mb.relative_yaw, atol=1e-9)


def test_shipped_bags_are_what_the_committed_command_makes(tmp_path):
    with shared_data():
        make_shipped_data.main(["--out", str(tmp_path)])
    for d in make_shipped_data.SHIPPED:
        shipped, made = os.path.join(ROOT, d), str(tmp_path / d)
        assert sorted(os.listdir(shipped)) == sorted(os.listdir(made)), d
        _same_messages(bag.read_bag(os.path.join(shipped, "scenario.bag")), bag.read_bag(os.path.join(made, "scenario.bag")))
        a, b = scenario.read(shipped), scenario.read(made)
        assert [(c.query, c.match, c.label) for c in a.candidates] == [(c.query, c.match, c.label) for c in b.candidates]
    m = make_shipped_data.MALFORMED
    _same_messages(bag.read_bag(os.path.join(ROOT, m, "malformed.bag")), bag.read_bag(str(tmp_path / m / "malformed.bag")))
    assert bag.read_expected(os.path.join(ROOT, m)) == bag.read_expected(str(tmp_path / m))


def test_shipped_data_is_small():
    total = 0
    for d in list(make_shipped_data.SHIPPED) + [make_shipped_data.MALFORMED]:
        for f in os.listdir(os.path.join(ROOT, d)):
            total += os.path.getsize(os.path.join(ROOT, d, f))
    assert total < 2 * 1024 * 1024


def test_malformed_bag_expectations():
    msgs, expect = bag.malformed_messages()
    assert sum(topic == bag.CANDIDATE_TOPIC for _, topic, _ in msgs) == len(expect)
    keys = [(bag.stamp_key(e["query_stamp"]), bag.stamp_key(e["match_stamp"])) for e in expect]
    assert len(set(keys)) == len(keys), "each expectation matches one verdict"
    kinds = {e["name"] for e in expect}
    for k in ("before_its_keyframe", "keyframe_never_comes", "unknown_query_stamp", "nan_relative_pose",
              "names_a_refused_keyframe", "keyframes_by_index"):
        assert k in kinds
    stamps = [m.header.stamp for _, topic, m in msgs if topic == bag.KEYFRAME_TOPIC]
    assert len(stamps) != len(set(stamps)), "a duplicate keyframe"
    assert any(b < a for a, b in zip(stamps, stamps[1:])), "an out-of-order keyframe"
