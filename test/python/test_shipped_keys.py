"""Nothing shipped does nothing at the defaults (issue 44): every key the shipped verifier YAMLs
set changes a verdict when its value is changed substantially.

A perturbation test. For every key of config/rover_template.yaml (judged at the template's
values) and of each override (judged at template + override, the effective set of that host),
rover_replay runs small scenes made from data/corridor with the key's value changed (numbers
scaled by 1e-2, 1e2 and 1e-4, a zero set to fractions of its range, and the ends of the range;
booleans flipped, choices switched), and the test asserts that the verdicts (verdicts.csv: accepted, reason, score) of
some run differ from the unchanged run's. The scenes exercise what clean single-session input
does not: a second session (sequence 2 from the second lap on: held candidates, the cycle test
and its drift model) and bad input (a keyframe glitch, a relocation, a stamp far ahead, a
candidate with an unnormalised quaternion). Runs are without a time limit (--time_budget_ms 0
after the files, so that verdicts do not depend on the machine's load), but where
time_budget_ms itself is judged.

Keys read by the hosts only (the ROS node or the loop_fusion adapter, not the core) cannot be
judged by rover_replay: HOST_KEYS lists each with the test that exercises it, and the test
asserts that file names the key. test_perturbation_can_fail shows the check sees a key that
does nothing (revoke_margin at revoke_group 0).
"""
import csv
import os
import re
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor

import pytest
import yaml

from conftest import ROOT, built_tool

CONFIG = os.path.join(ROOT, "config")
TEMPLATE = "rover_template.yaml"
OVERRIDES = ("rover_indoor.yaml", "rover_outdoor.yaml", "rover_paper.yaml")
# Keys a shipped YAML may set that the core does not read: {key: test file that exercises it}.
# (None today: the adapter's own parameters, ~verdict_log, ~relocalisation, ..., are set by the
# launch files, not by the verifier YAMLs.)
HOST_KEYS = {}
VERDICT_COLUMNS = ("accepted", "reason", "score")


def table(tool):
    """{name: (range text, default text)} from `rover_replay --help` (the parameter table)."""
    text = subprocess.run([tool, "--help"], capture_output=True, text=True, check=True).stdout
    rows = {}
    for line in text.splitlines():
        m = re.match(r"  --(\w+)\s+(\S+(?: \S+)?(?: \S+)?)\s+default (\S+)", line)
        if m:
            rows[m.group(1)] = (m.group(2), m.group(3))
    return rows


def perturbations(value, range_text):
    """Substantially different values of a key within its range, as rover_replay flags read them."""
    if isinstance(value, bool):
        return ["false" if value else "true"]
    if isinstance(value, str):
        return [c for c in range_text.split("|") if c != value and not (value == "auto" and c == "4dof")]
    m = re.match(r"([\[(])([-0-9.e+]+), ([-0-9.e+]+)\]", range_text)
    lo, hi, lo_open = float(m.group(2)), float(m.group(3)), m.group(1) == "("
    integral = isinstance(value, int)
    v = float(value)
    wanted = [v * 1e-2, v * 1e2, v * 1e-4, hi] if v != 0 else [hi * 1e-6, hi * 1e-2, hi * 1e-4, hi * 1e-1, hi]
    if not lo_open:
        wanted.append(lo)
    out = []
    for w in wanted:
        w = min(max(w, lo), hi)
        if lo_open and w <= lo:
            continue
        if integral:
            w = int(round(w))
            if lo_open and w <= lo or w < lo:
                continue
        if w != v and w not in out:
            out.append(w)
    return [repr(w) if isinstance(w, float) else str(w) for w in out]


def write_rows(path, header, rows):
    with open(path, "w") as f:
        f.writelines(header)
        w = csv.writer(f, lineterminator="\n")
        w.writerows(rows)


def split(path):
    """(comment and header lines, rows as lists) of a scenario CSV."""
    lines = open(path).read().splitlines(keepends=True)
    n = next(i for i, line in enumerate(lines) if not line.startswith("#")) + 1
    return lines[:n], [line.rstrip("\n").split(",") for line in lines[n:] if line.strip()]


