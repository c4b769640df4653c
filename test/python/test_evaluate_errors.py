"""scripts/evaluate.py on malformed input (a red team's findings): one line
"evaluate.py: error: FILE[:LINE]: what" and exit status 2, never a traceback; a byte-order
mark in a label file is not an error."""
import pytest

from conftest import script
from roverlib import scenario

evaluate = script("evaluate.py")

HEADER = ("query_stamp,match_stamp,query_index,match_index,accepted,reason,score,threshold,converged,"
          "iterations,window_size,solve_ms,elapsed_ms,inliers,innovation,path_length,verifier,detail")


def verdicts(tmp_path, rows, name="verdicts.csv"):
    p = tmp_path / name
    p.write_text(HEADER + "\n" + "".join(
        f"0,0,{q},{m},{a},accepted,{s},0.2,1,3,10,1,1,-1,0.1,5,test,\"\"\n" for q, m, a, s in rows))
    return str(p)


def labels(tmp_path, rows, bom=False):
    p = tmp_path / "candidates.csv"
    text = scenario.CANDIDATES_HEADER + "\n" + "".join(
        f"{q},{m},0,0,0,0,0,0,1,0,-1,{lab}\n" for q, m, lab in rows)
    p.write_bytes(("\ufeff" if bom else "").encode() + text.encode())
    return str(p)


def run(capsys, *argv):
    status = evaluate.main(list(argv))
    captured = capsys.readouterr()
    run.out = captured.out
    return status, captured.err.strip().splitlines()


@pytest.fixture
def good_labels(tmp_path):
    return labels(tmp_path, [(10, 1, 1), (20, 2, 0)])


def test_an_empty_verdict_log(tmp_path, capsys, good_labels):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    status, err = run(capsys, "--verdicts", str(empty), "--labels", good_labels)
    assert status == 2
    assert err == [f"evaluate.py: error: {empty}: the verdict log is empty (not even a header)"]
    only_header = tmp_path / "header.csv"
    only_header.write_text(HEADER + "\n")
    status, err = run(capsys, "--verdicts", str(only_header), "--labels", good_labels)
    assert (status, len(err)) == (2, 1)
    assert "has no verdicts" in err[0] and str(only_header) in err[0]


def test_run_without_ground_truth(tmp_path, capsys, good_labels):
    out = tmp_path / "replay"
    out.mkdir()
    verdicts(out, [(10, 1, 1, 0.1)])
    status, err = run(capsys, "--run", str(out), "--labels", good_labels)
    assert (status, len(err)) == (2, 1)
    assert f"{out}: no groundtruth.tum" in err[0]


def test_a_byte_order_mark_in_the_label_file_is_ignored(tmp_path, capsys):
    v = verdicts(tmp_path, [(10, 1, 1, 0.1), (20, 2, 0, 0.9)])
    status, err = run(capsys, "--verdicts", v, "--labels", labels(tmp_path, [(10, 1, 1), (20, 2, 0)], bom=True))
    assert status == 0, err
    assert err == []
    assert "2 labelled candidates (1 true, 1 false)" in run.out


def test_a_label_that_is_not_an_integer_names_file_and_line(tmp_path, capsys):
    v = verdicts(tmp_path, [(10, 1, 1, 0.1)])
    c = labels(tmp_path, [(10, 1, 1), (20, 2, "nan")])
    status, err = run(capsys, "--verdicts", v, "--labels", c)
    assert (status, len(err)) == (2, 1)
    assert err[0] == f"evaluate.py: error: {c}:3: label 'nan' is not an integer"


def test_a_verdict_index_that_is_not_an_integer_names_file_and_line(tmp_path, capsys, good_labels):
    v = verdicts(tmp_path, [(10, 1, 1, 0.1), ("nan", 2, 0, 0.5)])
    status, err = run(capsys, "--verdicts", v, "--labels", good_labels)
    assert (status, len(err)) == (2, 1)
    assert err[0] == f"evaluate.py: error: {v}:3: query_index 'nan' is not an integer"


