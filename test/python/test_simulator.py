"""The scenario simulator: labels agree with the ground truth, files round-trip, the C++
reader (rover_replay) reads what Python writes, and real-data scenarios load."""
import csv
import os
import subprocess

import numpy as np
import pytest

from conftest import ROOT, built_tool, script, shared_data
from roverlib import geometry as g
from roverlib import datasets, real_data, scenario, scenes


@pytest.mark.parametrize("name", sorted(scenes.SCENES))
def test_labels_agree_with_ground_truth(name):
    with shared_data():  # kitti_route reads the KITTI ground truth
        s = scenes.make_scene(name, sigma=0.05, seed=1, n_true=30, n_false=30)
    assert s.meta["false_candidates"] == 30
    if name != "parking_deck":  # a spiral never revisits a place
        assert s.meta["true_candidates"] == 30
    queries = [c.query for c in s.candidates]
    assert len(set(queries)) == len(queries), "one candidate per query keyframe"
    radius = 1.5 if name in ("city", "kitti_route") else 0.5
    for c in s.candidates:
        assert c.match < c.query - 40
        d = np.linalg.norm(s.truth[c.query][:3, 3] - s.truth[c.match][:3, 3])
        if c.label == 1:
            assert d < radius
            # the reported relative pose is the true one, up to PnP-like noise
            true_rel = g.relative(s.truth[c.match], s.truth[c.query])
            assert np.linalg.norm(true_rel[:3, 3] - c.T_rel[:3, 3]) < 0.2
        else:
            assert d > 1.0, f"false candidate {c.query}->{c.match} only {d:.2f} m apart"
            assert np.linalg.norm(c.T_rel[:3, 3]) < 2.0, "false candidates look plausible"


def test_same_seed_same_scenario_and_drift_grows_with_sigma():
    a = scenes.make_scene("warehouse", 0.1, seed=3)
    b = scenes.make_scene("warehouse", 0.1, seed=3)
    assert all(np.array_equal(x.T, y.T) for x, y in zip(a.keyframes, b.keyframes))
    assert [(c.query, c.match) for c in a.candidates] == [(c.query, c.match) for c in b.candidates]
    end_error = []
    for sigma in (0.01, 0.1):
        s = scenes.make_scene("warehouse", sigma, seed=3)
        end_error.append(np.linalg.norm(s.keyframes[-1].T[:3, 3] - s.truth[-1][:3, 3]))
    assert end_error[1] > 3 * end_error[0]


def test_scenario_round_trip(tmp_path):
    s = scenes.make_scene("room", 0.05, seed=2, n_true=10, n_false=10)
    scenario.write(s, str(tmp_path))
    r = scenario.read(str(tmp_path))
    assert len(r.keyframes) == len(s.keyframes)
    assert np.allclose(r.keyframes[17].T, s.keyframes[17].T, atol=1e-8)
    assert [(c.query, c.match, c.label) for c in r.candidates] == \
        [(c.query, c.match, c.label) for c in sorted(s.candidates, key=lambda c: c.query)]
    assert np.allclose(r.truth[5], s.truth[5], atol=1e-8)


