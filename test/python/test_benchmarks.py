"""The --quick mode of every benchmark family (what CI runs): each writes its table, CSV,
summary and PNGs, with sane values. No timing assertions."""
import csv
import os

import pytest

from conftest import built_tool, script
from roverlib import bench

bench_cost, bench_poc, bench_posegraph, bench_real = (script(f"bench/{f}.py") for f in ("cost", "poc", "posegraph", "real"))


@pytest.fixture(autouse=True)
def _built():
    for tool in ("rover_replay", "rover_benchmark_cost"):
        built_tool(tool)


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def _pngs(directory, names):
    for n in names:
        assert os.path.getsize(os.path.join(directory, n)) > 5000, n


def test_poc_quick(tmp_path, capsys):
    assert bench_poc.main(["--quick", "--out", str(tmp_path)]) == 0
    rows = _rows(tmp_path / "poc.csv")
    assert [(r["scene"], r["sigma"]) for r in rows] == [("room", "0.05"), ("room", "0.15")]
    for r in rows:
        assert int(r["true"]) == 40 and int(r["false"]) == 40
        for k in ("ap_oracle", "mr_oracle", "ap_none", "mr_none", "seq_precision", "seq_recall"):
            assert 0.0 <= float(r[k]) <= 1.0 + 1e-9, k
    # the room at low noise is the easy case of the paper's PoC (README "Results")
    assert float(rows[0]["ap_oracle"]) > 0.99 and float(rows[0]["seq_precision"]) == 1.0
    assert "AP oracle" in capsys.readouterr().out
    _pngs(tmp_path, ["pr_oracle.png", "pr_none.png"])
    assert (tmp_path / "summary.md").read_text().count("| room |") == 2


def test_real_quick(tmp_path):
    try:
        assert bench_real.main(["--quick", "--snapshots", "4", "--out", str(tmp_path)]) == 0
    except FileNotFoundError as e:
        pytest.fail(f"../shared/data is part of the CI set-up: {e}")
    (r,) = _rows(tmp_path / "real.csv")
    # EuRoC is decided at the shipped indoor configuration
    assert r["case"] == "euroc_mh01" and float(r["threshold"]) == bench.defaults("indoor")["threshold"]
    assert int(r["gated"]) + int(r["not_scored"]) <= int(r["true"]) + int(r["false"])
    for k in ("ate_odometry", "ate_accept_all", "ate_verified", "ate_true_only", "tate_odometry", "tate_accept_all",
              "tate_verified", "tate_true_only"):
        assert 0.0 < float(r[k]) < 100.0, k
    assert len(os.listdir(tmp_path / "runs" / "euroc_mh01_sequential" / "snapshots")) == 3 * 4
    _pngs(tmp_path, ["pr_real.png", "ate_real.png"])


def test_posegraph_quick(tmp_path):
    try:
        assert bench_posegraph.main(["--quick", "--jobs", "2", "--out", str(tmp_path)]) == 0
    except FileNotFoundError as e:
        pytest.fail(f"../shared/data is part of the CI set-up: {e}")
    rows = _rows(tmp_path / "posegraph.csv")
    assert sorted(r["kind"] for r in rows) == sorted(["random", "local", "grouped", "repetitive"])
    for r in rows:
        assert r["graph"] == "ring" and int(r["true"]) == 26 and int(r["false"]) == 6
        for k in ("rover_p", "rover_r", "gnc_p", "gnc_r", "dcs_p", "dcs_r"):
            assert 0.0 <= float(r[k]) <= 1.0 + 1e-9, k
        for k in ("ate_odometry", "ate_accept_all", "ate_rover_lf", "ate_rover_lm", "ate_gnc", "ate_dcs",
                  "ate_true_lm"):
            assert 0.0 <= float(r[k]) < 1000.0, k
        assert float(r["ate_true_lm"]) < float(r["ate_odometry"])
    _pngs(tmp_path, ["ring.png"])


def test_cost_quick(tmp_path):
    assert bench_cost.main(["--quick", "--out", str(tmp_path)]) == 0
    rows = _rows(tmp_path / "cost.csv")
    assert [(int(r["keyframes"]), int(r["span"])) for r in rows] == [(1000, 100), (2000, 100)]
    for r in rows:
        assert float(r["verify_median_ms"]) > 0 and float(r["loop_fusion_full_ms"]) > 0
        assert float(r["peak_rss_mb"]) > 1 and int(r["window"]) == 101
    assert rows[0]["target"].startswith("<= 1 ms")
    _pngs(tmp_path, ["cost.png"])
