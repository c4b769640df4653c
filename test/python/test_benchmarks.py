"""The --quick mode of every benchmark family (what CI runs): each writes its tables,
summary.csv with the stable columns, and PNGs, with sane values. No timing assertions."""
import csv
import math
import os

import pytest

from conftest import built_tool, script, shared_data
from roverlib import bench, splits

bench_cost, bench_poc, bench_posegraph, bench_real = (script(f"bench/{f}.py") for f in ("cost", "poc", "posegraph", "real"))

# what other tools read: never rename
COLUMNS = ["family", "split", "case", "method", "tp", "fp", "fn", "precision", "recall", "ate", "ate_true_only", "tate",
           "verify_ms_p50", "verify_ms_p99"]


@pytest.fixture(autouse=True)
def _built():
    for tool in ("rover_replay", "rover_benchmark_cost"):
        built_tool(tool)


def _rows(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def _summary(path, family):
    with open(path) as f:
        assert next(csv.reader(f)) == COLUMNS
    rows = _rows(path)
    assert rows and all(r["family"] == family for r in rows)
    for r in rows:
        if r["tp"]:
            tp, fp, fn = int(r["tp"]), int(r["fp"]), int(r["fn"])
            # precision "-" (empty) exactly when nothing was accepted; else the counts' ratio
            assert (r["precision"] == "") == (tp + fp == 0), r
            if tp + fp:
                assert float(r["precision"]) == pytest.approx(tp / (tp + fp), abs=1e-5)
            if tp + fn:
                assert float(r["recall"]) == pytest.approx(tp / (tp + fn), abs=1e-5)
    return rows


def _pngs(directory, names):
    for n in names:
        assert os.path.getsize(os.path.join(directory, n)) > 5000, n


def _by(rows, case, method):
    (r,) = [r for r in rows if r["case"] == case and r["method"] == method]
    return r


def test_summary_columns_are_stable():
    assert list(bench.SUMMARY_COLUMNS) == COLUMNS


def test_poc_quick(tmp_path, capsys):
    assert bench_poc.main(["--quick", "--snapshots", "3", "--out", str(tmp_path)]) == 0
    rows = _summary(tmp_path / "summary.csv", "poc")
    cases = [c.name for c in splits.cases("poc", "test", quick=True)]
    assert sorted({r["case"] for r in rows}) == sorted(cases) and {r["split"] for r in rows} == {"test"}
    want = {"odometry", "gnc", "dcs"} | {f"{m}+{b}" for m in ("rover", "accept_all", "pcm", "ipc") for b in ("lf", "lm")}
    assert {r["method"] for r in rows} == want, "the peers on the simulated scenes too"
    for case in cases:
        odo = _by(rows, case, "odometry")
        assert odo["precision"] == "" and int(odo["fn"]) == 40, "no decision: precision '-'"
        for m in ("rover+lf", "rover+lm", "accept_all+lf", "accept_all+lm"):
            r = _by(rows, case, m)
            assert 0.0 < float(r["ate"]) < 100.0 and 0.0 < float(r["ate_true_only"]) <= float(r["ate"]) * 1.5
            assert 0.0 < float(r["tate"]) < 100.0
        # both accept-all rows accept everything; the true-only ATE is per back end
        assert int(_by(rows, case, "accept_all+lf")["fp"]) == 40
        assert _by(rows, case, "rover+lf")["ate_true_only"] == _by(rows, case, "accept_all+lf")["ate_true_only"]
    # the room at low noise is the easy case of the paper's PoC
    room = _by(rows, "room_s0.05", "rover+lf")
    assert float(room["precision"]) == 1.0 and float(room["recall"]) > 0.9
    assert float(room["verify_ms_p50"]) > 0.0
    out = capsys.readouterr().out
    assert "Decisions" in out and "LM true-only" in out
    _pngs(tmp_path, ["pr_oracle.png", "pr_none.png", "poc.png"])
    assert (tmp_path / "summary.md").read_text().count("| room_s0.05 |") == 3


def test_real_quick(tmp_path):
    with shared_data():
        assert bench_real.main(["--quick", "--snapshots", "3", "--out", str(tmp_path)]) == 0
    rows = _summary(tmp_path / "summary.csv", "real")
    (case,) = {r["case"] for r in rows}
    assert case == "euroc_mh05_far"
    want = {"odometry", "gnc", "dcs"} | {f"{m}+{b}" for m in ("rover", "accept_all", "pcm", "ipc") for b in ("lf", "lm")}
    assert {r["method"] for r in rows} == want, "every peer on the same candidates"
    for r in rows:
        if r["method"] != "odometry":
            assert int(r["tp"]) + int(r["fn"]) == 40 and int(r["fp"]) <= 40
        assert 0.0 < float(r["ate"]) < 100.0
    for backend in ("lf", "lm"):
        refs = {r["ate_true_only"] for r in rows if r["method"].endswith("+" + backend)}
        assert len(refs) == 1, "one true-only reference per back end"
    assert math.isnan(float(_by(rows, case, "gnc")["tate"] or "nan")), "a batch method has no tATE"
    assert float(_by(rows, case, "pcm+lf")["verify_ms_p50"]) > 0.0
    wide = _rows(tmp_path / "cases.csv")
    assert wide[0]["limits"] == "-"
    _pngs(tmp_path, ["pr_real.png", "real.png"])


def test_posegraph_quick(tmp_path):
    with shared_data():
        assert bench_posegraph.main(["--quick", "--snapshots", "3", "--jobs", "1", "--out", str(tmp_path)]) == 0
    rows = _summary(tmp_path / "summary.csv", "posegraph")
    (case,) = {r["case"] for r in rows}
    assert case == "ringCity_near_20"
    for r in rows:
        if r["method"] != "odometry":
            assert (int(r["tp"]) + int(r["fn"]), int(r["fp"]) <= 10) == (40, True)
    odo = float(_by(rows, case, "odometry")["ate"])
    assert float(_by(rows, case, "rover+lm")["ate_true_only"]) < odo
    _pngs(tmp_path, ["ringCity.png"])


def test_cost_quick(tmp_path):
    assert bench_cost.main(["--quick", "--out", str(tmp_path)]) == 0
    rows = _rows(tmp_path / "cost.csv")
    assert [(int(r["keyframes"]), int(r["span"])) for r in rows] == [(1000, 100), (2000, 100)]
    for r in rows:
        assert float(r["verify_median_ms"]) > 0 and float(r["loop_fusion_full_ms"]) > 0
        assert float(r["peak_rss_mb"]) > 1 and int(r["window"]) == 101
    assert rows[0]["target"].startswith("<= 1 ms")
    summary = _summary(tmp_path / "summary.csv", "cost")
    assert [(r["case"], r["method"]) for r in summary][:2] == [("4dof_1000kf_span100", "rover"),
                                                               ("4dof_1000kf_span100", "loop_fusion_full")]
    _pngs(tmp_path, ["cost.png"])


def test_decision_flag_reaches_rover_replay(tmp_path):
    """--decision chi2 runs ROVER's sequential replay in units of drift: its verdicts compare the
    innovation's Mahalanobis distance with the chi-square gate (4 dof, gate_probability 0.999 of
    the YAML), not the YAML's 0.2 m threshold."""
    from scipy.stats import chi2
    assert bench_poc.main(["--quick", "--cases", "room_s0.05", "--decision", "chi2", "--snapshots", "2", "--jobs", "1",
                           "--out", str(tmp_path)]) == 0
    verdicts = _rows(tmp_path / "runs" / "room_s0.05" / "rover" / "verdicts.csv")
    assert len(verdicts) == 80
    # chi2's own fields (d2, gate); no trial, so no score or threshold in metres
    assert all(float(v["gate"]) == pytest.approx(chi2.ppf(0.999, 4), abs=1e-4) for v in verdicts)
    assert all(math.isfinite(float(v["d2"])) and math.isnan(float(v["score"])) and math.isnan(float(v["threshold"]))
               for v in verdicts)
    assert {v["reason"] for v in verdicts} <= {"accepted", "inconsistent_with_drift", "lookalike_closer"}
    assert "ROVER decision: chi2" in (tmp_path / "summary.md").read_text()
    _summary(tmp_path / "summary.csv", "poc")


def test_set_parameters_become_rover_replay_flags():
    """--set KEY=VALUE (repeatable) reaches ROVER's sequential replay after --decision, and the
    summary note names it; a malformed one stops the run."""
    import argparse
    ap = argparse.ArgumentParser()
    bench.family_arguments(ap, "poc")
    a = ap.parse_args(["--decision", "chi2", "--set", "revoke_group=3", "--set", "threshold=0.3"])
    assert bench.decision_args(a) == ["--decision", "chi2", "--revoke_group", "3", "--threshold", "0.3"]
    assert "--set revoke_group=3 threshold=0.3" in bench.decision_note(a)
    assert bench.decision_args(ap.parse_args([])) == []
    with pytest.raises(SystemExit):
        bench.decision_args(ap.parse_args(["--set", "revoke_group"]))


def test_agreement_quick(tmp_path):
    # The condensed trial against the full-window trial: every family and comparison
    # gets a summary row over real candidates, and on the same graph and X (same-state) the two
    # trials decide alike: a condensed trial that moved the keyframes wrongly would not.
    agreement = script("bench/agreement.py")
    with shared_data():  # its real and posegraph families
        assert agreement.main(["--quick", "--jobs", "1", "--out", str(tmp_path)]) == 0
    with open(tmp_path / "summary.csv") as f:
        rows = {(r["family"], r["comparison"]): r for r in csv.DictReader(f)}
    for family in ("poc", "real", "posegraph"):
        for comparison in ("same-state", "oracle", "sequential"):
            r = rows[(family, comparison)]
            assert int(r["candidates"]) > 0 and int(r["agree"]) <= int(r["candidates"])
        same = rows[(family, "same-state")]
        assert float(same["agree_pct"]) >= 99.0, same
        assert int(same["scored"]) > 0 and float(same["dscore_median"]) < 0.05, same
    # Per case (cases.csv): the family's rows split by case, nothing lost or counted twice.
    with open(tmp_path / "cases.csv") as f:
        cases = list(csv.DictReader(f))
    for family in ("poc", "real", "posegraph"):
        for comparison in ("same-state", "oracle", "sequential"):
            mine = [c for c in cases if c["family"] == family and c["comparison"] == comparison]
            assert len(mine) == int(rows[(family, comparison)]["cases"])
            for k in ("candidates", "agree"):
                assert sum(int(c[k]) for c in mine) == int(rows[(family, comparison)][k])
    assert (tmp_path / "disagreements.csv").exists() and (tmp_path / "summary.md").exists()


def test_robustness_quick(tmp_path):
    """bench.sh robustness (the +-10 % target): every case runs at every setting with the
    setting's parameter scaled from the case's YAML, the counts from the verdicts match
    rover_replay's own, and summary.md pools them per family."""
    robustness = script("bench/robustness.py")
    out = tmp_path / "rob"
    assert robustness.main(["--quick", "--families", "poc", "--settings", "base,thr1.1,gate0.9",
                            "--set", "revoke_group=0", "--out", str(out), "--jobs", "1"]) == 0
    rows = _rows(out / "results.csv")
    cases = {r["case"] for r in rows}
    assert cases and len(rows) == 3 * len(cases)
    for case in cases:
        by = {r["setting"]: r for r in rows if r["case"] == case}
        base = by["base"]
        assert float(by["thr1.1"]["threshold"]) == pytest.approx(1.1 * float(base["threshold"]))
        assert by["thr1.1"]["max_innovation"] == base["max_innovation"]
        assert float(by["gate0.9"]["max_innovation"]) == pytest.approx(0.9 * float(base["max_innovation"]))
        assert float(by["gate0.9"]["max_innovation_per_metre"]) == pytest.approx(
            0.9 * float(base["max_innovation_per_metre"]))
        for r in by.values():
            assert r["counts_agree"] == "1", r
            assert int(r["tp"]) + int(r["fn"]) > 0
        command = (out / "runs" / "poc" / case / "thr1.1" / "command.txt").read_text()
        assert "--threshold" in command and "--revoke_group 0" in command
    text = (out / "summary.md").read_text()
    tp, fp, fn = (sum(int(r[k]) for r in rows if r["setting"] == "base") for k in ("tp", "fp", "fn"))
    assert f"| poc | {len(cases)} | {tp}/{fp}/{fn} P " in text


def test_robustness_settings_scale_the_yaml_or_the_case_flag(tmp_path):
    robustness = script("bench/robustness.py")
    cfg = tmp_path / "v.yaml"
    cfg.write_text("threshold: 0.2\nmax_innovation: 0.5\nmax_innovation_per_metre: 0.02\n")
    flags = ["--config", str(cfg), "--threshold", "0.3"]
    extra, values = robustness.setting_flags(flags, "thr0.9")
    assert extra == ["--threshold", "0.27"] and values["threshold"] == pytest.approx(0.27)
    extra, values = robustness.setting_flags(flags, "gate1.1")
    assert extra == ["--max_innovation", "0.55", "--max_innovation_per_metre", "0.022"]
    assert values["threshold"] == pytest.approx(0.3)
    assert robustness.setting_flags(flags, "base")[0] == []
    cfg.write_text("threshold: 0.2\n")
    with pytest.raises(ValueError):
        robustness.setting_flags(["--config", str(cfg)], "gate0.9")


def resumed_robustness_run(robustness, tmp_path):
    """A finished quick sweep (poc, base setting) whose done.json now says tp 9999, what a
    resumed run would read back; resumed once with the same inputs, it must still say so.
    Returns (args, done.json, the real tp)."""
    import json
    out = tmp_path / "rob"
    args = ["--quick", "--families", "poc", "--settings", "base", "--out", str(out), "--jobs", "1"]
    assert robustness.main(args) == 0
    done = next((out / "runs" / "poc").glob("*/base/done.json"))
    row = json.loads(done.read_text())
    real_tp = row["tp"]
    row["tp"] = 9999
    done.write_text(json.dumps(row))
    robustness.main(args)  # the same inputs: resumed, the finished run is not redone
    assert json.loads(done.read_text())["tp"] == 9999
    return args, done, real_tp


def test_robustness_starts_over_for_another_build_or_set(tmp_path):
    """Finished runs are reused only for the same binary, YAMLs, split and --set."""
    import json
    robustness = script("bench/robustness.py")
    args, done, real_tp = resumed_robustness_run(robustness, tmp_path)
    assert robustness.main(args + ["--set", "revoke_group=0"]) == 0  # other --set: starts over
    assert json.loads(done.read_text())["tp"] == real_tp


def test_robustness_starts_over_for_a_rebuilt_core_library(tmp_path, monkeypatch):
    """The verifier is in the core library: a rebuilt core with the same rover_replay binary
    is another build (it was not, and reused the runs of the build before)."""
    import json
    robustness = script("bench/robustness.py")
    files = robustness.build_files(bench.tool("rover_replay"))
    assert any(os.path.basename(f) == "librover_loop_fusion_core.so" for f in files), files
    fake_core = tmp_path / "librover_loop_fusion_core.so"
    fake_core.write_bytes(b"one build")
    monkeypatch.setattr(robustness, "build_files", lambda replay: [replay, str(fake_core)])
    args, done, real_tp = resumed_robustness_run(robustness, tmp_path)
    fake_core.write_bytes(b"another build")
    assert robustness.main(args) == 0  # the core rebuilt: starts over
    assert json.loads(done.read_text())["tp"] == real_tp


def test_robustness_runs_where_there_is_no_git(tmp_path, monkeypatch):
    """A fresh machine has no git (fresh-debian caught it): the commit is then left out."""
    import shutil
    robustness = script("bench/robustness.py")
    if shutil.which("git") and os.path.isdir(os.path.join(bench.ROOT, ".git")):
        assert robustness.commit()  # this clone
    monkeypatch.setenv("PATH", str(tmp_path))  # no git on it
    assert robustness.commit() is None


def test_identity_keeps_both_splits_of_a_case(tmp_path, monkeypatch):
    """The simulated scenes share case names between the splits (other seeds). Identity wrote
    both splits' scenarios into one directory and skipped the second split's runs as done: a
    comparison covered one of them. Each split now has its own scenario and verdicts."""
    import json
    from roverlib import splits as roverlib_splits
    identity = script("bench/identity.py")
    room = {split: [c for c in roverlib_splits.cases("poc", split, False) if c.name == "room_s0.05"]
            for split in roverlib_splits.SPLITS}
    assert all(len(cases) == 1 for cases in room.values()), "room_s0.05 is in both splits"
    monkeypatch.setattr(roverlib_splits, "cases", lambda family, split, quick: room[split])
    monkeypatch.setattr(identity, "SHIPPED", ())
    out = str(tmp_path)
    assert identity.main(["build", "--out", out, "--families", "poc"]) == 0
    dirs = {e["split"]: e["dir"] for e in json.load(open(os.path.join(out, "cases.json")))}
    assert sorted(dirs) == sorted(roverlib_splits.SPLITS) and len(set(dirs.values())) == len(dirs)
    assert identity.main(["run", "--out", out, "--tag", "a", "--configs", "shipped", "--jobs", "1"]) == 0
    verdicts = {s: _rows(os.path.join(out, "a", "poc", s, "room_s0.05", "shipped-sequential.csv"))
                for s in roverlib_splits.SPLITS}
    labels = {s: _rows(os.path.join(dirs[s], "candidates.csv")) for s in dirs}
    for s in dirs:  # each split's final verdicts are its own scenario's candidates
        assert sorted((r["query_index"], r["match_index"]) for r in verdicts[s] if r["final"] == "1") == \
            sorted((r["query_index"], r["match_index"]) for r in labels[s])
    assert labels["tuning"] != labels["test"], "other seeds, other candidates"