def test_missing_columns_and_missing_files(tmp_path, capsys, good_labels):
    bad = tmp_path / "not_verdicts.csv"
    bad.write_text("a,b,c\n1,2,3\n")
    status, err = run(capsys, "--verdicts", str(bad), "--labels", good_labels)
    assert (status, len(err)) == (2, 1)
    assert f"{bad}:1: not a verdict log: no column query_index, match_index, accepted, reason, score" in err[0]
    status, err = run(capsys, "--verdicts", str(tmp_path / "nope.csv"), "--labels", good_labels)
    assert (status, len(err)) == (2, 1)
    assert "nope.csv: cannot read the verdict log: No such file or directory" in err[0]


# ---- figures a user must not trust are refused, with the reason ----------------

def node_log(tmp_path, rows, name="node.csv"):
    """A node's ~verdict_log: rows (query, match, accepted, reason, score, final, decision)."""
    p = tmp_path / name
    p.write_text(HEADER + ",final,decision\n" + "".join(
        f"0,0,{q},{m},{a},{reason},{s},0.2,1,3,10,1,1,-1,0.1,5,test,\"\",{f},{d}\n"
        for q, m, a, reason, s, f, d in rows))
    return str(p)


def eighty(tmp_path):
    """80 labelled candidates (every other one true) and their verdict rows, all right."""
    pairs = [(100 + i, i, i % 2) for i in range(80)]
    return labels(tmp_path, pairs), [(q, m, lab, 0.1 if lab else 0.5) for q, m, lab in pairs]


def test_lost_verdicts_are_refused_not_scored_as_fewer_candidates(tmp_path, capsys):
    # Before: a log missing 70 of 80 labelled candidates was scored as "10 labelled candidates", exit 0.
    c, rows = eighty(tmp_path)
    v = verdicts(tmp_path, rows[:10])
    status, err = run(capsys, "--verdicts", v, "--labels", c)
    assert (status, len(err)) == (2, 1), err
    assert f"70 of the 80 candidates in {c} have no verdict (lost verdicts; the first: loop 110 -> 10)" in err[0]
    assert "not scored" in err[0] and "labelled candidates" not in run.out
    # candidates labelled -1 (unknown) need their verdict too
    c2 = labels(tmp_path, [(10, 1, 1), (20, 2, 0), (30, 3, -1)])
    status, err = run(capsys, "--verdicts", verdicts(tmp_path, [(10, 1, 1, 0.1), (20, 2, 0, 0.5)]), "--labels", c2)
    assert status == 2 and "1 of the 3 candidates" in err[0] and "loop 30 -> 3" in err[0]


def test_verdicts_for_unknown_pairs_and_repeated_rows_are_refused(tmp_path, capsys):
    c, rows = eighty(tmp_path)
    v = verdicts(tmp_path, rows + [(999, 5, 1, 0.1)])
    status, err = run(capsys, "--verdicts", v, "--labels", c)
    assert (status, len(err)) == (2, 1), err
    assert "the first at line 82: loop 999 -> 5 is not in" in err[0]
    v = verdicts(tmp_path, rows[:1] + rows)  # the first row twice
    status, err = run(capsys, "--verdicts", v, "--labels", c)
    assert (status, len(err)) == (2, 1), err
    assert "the first at line 3: more verdicts for loop 100 -> 0 than" in err[0] and "repeated row" in err[0]
    # a pair the label file lists twice (the same loop proposed twice) takes two verdicts
    c2 = labels(tmp_path, [(10, 1, 1), (10, 1, 1), (20, 2, 0)])
    status, err = run(capsys, "--verdicts", verdicts(tmp_path, [(10, 1, 1, 0.1), (10, 1, 0, 0.1), (20, 2, 0, 0.5)]),
                      "--labels", c2)
    assert status == 0, err
    assert "3 labelled candidates (2 true, 1 false)" in run.out


