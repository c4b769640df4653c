"""The tuning/test split (roverlib/splits.py): disjoint, hard cases on both sides, the threshold
sweep reads only the tuning set, and a scene without true loops says so in its name."""
import collections

import pytest

from conftest import missing_shared_data, script
from roverlib import datasets, splits

threshold_sweep = script("threshold_sweep.py")


def test_tuning_and_test_share_no_scene_seed_pair_and_no_sequence():
    tuning, test = splits.cases(split="tuning"), splits.cases(split="test")
    assert tuning and test
    pairs = collections.defaultdict(set)
    sequences = collections.defaultdict(set)
    for c in tuning + test:
        k = c.kwargs
        if c.family == "poc":
            pairs[(k["name"], k["seed"])].add(c.split)
        if c.family == "real":
            sequences["euroc_mh04" if k["name"].startswith("euroc_mh04") else k["name"]].add(c.split)
        if c.family == "posegraph":
            sequences[k["graph"]].add(c.split)
        if c.family == "poc" and k["name"] == "kitti_route":
            sequences[f"kitti_{k['sequence']}"].add(c.split)
    assert not [p for p, s in pairs.items() if len(s) > 1]
    assert not [q for q, s in sequences.items() if len(s) > 1]
    assert splits.overlaps() == ([], [])


def test_every_family_has_both_splits_and_unique_names():
    for family in splits.FAMILIES:
        for split in splits.SPLITS:
            cs = splits.cases(family, split)
            assert cs, (family, split)
            assert len({c.name for c in cs}) == len(cs)
        assert splits.cases(family, "test", quick=True), f"{family}: CI runs a --quick subset of the test set"
        assert not splits.cases(family, "tuning", quick=True)


def _hard(c):
    """The hard-case features of a case."""
    k = c.kwargs
    out = set()
    if c.family == "poc":
        near = {"warehouse": "spacing", "parking_deck": "floor_height", "corridor": "door_spacing"}
        if k["name"] in near and k.get(near[k["name"]], 3.0) < 3.0:
            out.add({"warehouse": "lateral", "parking_deck": "vertical", "corridor": "along"}[k["name"]])
        if k.get("rows", 1) > 1:
            out.add("rows")
        if k.get("early_lookalike"):
            out.add("early")
        if k["sigma"] >= 0.25:
            out.add("noise")
        if k["name"] in ("city", "kitti_route"):
            out.add("long laps")
        if k.get("laps", 0) >= 10:
            out.add("many laps")
        if not c.true_loops:
            out.add("no true loops")
    if c.family == "real" and "lookalike" in k:
        out.add("near")
    if c.family == "posegraph":
        out.add(k["kind"])
    return out


def test_hard_cases_on_both_sides():
    for family, needed in (("poc", {"lateral", "vertical", "along", "rows", "early", "noise", "long laps",
                                    "many laps", "no true loops"}),
                           ("real", {"near"}), ("posegraph", {"near", "grouped", "repetitive"})):
        for split in splits.SPLITS:
            got = set().union(*(_hard(c) for c in splits.cases(family, split)))
            assert needed <= got, (family, split, needed - got)


def test_threshold_sweep_reads_only_the_tuning_set():
    for env in ("indoor", "outdoor"):
        chosen = threshold_sweep.sweep_cases(env)
        assert chosen and all(c.split == "tuning" and c.environment == env for c in chosen)
        assert threshold_sweep.sweep_cases(env, quick=True) == chosen[:4]
    with pytest.raises(SystemExit):
        threshold_sweep.main(["--split", "test"])  # there is no such option


def test_a_case_without_true_loops_says_so_in_its_name():
    missing = []  # the cases that read ../shared/data, where it is not there
    for c in splits.cases("poc") + splits.cases("real"):
        try:
            s = c.build()
        except datasets.MissingData as e:
            missing.append(str(e))
            continue
        none = s.meta["true_candidates"] == 0
        assert none == ("no_true_loops" in c.name) == (not c.true_loops), c.name
        assert s.meta["false_candidates"] > 0, c.name
    if missing:
        missing_shared_data(f"{len(missing)} cases, e.g. {missing[0]}")