def test_replay_reads_what_python_writes(tmp_path):
    tool = built_tool("rover_replay")
    s = scenes.make_scene("corridor", 0.03, seed=4, n_true=20, n_false=20)
    scenario.write(s, str(tmp_path / "scn"))
    out = subprocess.run([tool, "--scenario", str(tmp_path / "scn"), "--out", str(tmp_path / "out"),
                          "--protocol", "oracle", "--quiet"], capture_output=True, text=True, check=True)
    assert "TP" in out.stdout
    rows = (tmp_path / "out" / "verdicts.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 40
    for f in ("odometry.tum", "verified.tum", "loop_fusion_verified.tum", "loop_fusion_accept_all.tum",
              "groundtruth.tum"):
        lines = (tmp_path / "out" / f).read_text().strip().splitlines()
        assert len(lines) == len(s.keyframes), f


def test_relative_yaw_is_loop_fusions_on_a_tilted_body(tmp_path):
    """candidates.csv's relative_yaw is loop_fusion's loop_info[7], the difference of world
    yaws, which the core compares with yaw_q - yaw_m (core/pose_graph.cpp), not the yaw of the
    relative rotation: on a tilted body an exact loop then has zero innovation, and chi2 accepts
    it (with the relative rotation's yaw it was 9 deg off, d^2 48 > 18.5: rejected)."""
    s, c = scenes.tilted_loop()
    R_m, R_q = s.truth[c.match][:3, :3], s.truth[c.query][:3, :3]
    world = g.wrap(g.yaw_of(R_q) - g.yaw_of(R_m))
    assert abs(np.degrees(world - g.yaw_of(c.T_rel[:3, :3]))) > 5.0, "the two conventions differ here"
    scenario.write(s, str(tmp_path / "scn"))
    rows = (tmp_path / "scn" / "candidates.csv").read_text().splitlines()
    assert float(rows[1].split(",")[9]) == pytest.approx(world, abs=1e-8)
    tool = built_tool("rover_replay")
    for decision in ("chi2", "metric"):
        subprocess.run([tool, "--scenario", str(tmp_path / "scn"), "--out", str(tmp_path / decision),
                        "--decision", decision, "--quiet"], capture_output=True, check=True)
        v = _csv(tmp_path / decision / "verdicts.csv")
        assert len(v) == 1 and v[0]["reason"] == "accepted", (decision, v)
        # the metric trial's score [m]; chi2's test quantity is d2 (no trial, score NaN)
        assert float(v[0]["d2" if decision == "chi2" else "score"]) < 1e-6, (decision, v)


def test_replay_prints_no_precision_when_nothing_was_accepted(tmp_path):
    # A gate of 1e-9 m rejects every candidate: precision of no accepted loop is "-", never 1.0.
    tool = built_tool("rover_replay")
    s = scenes.make_scene("corridor", 0.03, seed=4, n_true=10, n_false=10)
    scenario.write(s, str(tmp_path / "scn"))
    out = subprocess.run([tool, "--scenario", str(tmp_path / "scn"), "--out", str(tmp_path / "out"),
                          "--max_innovation", "1e-9", "--max_innovation_per_metre", "0", "--quiet"],
                         capture_output=True, text=True, check=True).stdout
    line = next(l for l in out.splitlines() if " TP " in l)
    assert "TP 0 FP 0" in line, line
    assert line.split("precision ")[1].split()[0] == "-", line
    assert line.split("recall ")[1].split()[0] == "0.000", line


def _csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_real_euroc_scenario():
    with shared_data():
        s = real_data.make_real("euroc_mh01", seed=0, n_true=20, n_false=20)
    assert 200 < len(s.keyframes) < 1000
    assert s.meta["true_candidates"] == 20 and s.meta["false_candidates"] == 20
    for c in s.candidates:
        d = np.linalg.norm(s.truth[c.query][:3, 3] - s.truth[c.match][:3, 3])
        assert (d < 0.5) if c.label == 1 else (d > 3.0)
    # The VIO estimate drifts from the truth but stays within metres on MH_01.
    stamps = [k.stamp for k in s.keyframes]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))


def test_kitti_is_converted_to_z_up():
    with shared_data():
        s = real_data.make_real("kitti_09", seed=0, n_true=5, n_false=5)
    z = np.array([T[2, 3] for T in s.truth])
    xy = np.array([T[:2, 3] for T in s.truth])
    assert np.ptp(z) < 0.2 * np.ptp(xy), "a car drives mostly in the horizontal plane"


def _claim_offset(s, c):
    """Where a candidate says the query is, minus where it is (world frame)."""
    return (s.truth[c.match] @ c.T_rel)[:3, 3] - s.truth[c.query][:3, 3]


@pytest.mark.parametrize("scene,param,axis", [("warehouse", "spacing", 0), ("parking_deck", "floor_height", 2),
                                              ("corridor", "door_spacing", None)])
