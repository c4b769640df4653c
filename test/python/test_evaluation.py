"""The evaluator (roverlib/metrics.py, scripts/evaluate.py) on hand-made inputs whose AP, MR,
precision/recall and ATE are known, and rover_replay's snapshots for the temporal ATE."""
import json
import math
import subprocess

import numpy as np
import pytest

from conftest import built_tool, script
from roverlib import alignment, bench, metrics, scenario, scenes

evaluate = script("evaluate.py")

HEADER = ("query_stamp,match_stamp,query_index,match_index,accepted,reason,score,threshold,converged,"
          "iterations,window_size,solve_ms,elapsed_ms,inliers,innovation,path_length,verifier,detail")


def verdict_line(q, m, accepted, reason, score):
    return f"0,0,{q},{m},{int(accepted)},{reason},{score},0.15,1,3,10,1,1,-1,0.1,5,test,\"\""


def write_inputs(tmp_path, rows, labels):
    """rows: (query, match, accepted, reason, score); labels: (query, match, label)."""
    v = tmp_path / "verdicts.csv"
    v.write_text(HEADER + "\n" + "\n".join(verdict_line(*r) for r in rows) + "\n")
    c = tmp_path / "candidates.csv"
    c.write_text("# labels\n" + scenario.CANDIDATES_HEADER + "\n" +
                 "\n".join(f"{q},{m},0,0,0,0,0,0,1,0,-1,{lab}" for q, m, lab in labels) + "\n")
    return str(v), str(c)


def test_average_precision_and_max_recall_by_hand():
    # ranked by score (low = true): T T F T F
    label = [1, 1, 0, 1, 0]
    score = [0.1, 0.2, 0.3, 0.4, 0.5]
    r = metrics.ranking_metrics(label, score)
    # AP = mean over the positives of the precision at their rank: (1 + 1 + 3/4) / 3
    assert r["ap"] == pytest.approx((1 + 1 + 0.75) / 3, abs=1e-12)
    assert r["mr"] == pytest.approx(2 / 3, abs=1e-12)
    # order of the input does not matter, only the scores
    perm = [4, 2, 0, 3, 1]
    r2 = metrics.ranking_metrics([label[i] for i in perm], [score[i] for i in perm])
    assert r2["ap"] == pytest.approx(r["ap"]) and r2["mr"] == pytest.approx(r["mr"])


def test_perfect_and_worst_rankings():
    r = metrics.ranking_metrics([1, 1, 0, 0], [0.01, 0.02, 0.5, 0.6])
    assert r["ap"] == 1.0 and r["mr"] == 1.0
    r = metrics.ranking_metrics([0, 1, 1], [0.01, 0.5, 0.6])  # top-ranked candidate is false
    assert r["mr"] == 0.0
    assert r["ap"] == pytest.approx((1 / 2 + 2 / 3) / 2)
    r = metrics.ranking_metrics([1, 1], [0.1, 0.2])  # no negatives: undefined
    assert math.isnan(r["ap"]) and math.isnan(r["mr"])


def test_unscored_verdicts_rank_last_and_labels_join(tmp_path):
    rows = [(10, 1, True, "accepted", 0.05),
            (11, 2, False, "time_budget_exceeded", 0.01),  # true loop, no usable score
            (12, 3, False, "score_above_threshold", 0.9),
            (13, 4, False, "invalid_input", "nan"),
            (14, 5, True, "accepted", 0.1),
            (15, 6, False, "score_above_threshold", 0.3)]  # label unknown (-1): left out
    labels = [(10, 1, 1), (11, 2, 1), (12, 3, 0), (13, 4, 0), (14, 5, 0), (15, 6, -1)]
    v, c = write_inputs(tmp_path, rows, labels)
    j = metrics.join(metrics.read_verdicts(v), metrics.read_labels(c))
    assert list(j["label"]) == [1, 1, 0, 0, 0]
    assert list(j["score"][:1]) == [0.05] and np.isinf(j["score"][1]) and np.isinf(j["score"][3])
    # ranking: 10 (T, 0.05), 14 (F, 0.1), 12 (F, 0.9), then 11 (T) tied last with 13 (F)
    r = metrics.ranking_metrics(j["label"], j["score"])
    assert r["mr"] == pytest.approx(0.5)
    assert r["ap"] == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 5)  # sklearn: a tie is one threshold
    d = metrics.decision_metrics(j["label"], j["accepted"])
    assert (d["tp"], d["fp"], d["tn"], d["fn"]) == (1, 1, 2, 1)
    assert d["precision"] == 0.5 and d["recall"] == 0.5