@pytest.mark.parametrize("score, why", [("abc", "score 'abc' is not a number"), ("", "score '' is not a number"),
                                        ("-1e308", "score -1e308 is negative"), ("-inf", "score -inf is negative"),
                                        ("-0.1", "score -0.1 is negative")])
def test_scores_that_are_not_numbers_or_negative_are_refused(tmp_path, capsys, good_labels, score, why):
    v = verdicts(tmp_path, [(10, 1, 1, 0.1), (20, 2, 1, score)])
    status, err = run(capsys, "--verdicts", v, "--labels", good_labels)
    assert (status, len(err)) == (2, 1), err
    assert err[0].startswith(f"evaluate.py: error: {v}:3: {why}"), err


def test_no_score_ranks_last(tmp_path, capsys, good_labels):
    for score in ("nan", "inf"):
        status, err = run(capsys, "--verdicts", verdicts(tmp_path, [(10, 1, 1, 0.1), (20, 2, 0, score)]),
                          "--labels", good_labels)
        assert status == 0, err
        assert "AP 1.0000" in run.out


def test_a_nodes_log_is_read_as_each_candidates_final_verdict(tmp_path, capsys):
    c = labels(tmp_path, [(10, 1, 1), (20, 2, 0), (30, 3, 1), (40, 4, 0), (50, 5, 1)])
    rows = [(10, 1, 0, "deferred", "nan", 0, "verify"),           # held ...
            (20, 2, 0, "deferred", "nan", 0, "verify"),
            (30, 3, 1, "accepted", 0.05, 1, "verify"),
            (10, 1, 1, "accepted", "nan", 1, "release"),           # ... released: accepted
            (20, 2, 0, "unconfirmed", "nan", 1, "drop"),           # ... dropped
            (40, 4, 1, "accepted", 0.1, 1, "verify"),
            (40, 4, 0, "revoked", "nan", 1, "revoke"),             # accepted, then revoked
            (50, 5, 1, "accepted", 0.02, 1, "release")]            # rover_replay's one-row form
    status, err = run(capsys, "--verdicts", node_log(tmp_path, rows), "--labels", c)
    assert status == 0, err
    assert "5 labelled candidates (3 true, 2 false)" in run.out
    assert "TP 3 FP 0 TN 2 FN 0" in run.out
    # a held candidate whose final verdict never came (the log ends before the decision): not
    # accepted, as the run never used it, and said so
    v = node_log(tmp_path, rows[:3] + rows[4:])
    status, err = run(capsys, "--verdicts", v, "--labels", c)
    assert (status, len(err)) == (0, 1), err
    assert err[0].startswith(f"evaluate.py: warning: {v}:2: 1 candidate(s) still held when the log ends (the first: "
                             f"loop 10 -> 1"), err
    assert "scored as not accepted" in err[0]
    assert "TP 2 FP 0 TN 2 FN 1" in run.out
    status, err = run(capsys, "--verdicts", node_log(tmp_path, rows[:1] + [(10, 1, 0, "accepted", 1, 1, "keep")]),
                      "--labels", c)
    assert status == 2 and "decision 'keep' is not one of verify, release, drop, revoke" in err[0]