def test_near_look_alikes_in_agreeing_rows_one_before_the_first_true_loop(scene, param, axis):
    extra = {"ascents": 2} if scene == "parking_deck" else {"laps": 6} if scene == "corridor" else {}
    s = scenes.make_scene(scene, 0.05, seed=11, rows=5, early_lookalike=True, random_fraction=0.0,
                          **{param: 1.5}, **extra)
    false = [c for c in s.candidates if c.label == 0]
    true = [c for c in s.candidates if c.label == 1]
    assert len(false) == 100 and len(true) > 50, "a parking deck with a second ascent has true loops"
    for c in false:
        w = _claim_offset(s, c)
        assert np.linalg.norm(w) == pytest.approx(1.5, abs=0.2), "the look-alike is 1.5 m off"
        if axis is not None:
            assert abs(w[axis]) == pytest.approx(1.5, abs=0.2)
    # rows: five consecutive queries, the same offset (they agree with each other)
    for k in range(0, len(false), 5):
        row = false[k:k + 5]
        assert [c.query for c in row] == list(range(row[0].query, row[0].query + 5))
        assert all(np.allclose(_claim_offset(s, c), _claim_offset(s, row[0]), atol=0.2) for c in row)
    assert max(c.query for c in false[:5]) < min(c.query for c in true), "a row before the first true loop"


def test_long_laps_and_old_matches():
    city = scenes.make_scene("city", 0.03, seed=2, rows=5, random_fraction=0.0)
    P = np.array([T[:3, 3] for T in city.truth])
    path = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))]
    first = min(c.query for c in city.candidates if c.label == 1)
    assert path[first] > 1000.0, "city: the first true loop comes after two 600 m laps"
    assert min(path[c.query] - path[c.match] for c in city.candidates if c.label == 1) >= 500.0, "city scale"
    corridor = scenes.make_scene("corridor", 0.05, seed=2, laps=12)
    spans = [c.query - c.match for c in corridor.candidates if c.label == 1]
    assert max(spans) > 10 * 120, "matches are the oldest revisit: up to 11 laps (120 keyframes each) old"


def test_without_options_the_scenes_are_what_they_were():
    """The shipped bags and earlier results were made with the default options: adding hard
    cases must not change them (these keyframes and candidates were recorded before)."""
    s = scenes.make_scene("room", 0.05, 0, 40, 40)
    assert len(s.keyframes) == 640
    assert [(c.query, c.match, c.label) for c in s.candidates][:4] == [(84, 3, 1), (111, 29, 1), (123, 1, 0), (133, 49, 1)]
    assert s.keyframes[5].T[0, 3] == pytest.approx(2.283498764913037, abs=1e-12)


def test_steady_drift_turns_and_stretches_every_metre_by_the_same_amount():
    """yaw_bias and scale_error: without noise, a straight line becomes an arc turning
    yaw_bias degrees per metre whose steps are 1 + scale_error times as long."""
    truth = [g.pose(np.eye(3), np.array([0.5 * i, 0.0, 0.0])) for i in range(201)]  # 100 m
    rng = np.random.default_rng(0)
    vio = scenes.add_drift(truth, 0.0, rng, yaw_bias=0.2, scale_error=0.02)
    assert np.degrees(g.yaw_of(vio[-1][:3, :3])) == pytest.approx(20.0, abs=1e-9)
    steps = [np.linalg.norm(b[:3, 3] - a[:3, 3]) for a, b in zip(vio[:-1], vio[1:])]
    assert steps == pytest.approx([0.51] * 200, abs=1e-12)
    plain = scenes.add_drift(truth, 0.0, rng)
    assert all(np.array_equal(a, b) for a, b in zip(plain, truth))
    s = scenes.make_scene("corridor", 0.05, seed=8, yaw_bias=0.2, scale_error=0.02)
    assert s.meta["yaw_bias_deg_per_m"] == 0.2 and s.meta["scale_error"] == 0.02
    assert "yaw_bias_deg_per_m" not in scenes.make_scene("corridor", 0.05, seed=8).meta


