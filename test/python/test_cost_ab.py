"""scripts/bench/cost_ab.py: the cost benchmark of two builds side by side. Its verdict
comparison must see a changed decision and nothing but timing; a kept build must run beside the
workspace's and decide as it does. No timing assertions."""
import csv
import os

from conftest import built_tool, script

cost_ab = script("bench/cost_ab.py")


def _row(**kw):
    r = {"dof": "4", "keyframes": "1000", "span": "10", "query_index": "990", "match_index": "980", "accepted": "1",
         "reason": "accepted", "score": "0.012", "solve_ms": "0.10", "verify_ms": "0.20"}
    r.update(kw)
    return r


def test_a_changed_decision_is_seen_and_timing_is_not():
    ref = [_row(), _row(query_index="991", match_index="500", accepted="0", reason="score_above_threshold")]
    assert cost_ab.decision_differences(ref, [_row(verify_ms="9.9", solve_ms="7"), dict(ref[1])]) == []
    assert cost_ab.decision_differences(ref, [_row(accepted="0"), dict(ref[1])]) == [0]
    assert cost_ab.decision_differences(ref, [dict(ref[0]), dict(ref[1], score="0.013")]) == [1]
    assert cost_ab.decision_differences(ref, [dict(ref[0])]) == [1]  # a row missing


def test_summary_sums_verify_ms_per_row_and_takes_the_ratio():
    old = [_row(verify_ms="1.0"), _row(verify_ms="3.0"), _row(span="100", verify_ms="2.0")]
    new = [_row(verify_ms="1.0"), _row(verify_ms="1.0"), _row(span="100", verify_ms="4.0")]
    table = cost_ab.summarise([("old", 1, old), ("new", 1, new)])
    assert [(r["span"], r["old1_sum_ms"], r["new1_sum_ms"]) for r in table] == [("10", 4.0, 2.0), ("100", 2.0, 4.0)]
    assert [r["ratio_new_over_old"] for r in table] == [0.5, 2.0]
    assert table[0]["old1_p99_ms"] == 3.0 and table[0]["old1_p50_ms"] == 1.0  # nearest rank


def test_a_kept_build_runs_beside_the_workspace_and_decides_alike(tmp_path):
    built_tool("rover_benchmark_cost")
    kept = str(tmp_path / "kept")
    assert cost_ab.main(["save", kept]) == 0
    assert os.path.exists(os.path.join(kept, "rover_benchmark_cost")) and os.listdir(os.path.join(kept, "lib"))
    out = str(tmp_path / "ab")
    rc = cost_ab.main(["run", "--old", kept, "--rounds", "1", "--out", out, "--", "--modes", "4dof", "--sizes", "1000",
                       "--spans", "10,100", "--queries", "3", "--full-repeats", "1"])
    assert rc == 0  # the same code on both sides: every decision identical
    with open(os.path.join(out, "rows.csv")) as f:
        rows = list(csv.DictReader(f))
    assert [(r["keyframes"], r["span"]) for r in rows] == [("1000", "10"), ("1000", "100")]
    assert all(float(r["old1_sum_ms"]) > 0 and float(r["new1_sum_ms"]) > 0 for r in rows)
    with open(os.path.join(out, "summary.md")) as f:
        assert "every verdict row identical" in f.read()
