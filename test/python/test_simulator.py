"""The scenario simulator: labels agree with the ground truth, files round-trip, the C++
reader (rover_replay) reads what Python writes, and real-data scenarios load."""
import subprocess

import numpy as np
import pytest

from conftest import built_tool
from roverlib import geometry as g
from roverlib import real_data, scenario, scenes


@pytest.mark.parametrize("name", sorted(scenes.SCENES))
def test_labels_agree_with_ground_truth(name):
    s = scenes.make_scene(name, sigma=0.05, seed=1, n_true=30, n_false=30)
    assert s.meta["false_candidates"] == 30
    if name != "parking_deck":  # a spiral never revisits a place
        assert s.meta["true_candidates"] == 30
    queries = [c.query for c in s.candidates]
    assert len(set(queries)) == len(queries), "one candidate per query keyframe"
    for c in s.candidates:
        assert c.match < c.query - 40
        d = np.linalg.norm(s.truth[c.query][:3, 3] - s.truth[c.match][:3, 3])
        if c.label == 1:
            assert d < 0.5
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


def test_real_euroc_scenario():
    try:
        s = real_data.make_real("euroc_mh01", seed=0, n_true=20, n_false=20)
    except FileNotFoundError as e:
        pytest.fail(f"../shared/data is part of the CI set-up: {e}")
    assert 200 < len(s.keyframes) < 1000
    assert s.meta["true_candidates"] == 20 and s.meta["false_candidates"] == 20
    for c in s.candidates:
        d = np.linalg.norm(s.truth[c.query][:3, 3] - s.truth[c.match][:3, 3])
        assert (d < 0.5) if c.label == 1 else (d > 3.0)
    # The VIO estimate drifts from the truth but stays within metres on MH_01.
    stamps = [k.stamp for k in s.keyframes]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))


def test_kitti_is_converted_to_z_up():
    s = real_data.make_real("kitti_09", seed=0, n_true=5, n_false=5)
    z = np.array([T[2, 3] for T in s.truth])
    xy = np.array([T[:2, 3] for T in s.truth])
    assert np.ptp(z) < 0.2 * np.ptp(xy), "a car drives mostly in the horizontal plane"