def test_a_nodes_log_with_a_repeated_held_candidate_is_read_copy_by_copy(tmp_path, capsys):
    # issue 45 item 3: one "held" slot per pair: a candidate held and proposed again while held
    # (its copies are decided with it, in the order they came) left "2 candidate(s) still held
    # when the log ends" and "2 verdict(s) for no candidate", exit 2, on a whole log.
    c = labels(tmp_path, [(10, 1, 1)] * 3 + [(20, 2, 0)] * 3 + [(30, 3, 1)] * 2)
    rows = [(10, 1, 0, "deferred", 0.3, 0, "verify")] * 3 + \
           [(20, 2, 0, "deferred", 0.4, 0, "verify")] * 3 + \
           [(30, 3, 0, "deferred", 0.1, 0, "verify"),
            (30, 3, 1, "accepted", 0.1, 1, "release"),           # released, then its copy
            (30, 3, 0, "deferred", 0.1, 0, "verify")] + \
           [(10, 1, 1, "accepted", "nan", 1, "release")] * 3 + \
           [(20, 2, 0, "unconfirmed", "nan", 1, "drop")] * 3 + \
           [(30, 3, 1, "accepted", "nan", 1, "release"),
            (30, 3, 0, "revoked", "nan", 1, "revoke"),            # the first release revoked
            (30, 3, 0, "revoked", "nan", 1, "revoke")]            # and the copy's
    status, err = run(capsys, "--verdicts", node_log(tmp_path, rows), "--labels", c)
    assert (status, err) == (0, []), err
    assert "8 labelled candidates (5 true, 3 false)" in run.out
    assert "TP 3 FP 0 TN 3 FN 2" in run.out
    got = evaluate.read_verdicts(node_log(tmp_path, rows))
    assert [(r["query_index"], r["decision"], r["score"]) for r in got] == \
        [("10", "release", "0.3")] * 3 + [("20", "drop", "0.4")] * 3 + [("30", "revoke", "0.1")] * 2
    # the last copy's decision missing: that one copy is still held when the log ends
    status, err = run(capsys, "--verdicts", node_log(tmp_path, rows[:10] + rows[11:]), "--labels", c)
    assert status == 0 and len(err) == 1 and "1 candidate(s) still held when the log ends" in err[0], err
    assert "TP 2 FP 0 TN 3 FN 3" in run.out


def test_metrics_json_is_strict_json(tmp_path, capsys):
    # Only true loops: AP and MR are undefined; nothing accepted would make precision undefined.
    import json
    c = labels(tmp_path, [(10, 1, 1), (20, 2, 1)])
    out = tmp_path / "eval"
    status, err = run(capsys, "--verdicts", verdicts(tmp_path, [(10, 1, 0, 0.1), (20, 2, 0, 0.5)]), "--labels", c,
                      "--out", str(out))
    assert status == 0, err

    def no_constant(name):
        raise AssertionError(f"metrics.json holds {name}, which is not JSON")
    m = json.loads((out / "metrics.json").read_text(), parse_constant=no_constant)
    assert m["ap"] is None and m["mr"] is None and m["precision"] is None
    assert m["recall"] == 0.0 and m["fn"] == 2
    assert "AP -" in run.out and "precision -" in run.out


@pytest.mark.parametrize("bad, why", [("nan", "x 'nan' is not finite"), ("dup", "stamp 2 repeats line 3"),
                                      ("short", "7 values, a line of a TUM ground truth has 8 (stamp x y z qx qy qz qw)")])
def test_ground_truth_with_nan_or_repeated_stamps_is_refused(tmp_path, capsys, good_labels, bad, why):
    # ground truth with NaN or duplicate rows was accepted ("SVD did not converge",
    # or an ATE against the wrong pose).
    rows = [f"{i} {i}.0 0 0 0 0 0 1" for i in range(1, 6)]
    if bad == "nan":
        rows[1] = "2 nan 0 0 0 0 0 1"
    elif bad == "dup":
        rows.insert(2, rows[1])
    else:
        rows[1] = "2 2.0 0 0 0 0 1"
    gt = tmp_path / "gt.tum"
    gt.write_text("# t x y z qx qy qz qw\n" + "\n".join(rows) + "\n")
    est = tmp_path / "est.tum"
    est.write_text("\n".join(f"{i} {i}.0 0 0.1 0 0 0 1" for i in range(1, 6)) + "\n")
    v = verdicts(tmp_path, [(10, 1, 1, 0.1), (20, 2, 0, 0.5)])
    status, err = run(capsys, "--verdicts", v, "--labels", good_labels, "--groundtruth", str(gt),
                      "--trajectory", f"est={est}", "--align", "none")
    assert (status, len(err)) == (2, 1), err
    line = 4 if bad == "dup" else 3
    assert err[0] == f"evaluate.py: error: {gt}:{line}: {why}" + (" (two poses at one time)" if bad == "dup" else "")
