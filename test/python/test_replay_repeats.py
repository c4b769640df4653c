"""rover_replay on repeated candidate messages (issue 45 item 2): its rows must say exactly what
the verifier did with each copy. It kept one open row per (query, match): the verifier's
decision about a held candidate went to the row of its latest copy, the first row stayed "still
held when the run ended", and a committed false loop disappeared from the figures."""
import csv
import os
import re
import subprocess

import pytest

from conftest import ROOT, built_tool
from roverlib import repeats, scenario


def _replay(s, directory, *flags):
    scenario.write(s, str(directory / "scn"))
    out = subprocess.run([built_tool("rover_replay"), "--scenario", str(directory / "scn"), "--out",
                          str(directory / "out"), "--quiet", "--time_budget_ms", "0"] + list(flags),
                         capture_output=True, text=True, check=True).stdout
    with open(directory / "out" / "verdicts.csv") as f:
        return list(csv.DictReader(f)), out


@pytest.mark.parametrize("pair, flags", [((204, 21), ()), ((136, 13), ("--decision", "revisit"))],
                         ids=["metric_204_21", "revisit_136_13"])
def test_every_copy_of_a_held_candidate_gets_the_row_of_what_the_verifier_decided(tmp_path, pair, flags):
    """The corridor relocated at keyframe 180 (+100 m), its true candidates and one false
    candidate sent three times in a row: each copy's row carries the same final verdict, decided
    at the same keyframe, and the printed figures count the rows as written."""
    s = repeats.relocated(scenario.read(os.path.join(ROOT, "data", "corridor")), 180, 100.0, pair)
    s.candidates = [c for c in s.candidates for _ in range(3 if (c.query, c.match) == pair else 1)]
    rows, out = _replay(s, tmp_path, *flags)
    its = repeats.by_pair(rows)[pair]
    assert len(its) == 3
    assert all(r["reason"] != "deferred" for r in its)
    first = its[0]
    for r in its:
        what = f"{pair}: {r['decision']} at {r['decided_at_keyframe']}: {r['detail'][:200]!r}"
        assert "still held when the run ended" not in r["detail"], what
        assert (r["accepted"], r["reason"], r["decision"], r["decided_at_keyframe"]) == \
            (first["accepted"], first["reason"], first["decision"], first["decided_at_keyframe"]), what
    assert first["accepted"] == "0", "a false candidate confirmed by its own copies"
    tp, fp = (int(x) for x in re.search(r"TP (\d+) FP (\d+)", out).groups())
    labels = {(c.query, c.match): c.label for c in s.candidates}
    accepted = [labels[(int(r["query_index"]), int(r["match_index"]))] for r in rows if r["accepted"] == "1"]
    assert (tp, fp) == (accepted.count(1), accepted.count(0))
    assert fp == 0 and tp == sum(1 for c in s.candidates if c.label == 1)