def test_precision_of_no_decision_is_undefined_not_one():
    d = metrics.decision_metrics([1, 0, 1], [False, False, False])
    assert math.isnan(d["precision"]) and d["recall"] == 0.0 and d["fn"] == 2
    d = metrics.decision_metrics([0, 0], [True, False])  # no true loop: recall undefined
    assert d["precision"] == 0.0 and math.isnan(d["recall"]) and d["fp"] == 1
    # a table shows both as "-"
    assert bench.fmt(d["recall"], ".2f") == "-" and bench.fmt(0.5, ".2f") == "0.50"


def _square(n=80, side=10.0):
    """n points around a square in the plane z = 0."""
    corners = np.array([[0, 0], [side, 0], [side, side], [0, side], [0, 0]], dtype=float)
    xy = []
    for t in np.linspace(0, 4, n, endpoint=False):
        i = int(t)
        xy.append(corners[i] + (t - i) * (corners[i + 1] - corners[i]))
    return np.column_stack([np.array(xy), np.zeros(n)])


def test_ate_known_values():
    p = _square()
    stamps = np.arange(len(p), dtype=float)
    gt = metrics.trajectory(stamps, p)
    # a rigid motion of the whole trajectory: nothing after SE(3) alignment
    yaw = 0.4
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    moved = metrics.trajectory(stamps, p @ R.T + [3.0, -2.0, 1.0])
    assert metrics.ate(gt, moved, "se3") < 1e-9
    assert metrics.ate(gt, moved, "none") > 1.0
    # a constant offset without alignment: ATE = the offset
    assert metrics.ate(gt, metrics.trajectory(stamps, p + [0, 0, 0.25]), "none") == pytest.approx(0.25)
    # +-d in z, alternating (uncorrelated with x, y): alignment cannot remove it, ATE = d
    d = 0.1
    zz = p.copy()
    zz[:, 2] = d * (-1.0) ** np.arange(len(p))
    assert metrics.ate(gt, metrics.trajectory(stamps, zz), "se3") == pytest.approx(d, rel=1e-3)
    # scale is only removed by Sim(3)
    scaled = metrics.trajectory(stamps, 1.5 * p)
    assert metrics.ate(gt, scaled, "sim3") < 1e-9 and metrics.ate(gt, scaled, "se3") > 0.5


def test_umeyama_recovers_a_known_similarity_and_refuses_a_line():
    """roverlib.alignment, the one Python alignment (metrics.ate and the demo's summary use it)."""
    rng = np.random.default_rng(3)
    P = rng.normal(size=(3, 30)) * [[4.0], [3.0], [1.0]]
    yaw = 0.7
    R = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    t = np.array([1.0, -2.0, 0.5])
    Q = 1.3 * R @ P + t[:, None]
    R_, t_, s_ = alignment.umeyama(P, Q, with_scale=True)
    np.testing.assert_allclose(R_, R, atol=1e-9)
    np.testing.assert_allclose(t_, t, atol=1e-9)
    assert s_ == pytest.approx(1.3)
    assert alignment.ate(Q, P, "sim3") < 1e-9 and alignment.ate(Q, P, "se3") > 0.1
    # a mirrored copy is not a rotation: SE(3) cannot remove it
    assert alignment.ate(P * [[1.0], [1.0], [-1.0]], P, "se3") > 0.1
    line = np.outer([1.0, 0.0, 0.0], np.arange(10.0))  # on the x axis: the rotation about it is free
    with pytest.raises(alignment.AlignmentError):
        alignment.umeyama(line, line + 1.0)
    with pytest.raises(alignment.AlignmentError):
        alignment.ate(P, P[:, :5], "se3")
    with pytest.raises(ValueError):
        alignment.ate(P, P, "affine")


