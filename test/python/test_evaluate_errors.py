"""scripts/evaluate.py on malformed input (issue 14's red team): one line
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
