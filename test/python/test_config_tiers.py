"""The parameters in tiers (config/rover_template.yaml, then an override) give every host the
parameter set the three full YAMLs gave before them (test/data/config_before_tiers.json: what
config/rover_indoor.yaml, rover_outdoor.yaml and rover_paper.yaml set at commit 485d8ea), so
that every figure stays as it was: with --decision chi2 or revisit (the benchmarks add an
override's opt-in keys then) the sets are equal; at the shipped decision, metric, they differ
only in those opt-in keys, and those change no verdict there. Checked on roverlib.config's merge, on what rover_replay
reads (its describe() line) and on bench.shipped(). The launch files' two loads are checked in
test/ros/test_launch.py."""
import csv
import json
import os
import subprocess

import pytest
import yaml

from conftest import ROOT, built_tool
from roverlib import bench, config

BEFORE = os.path.join(ROOT, "test", "data", "config_before_tiers.json")
HOST_SET = ("accept_without_prior", "anchor_incoming_keyframes", "confirm_without_prior")


def before(environment, decision=None):
    with open(BEFORE) as f:
        c = json.load(f)[environment]
    if decision is not None:
        c["decision"] = decision
    return c


def described(tool, tmp_path, args):
    """The parameter line rover_replay prints for `args` (it stops at the missing scenario)."""
    res = subprocess.run([tool, "--scenario", str(tmp_path / "none"), "--out", str(tmp_path / "out")] + args,
                         capture_output=True, text=True)
    line = res.stdout.split("\n")[0]
    assert line.startswith("rover_replay: decision="), res.stdout + res.stderr
    return line.split(";")[0]


@pytest.mark.parametrize("decision", [None, "metric", "chi2", "revisit"])
@pytest.mark.parametrize("environment", config.ENVIRONMENTS)
def test_merge_equals_the_full_files(environment, decision):
    got, want = config.effective(environment, decision), before(environment, decision)
    if got["decision"] in config.OPT_IN_DECISIONS:
        assert got == want
    else:
        # At decision metric an override's opt-in keys (no effect there) are at the defaults:
        # they are all that differs (test_opt_in_keys_change_no_verdict_at_metric).
        differ = {k for k in want if got.get(k) != want[k]}
        assert differ == set(config.opt_in(environment))
        assert {k: got[k] for k in differ} == {k: config.defaults()[k] for k in differ}


@pytest.mark.parametrize("environment", [e for e in config.ENVIRONMENTS if config.opt_in(e)])
def test_opt_in_keys_change_no_verdict_at_metric(tmp_path, environment):
    # So the figures at the shipped decision stay what the full files gave: every column of
    # verdicts.csv but the times, on the scenes of test_shipped_keys.py and the shipped ones.
    from test_shipped_keys import make_scenes
    tool = built_tool("rover_replay")
    scenes = dict(make_scenes(str(tmp_path / "scenes")))
    for name in ("warehouse", "euroc_mh05"):
        scenes[name] = os.path.join(ROOT, "data", name)
    timing = ("solve_ms", "elapsed_ms")
    for name, scene in scenes.items():
        rows = []
        for i, extra in enumerate(([], config.opt_in_args(environment, ["--decision", "chi2"]))):
            out = tmp_path / f"{name}{i}"
            args = config.replay_args(environment) + extra + ["--time_budget_ms", "0"]
            subprocess.run([tool, "--scenario", scene, "--out", str(out), "--quiet", "--snapshots", "0"] + args,
                           check=True, capture_output=True)
            with open(out / "verdicts.csv") as f:
                rows.append([{k: v for k, v in r.items() if k not in timing}
                             for r in csv.DictReader(line for line in f if not line.startswith("#"))])
        assert rows[0] == rows[1], name


def test_overrides_hold_only_keys_that_differ_from_the_template():
    template = config.load(config.TEMPLATE)
    for environment in config.ENVIRONMENTS:
        override = config.load(config.override_path(environment))
        for key, value in override.items():
            assert key in template, f"rover_{environment}.yaml sets {key}, which the template does not"
            assert template[key] != value, f"rover_{environment}.yaml repeats the template's {key}"
        assert not set(config.opt_in(environment)) & set(template), "opt-in keys are not set in the template"
    assert config.load(config.override_path("indoor")) == {}, "the template holds the indoor values"


def test_template_names_every_parameter_once_at_its_default(tmp_path):
    tool = built_tool("rover_replay")
    set_keys, named = config.load(config.TEMPLATE), config.defaults()
    assert not set(set_keys) & set(named)
    # Every key at its default: the template alone reads as the core's defaults.
    full = dict(named, **set_keys)
    path = tmp_path / "full.yaml"
    path.write_text(yaml.safe_dump(full))
    assert described(tool, tmp_path, ["--config", str(path)]) == described(tool, tmp_path, [])
    names = set(full) | set(HOST_SET)
    help_text = subprocess.run([tool, "--help"], capture_output=True, text=True).stdout
    table = {line.split()[0][2:] for line in help_text.splitlines() if line.startswith("  --")}
    assert names == table, "the template names every parameter of the table but the host-set ones"


@pytest.mark.parametrize("decision", ["metric", "chi2", "revisit"])
@pytest.mark.parametrize("environment", config.ENVIRONMENTS)
def test_rover_replay_reads_what_the_full_files_set(tmp_path, environment, decision):
    tool = built_tool("rover_replay")
    old = tmp_path / "before.yaml"
    old.write_text(yaml.safe_dump(before(environment)))
    flags = ["--decision", decision]
    if decision == "metric":  # at metric, the opt-in keys at the defaults (see above)
        old.write_text(yaml.safe_dump(dict(before(environment), **{
            k: config.defaults()[k] for k in config.opt_in(environment)})))
    want = described(tool, tmp_path, ["--config", str(old)] + flags)
    assert described(tool, tmp_path, bench.shipped(environment, *flags)) == want
    if decision == "metric":
        assert described(tool, tmp_path, config.replay_args(environment)) == want