def test_real_near_look_alikes():
    with shared_data():
        s = real_data.make_real("euroc_mh03", 7, lookalike=dict(offset=1.5, first="lateral", rows=3))
    false = [c for c in s.candidates if c.label == 0]
    assert len(false) >= 15 and len(false) % 3 == 0 and s.meta["true_candidates"] > 10
    for c in false:
        assert np.linalg.norm(_claim_offset(s, c)) == pytest.approx(1.5, abs=0.15)  # + PnP-like noise
    assert max(c.query for c in false[:3]) < min(c.query for c in s.candidates if c.label == 1)


def test_simulate_exposes_the_false_candidate_distance(tmp_path):
    import sys
    sim = [sys.executable, os.path.join(ROOT, "scripts", "simulate.py")]
    with shared_data():  # what simulate.py --real euroc_mh01 reads
        for rel in real_data.SEQUENCES["euroc_mh01"][:2]:
            datasets.data_path(rel)
    subprocess.run(sim + ["--real", "euroc_mh01", "--false-distance", "1,2", "--out", str(tmp_path / "a")], check=True,
                   capture_output=True)
    s = scenario.read(str(tmp_path / "a"))
    gt = s.truth
    d = [np.linalg.norm(gt[c.query][:3, 3] - gt[c.match][:3, 3]) for c in s.candidates if c.label == 0]
    assert d and all(1.0 < x < 2.0 for x in d)
    subprocess.run(sim + ["--scene", "warehouse", "--lookalike-distance", "2", "--true", "10", "--false", "10",
                          "--out", str(tmp_path / "b")], check=True, capture_output=True)
    s = scenario.read(str(tmp_path / "b"))
    assert any(abs(np.linalg.norm(_claim_offset(s, c)) - 2.0) < 0.1 for c in s.candidates if c.label == 0)
    bad = subprocess.run(sim + ["--scene", "room", "--lookalike-distance", "2", "--out", str(tmp_path / "c")],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "mirror" in bad.stderr


def test_replay_says_when_a_query_is_older_than_its_match(tmp_path):
    """rover_replay verifies a candidate when its query keyframe arrives; a match
    that comes later in keyframes.csv was reported as "unknown match keyframe"."""
    tool = built_tool("rover_replay")
    s = scenes.make_scene("room", 0.05, seed=3, n_true=2, n_false=2)
    scenario.write(s, str(tmp_path / "scn"))
    q, m = s.keyframes[10].index, s.keyframes[11].index
    with open(tmp_path / "scn" / "candidates.csv", "a") as f:
        f.write(f"{q},{m},0.1,0,0,0,0,0,1,0,40,0\n")
    subprocess.run([tool, "--scenario", str(tmp_path / "scn"), "--out", str(tmp_path / "out"), "--quiet"],
                   capture_output=True, check=True)
    (row,) = [r for r in _csv(tmp_path / "out" / "verdicts.csv") if (int(r["query_index"]), int(r["match_index"])) == (q, m)]
    assert row["reason"] == "invalid_input"
    assert row["detail"] == (f"match keyframe {m} comes after query keyframe {q} in keyframes.csv: the match must be "
                             f"the older keyframe"), row["detail"]


def test_a_steady_drift_term_puts_the_first_revisit_back_inside_the_gate():
    """scripts/steady_drift_d2.py: under the random-walk model alone a steady yaw drift's true
    loops sit far outside the chi-square gate; with the steady term they are inside it, look-alikes
    stay out, and a random-walk scene is left as it was."""
    r = script("steady_drift_d2.py").main(["--split", "tuning", "corridor_yaw0.2_scale2pct", "room_s0.1"])
    steady, plain = r["corridor_yaw0.2_scale2pct"], r["room_s0.1"]
    assert steady["true_in_rw"] < 0.1 and steady["true_in_steady"] > 0.9
    assert steady["false_in_steady"] < 0.05
    assert plain["true_in_rw"] > 0.95 and plain["true_in_steady"] > 0.95 and plain["false_in_steady"] < 0.05