def test_temporal_ate_is_the_mean_over_snapshots():
    p = _square()
    stamps = np.arange(len(p), dtype=float)
    gt = metrics.trajectory(stamps, p)
    first = metrics.trajectory(stamps[:40], p[:40] + [0, 0, 0.2])
    full = metrics.trajectory(stamps, p + [0, 0, 0.6])
    assert metrics.temporal_ate(gt, [first, full], "none") == pytest.approx(0.4)
    parts = metrics.prefixes(gt, 3)
    assert [t.num_poses for t in parts] == [27, 54, 80]


def test_temporal_ate_leaves_out_snapshots_that_cannot_be_aligned():
    p = _square()
    stamps = np.arange(len(p), dtype=float)
    gt = metrics.trajectory(stamps, p)
    line = metrics.trajectory(stamps[:5], p[:5])  # the first side so far: keyframes on one line
    with pytest.raises(alignment.AlignmentError):
        metrics.ate(gt, line, "se3")
    d = 0.1
    zz = p.copy()
    zz[:, 2] = d * (-1.0) ** np.arange(len(p))
    assert metrics.temporal_ate(gt, [line, metrics.trajectory(stamps, zz)], "se3") == pytest.approx(d, rel=1e-3)
    assert math.isnan(metrics.temporal_ate(gt, [line], "se3"))


def test_evaluate_cli_writes_metrics_and_pr_curve(tmp_path):
    rows = [(10, 1, True, "accepted", 0.05), (11, 2, False, "score_above_threshold", 0.4),
            (12, 3, False, "score_above_threshold", 0.2), (13, 4, True, "accepted", 0.1)]
    v, c = write_inputs(tmp_path, rows, [(10, 1, 1), (11, 2, 1), (12, 3, 0), (13, 4, 0)])
    p = _square(20)
    gt_path, est_path = tmp_path / "gt.tum", tmp_path / "est.tum"
    gt_path.write_text("".join(f"{i} {x} {y} {z} 0 0 0 1\n" for i, (x, y, z) in enumerate(p)))
    est_path.write_text("".join(f"{i} {x} {y} {z + 0.3} 0 0 0 1\n" for i, (x, y, z) in enumerate(p)))
    out = tmp_path / "eval"
    assert evaluate.main(["--verdicts", v, "--labels", c, "--out", str(out), "--groundtruth", str(gt_path),
                          "--trajectory", f"est={est_path}", "--align", "none"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    # ranked: T(0.05) F(0.1) F(0.2) T(0.4): AP = (1 + 2/4) / 2, MR = 1/2
    assert m["ap"] == pytest.approx(0.75) and m["mr"] == pytest.approx(0.5)
    assert (m["tp"], m["fp"], m["tn"], m["fn"]) == (1, 1, 1, 1)
    assert m["trajectories"]["est"]["ate"] == pytest.approx(0.3)
    assert (out / "pr_curve.png").stat().st_size > 1000


def test_replay_snapshots_and_evaluate_run(tmp_path):
    tool = built_tool("rover_replay")
    s = scenes.make_scene("room", 0.05, seed=5, n_true=10, n_false=10)
    scenario.write(s, str(tmp_path / "scn"))
    out = tmp_path / "run"
    subprocess.run([tool, "--scenario", str(tmp_path / "scn"), "--out", str(out), "--snapshots", "3", "--quiet"],
                   check=True, capture_output=True)
    n = len(s.keyframes)
    for name in ("verified", "loop_fusion_verified", "loop_fusion_accept_all"):
        counts = [len((out / "snapshots" / f"{name}_{k}.tum").read_text().splitlines()) for k in (1, 2, 3)]
        assert counts == [-(-k * n // 3) for k in (1, 2, 3)], name
    assert (out / "snapshots" / "verified_3.tum").read_text() == (out / "verified.tum").read_text()
    res = evaluate.evaluate(str(out / "verdicts.csv"), str(tmp_path / "scn" / "candidates.csv"), run=str(out),
                            quiet=True)
    t = res["trajectories"]
    assert set(t) == {"odometry", "loop_fusion_accept_all", "loop_fusion_verified", "verified"}
    assert all(np.isfinite(v["tate"]) for v in t.values())
    assert res["true"] == 10 and res["false"] == 10