def make_scenes(root):
    """Two scenes from data/corridor (3 laps of 120 keyframes, 0.5 s apart)."""
    src = os.path.join(ROOT, "data", "corridor")
    scenes = {"corridor": src}
    # A second session: sequence 2 from the second lap on (nothing connects it at first).
    d = os.path.join(root, "two_sessions")
    os.makedirs(d)
    head, rows = split(os.path.join(src, "keyframes.csv"))
    for r in rows:
        if int(r[0]) >= 120:
            r[2] = "2"
    write_rows(os.path.join(d, "keyframes.csv"), head, rows)
    shutil.copy(os.path.join(src, "candidates.csv"), d)
    scenes["two_sessions"] = d
    # Bad input: a glitch (one keyframe 20 m off), a relocation (every keyframe from 200 on
    # 15 m off), a stamp 5000 s ahead, a candidate whose quaternion is 1 % long.
    d = os.path.join(root, "bad_input")
    os.makedirs(d)
    head, rows = split(os.path.join(src, "keyframes.csv"))
    for r in rows:
        i = int(r[0])
        if i == 150:
            r[3] = f"{float(r[3]) + 20.0:.9f}"
        if i >= 203:
            r[3] = f"{float(r[3]) + 15.0:.9f}"
        if i == 100:
            r[1] = f"{float(r[1]) + 5000.0:.9f}"
    write_rows(os.path.join(d, "keyframes.csv"), head, rows)
    head, rows = split(os.path.join(src, "candidates.csv"))
    for r in rows:
        if r[0] in ("137", "161", "207"):
            r[5:9] = [f"{float(x) * 1.01:.9f}" for x in r[5:9]]
    write_rows(os.path.join(d, "candidates.csv"), head, rows)
    scenes["bad_input"] = d
    return scenes


def verdicts(tool, scene, out, args):
    res = subprocess.run([tool, "--scenario", scene, "--out", out, "--quiet", "--snapshots", "0"] + args,
                         capture_output=True, text=True)
    assert res.returncode == 0, f"rover_replay {' '.join(args)}: {res.stderr}"
    with open(os.path.join(out, "verdicts.csv")) as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    return [tuple(r[c] for c in VERDICT_COLUMNS) for r in rows]


def files_of(name):
    """The files a host loads, in order, to get the set `name` is judged at."""
    return [TEMPLATE] if name == TEMPLATE else [TEMPLATE, name]


def load(name):
    with open(os.path.join(CONFIG, name)) as f:
        return yaml.safe_load(f) or {}


def dead_keys(tool, files, keys, tmp, rows):
    """The keys of `keys` whose perturbations change no verdict on any scene, loading `files`."""
    scenes = make_scenes(os.path.join(tmp, "scenes"))
    base_args = []
    for f in files:
        base_args += ["--config", os.path.join(CONFIG, f)]
    # No time limit (verdicts that do not depend on the machine's load), but where it is judged.
    base_args += ["--time_budget_ms", "0"]
    with ThreadPoolExecutor(2) as pool:
        base = dict(zip(scenes, pool.map(
            lambda s: verdicts(tool, scenes[s], os.path.join(tmp, "out", "baseline_" + s), base_args), scenes)))

    def changes_a_verdict(key):
        """True at the first perturbation and scene whose verdicts differ from the baseline's."""
        assert key in rows, f"{key} is no verifier parameter and not in HOST_KEYS"
        for p in perturbations(keys[key], rows[key][0]):
            for s in scenes:
                out = os.path.join(tmp, "out", f"{key}_{p}_{s}")
                if verdicts(tool, scenes[s], out, base_args + ["--" + key, p]) != base[s]:
                    return True
        return False

    judged = [k for k in keys if k not in HOST_KEYS]
    with ThreadPoolExecutor(2) as pool:
        live = dict(zip(judged, pool.map(changes_a_verdict, judged)))
    return sorted(k for k in judged if not live[k])


@pytest.fixture(scope="module")
def tool():
    return built_tool("rover_replay")


@pytest.mark.parametrize("name", (TEMPLATE,) + OVERRIDES)
def test_every_shipped_key_changes_a_verdict(tool, tmp_path, name):
    files = files_of(name)
    dead = dead_keys(tool, files, load(name), str(tmp_path), table(tool))
    assert dead == [], (f"{name} sets keys that change no verdict when changed (at {' + '.join(files)}): "
                        f"{', '.join(dead)}: remove them from the shipped YAML (the template may name "
                        "them, commented out, in its expert block)")


def test_host_keys_are_exercised():
    for key, test in HOST_KEYS.items():
        assert key in open(os.path.join(ROOT, "test", test)).read(), f"{test} does not exercise {key}"


def test_perturbation_can_fail(tool, tmp_path):
    # revoke_margin does nothing while revoke_group is 0 (no revocation); threshold does.
    dead = dead_keys(tool, [TEMPLATE], {"revoke_margin": 4.0, "threshold": 0.2}, str(tmp_path), table(tool))
    assert dead == ["revoke_margin"]
