#!/usr/bin/env python3
"""Robustness of ROVER's decisions to its two main parameters (the target: moving the
score threshold or the gate by +-10 % changes no case's recall by more than 0.05).

Every case of the split (the family's own scenario: same candidates and order as the family
benchmark) is replayed with rover_replay, sequential protocol, with the case's ROVER flags
exactly as the family benchmark runs it (the shipped YAML of its environment, its mode, the
time budget lifted) and then one setting:

  base      nothing more
  thr0.9    --threshold 0.9 x the YAML's value          thr1.1    1.1 x
  gate0.9   --max_innovation and --max_innovation_per_metre both 0.9 x the YAML's values
  gate1.1   both 1.1 x

  ./scripts/bench.sh robustness [--split test|tuning] [--families poc,real,posegraph] [--only CASES]
                                [--settings base,thr0.9,...] [--set KEY=VALUE ...] [--quick]
                                [--out results/robustness] [--jobs 2]

Writes OUT/results.csv (a row per case and setting: TP/FP/TN/FN from the verdicts joined with
the scenario's labels, checked against rover_replay's own line), OUT/summary.md (TP/FP/FN per
family and setting; recall per case over the settings, its spread = max - min, the cases above
--spread listed) and OUT/meta.json. An interrupted run goes on where it stopped (a finished run
has its done.json) if the rover_replay binary and its libraries, the YAMLs of config/, the split and --set are
the same; otherwise it starts over. The real family and the pose graphs read ../shared/data.
"""
import argparse
import csv
import glob
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import yaml

from roverlib import bench, methods, metrics, programs, splits

SETTINGS = {  # name -> {parameter: factor}
    "base": {},
    "thr0.9": {"threshold": 0.9},
    "thr1.1": {"threshold": 1.1},
    "gate0.9": {"max_innovation": 0.9, "max_innovation_per_metre": 0.9},
    "gate1.1": {"max_innovation": 1.1, "max_innovation_per_metre": 1.1},
}
SCALED = ("threshold", "max_innovation", "max_innovation_per_metre")
FAMILIES = ("poc", "real", "posegraph")
SUMMARY = re.compile(r"TP (\d+) FP (\d+) TN (\d+) FN (\d+)")
COLUMNS = ["family", "case", "split", "setting", *SCALED, "tp", "fp", "tn", "fn", "precision", "recall",
           "replay_tp", "replay_fp", "replay_tn", "replay_fn", "counts_agree", "seconds"]


def fmt(v):
    return f"{v:.10g}"


def flag_value(flags, name):
    """The last value given to --name in flags (None if absent)."""
    v = None
    for i, f in enumerate(flags[:-1]):
        if f == f"--{name}":
            v = flags[i + 1]
    return v


def setting_flags(flags, setting):
    """(the flags a setting appends, {parameter: the value it runs with}) for a case's flags: the
    values scaled are the YAMLs' (every --config, in order: the template, then the override), or
    a flag of the case's that overrides them."""
    cfgs = [flags[i + 1] for i, f in enumerate(flags[:-1]) if f == "--config"]
    y = {}
    for cfg in cfgs:
        with open(cfg) as f:
            y.update(yaml.safe_load(f) or {})
    values = {}
    for key in SCALED:
        v = flag_value(flags, key)
        if v is None:
            if key not in y:
                raise ValueError(f"{', '.join(cfgs) or 'no --config'}: no {key}; give it in the case's flags")
            v = y[key]
        values[key] = float(v)
    extra = []
    for key, factor in SETTINGS[setting].items():
        values[key] = float(fmt(values[key] * factor))
        extra += [f"--{key}", fmt(values[key])]
    return extra, values


def counts(verdicts_path, labels_path):
    """TP/FP/TN/FN of a run's final verdicts against the scenario's labels (metrics.join: the
    candidates of one (query, match) pair take their labels in order; label -1 left out)."""
    rows = metrics.read_final_verdicts(verdicts_path)
    j = metrics.join(rows, metrics.read_labels(labels_path))
    true, accepted = j["label"] == 1, j["accepted"]
    return {"tp": int((true & accepted).sum()), "fp": int((~true & accepted).sum()),
            "tn": int((~true & ~accepted).sum()), "fn": int((true & ~accepted).sum())}


def ratio(a, b):
    return a / b if b else None


def run_one(job):
    entry, setting, a = job
    d = os.path.join(a.out, "runs", entry["family"], entry["case"], setting)
    done = os.path.join(d, "done.json")
    if os.path.exists(done):
        with open(done) as f:
            return json.load(f)
    shutil.rmtree(d, ignore_errors=True)
    os.makedirs(d)
    extra, values = setting_flags(entry["flags"], setting)
    tmp = os.path.join(d, "replay")
    cmd = [a.replay, "--scenario", entry["dir"], "--out", tmp, "--protocol", "sequential", "--quiet"] + \
        entry["flags"] + extra + a.set_flags
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    for name, text in (("command.txt", " ".join(cmd) + "\n"), ("stdout.txt", res.stdout), ("stderr.txt", res.stderr)):
        with open(os.path.join(d, name), "w") as f:
            f.write(text)
    if res.returncode != 0:
        raise RuntimeError(f"{entry['family']}/{entry['case']} {setting}: exit {res.returncode}: "
                           f"{res.stderr.strip()[-300:]}")
    os.replace(os.path.join(tmp, "verdicts.csv"), os.path.join(d, "verdicts.csv"))
    shutil.rmtree(tmp)
    c = counts(os.path.join(d, "verdicts.csv"), os.path.join(entry["dir"], "candidates.csv"))
    m = SUMMARY.search(res.stdout)
    replay = dict(zip(("replay_tp", "replay_fp", "replay_tn", "replay_fn"), map(int, m.groups()))) if m else {}
    p, r = ratio(c["tp"], c["tp"] + c["fp"]), ratio(c["tp"], c["tp"] + c["fn"])
    row = {"family": entry["family"], "case": entry["case"], "split": entry["split"], "setting": setting, **values, **c,
           "precision": "" if p is None else round(p, 6), "recall": "" if r is None else round(r, 6), **replay,
           "counts_agree": int(bool(m) and all(c[k] == replay[f"replay_{k}"] for k in c)),
           "seconds": round(seconds, 3)}
    with open(done, "w") as f:
        json.dump(row, f)
    return row


def f3(v):
    return "-" if v is None else f"{v:.3f}"


def summary(rows, settings, spread_bound):
    """summary.md's text: pooled counts per family and setting, recall spread per case."""
    families = [fm for fm in FAMILIES if any(r["family"] == fm for r in rows)]
    out = ["## Pooled per family and setting (TP/FP/FN, P, R; P \"-\": nothing accepted)", "",
           "| family | cases | " + " | ".join(settings) + " | cases with recall spread > " + f"{spread_bound:g} |",
           "|---|---|" + "---|" * len(settings) + "---|"]
    recall = {}
    for r in rows:
        recall.setdefault((r["family"], r["case"]), {})[r["setting"]] = ratio(int(r["tp"]), int(r["tp"]) + int(r["fn"]))
    spreads = {}
    for key, rec in recall.items():
        vals = [rec[s] for s in settings if rec.get(s) is not None]
        spreads[key] = (max(vals) - min(vals)) if vals else None
    for fm in families:
        cells = []
        n = len({r["case"] for r in rows if r["family"] == fm})
        for s in settings:
            sel = [r for r in rows if r["family"] == fm and r["setting"] == s]
            tp, fp, fn = (sum(int(r[k]) for r in sel) for k in ("tp", "fp", "fn"))
            cells.append(f"{tp}/{fp}/{fn} P {f3(ratio(tp, tp + fp))} R {f3(ratio(tp, tp + fn))}")
        with_true = [k for k in spreads if k[0] == fm and spreads[k] is not None]
        above = [k for k in with_true if spreads[k] > spread_bound]
        out.append(f"| {fm} | {n} | " + " | ".join(cells) + f" | {len(above)} of {len(with_true)} |")
    out += ["", f"## Recall per case over the settings (spread = max - min; cases above {spread_bound:g})", "",
            "| family | case | " + " | ".join(settings) + " | false accepted | spread |",
            "|---|---|" + "---|" * len(settings) + "---|---|"]
    listed = sorted((k for k in spreads if spreads[k] is not None and spreads[k] > spread_bound),
                    key=lambda k: (-spreads[k], k))
    for fm, case in listed:
        fps = [int(r["fp"]) for s in settings for r in rows if (r["family"], r["case"], r["setting"]) == (fm, case, s)]
        out.append(f"| {fm} | {case} | " + " | ".join(f3(recall[fm, case].get(s)) for s in settings) +
                   f" | {min(fps)}..{max(fps)} | {spreads[fm, case]:.3f} |")
    no_true = sorted(f"{fm}/{c}" for (fm, c), v in spreads.items() if v is None)
    if no_true:
        out += ["", "No true loops (no recall): " + ", ".join(no_true)]
    largest_fp = sorted(((max(int(r["fp"]) for r in rows if (r["family"], r["case"]) == k) -
                          min(int(r["fp"]) for r in rows if (r["family"], r["case"]) == k), k) for k in spreads),
                        reverse=True)
    moved = [f"{fm}/{c} {d}" for d, (fm, c) in largest_fp if d > 0][:10]
    out += ["", "False loops accepted, largest change over the settings: " + (", ".join(moved) if moved else "none")]
    return "\n".join(out) + "\n"


def scenarios(a):
    """[{family, case, split, dir, flags}] of the split: each case's scenario as its family writes it."""
    entries = []
    names = set(a.only.split(",")) if a.only else None
    for family in a.families.split(","):
        module = programs.load(f"bench/{family}.py")
        for case in splits.cases(family, a.split, a.quick):
            if names and case.name not in names:
                continue
            _, d, prob, rover_args = module.setup(case, os.path.join(a.out, "scenarios", family))
            entries.append({"family": family, "case": case.name, "split": a.split, "dir": d,
                            "flags": [str(x) for x in methods.rover_flags(case.environment, prob, rover_args)]})
    return entries


def commit():
    """The clone's commit, or None where there is no git (a fresh machine, a tarball)."""
    try:
        out = subprocess.run(["git", "-C", bench.ROOT, "rev-parse", "HEAD"], capture_output=True, text=True)
    except OSError:
        return None
    return out.stdout.strip() or None


def build_files(replay):
    """rover_replay and the package's shared libraries it loads (the devel space's lib/, the
    directory above the binary's): the verifier lives in the core library, so a rebuilt core
    with an unchanged rover_replay is another build."""
    libdir = os.path.dirname(os.path.dirname(os.path.abspath(replay)))
    return [replay] + sorted(glob.glob(os.path.join(libdir, "librover_loop_fusion*.so")))


def resume_or_start_over(a):
    """Finished runs are kept only for the same build (build_files), YAMLs, split and --set:
    else OUT/runs is emptied (a rebuilt rover_replay or core library, or an edited YAML, starts
    over)."""
    digest = hashlib.sha256()
    for path in build_files(a.replay) + sorted(glob.glob(os.path.join(bench.ROOT, "config", "*.yaml"))):
        with open(path, "rb") as f:
            digest.update(f.read())
    key = {"inputs_sha256": digest.hexdigest(), "split": a.split, "set": a.set_flags}
    runs = os.path.join(a.out, "runs")
    path = os.path.join(runs, "key.json")
    if os.path.isdir(runs):
        try:
            with open(path) as f:
                same = json.load(f) == key
        except (OSError, ValueError):
            same = False
        if not same:
            print(f"{runs}: runs of another build, YAML or --set: starting over", flush=True)
            shutil.rmtree(runs)
    os.makedirs(runs, exist_ok=True)
    with open(path, "w") as f:
        json.dump(key, f)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", default="test", choices=splits.SPLITS)
    ap.add_argument("--families", default=",".join(FAMILIES))
    ap.add_argument("--only", help="case names (comma-separated)")
    ap.add_argument("--quick", action="store_true", help="only the CI subset of cases")
    ap.add_argument("--settings", default=",".join(SETTINGS), help=f"a subset of {','.join(SETTINGS)}")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a verifier parameter for every run (after the setting's), e.g. global_check=true")
    ap.add_argument("--spread", type=float, default=0.05, help="recall spread listed per case (target: 0.05)")
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "robustness"))
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args(argv)
    settings = a.settings.split(",")
    for s in settings:
        if s not in SETTINGS:
            ap.error(f"unknown setting {s}")
    for fm in a.families.split(","):
        if fm not in FAMILIES:
            ap.error(f"unknown family {fm}")
    a.set_flags = []
    for kv in a.set:
        key, sep, value = kv.partition("=")
        if not sep or not key:
            ap.error(f"--set {kv}: expected KEY=VALUE")
        if key in SCALED:
            ap.error(f"--set {key}: that is what the settings scale")
        a.set_flags += [f"--{key}", value]
    a.replay = bench.tool("rover_replay")
    os.makedirs(a.out, exist_ok=True)
    resume_or_start_over(a)
    entries = scenarios(a)
    if not entries:
        ap.error("no case selected")
    jobs = [(e, s, a) for e in sorted(entries, key=lambda e: e["family"] != "posegraph") for s in settings]
    print(f"{len(entries)} cases x {len(settings)} settings = {len(jobs)} sequential runs of rover_replay, "
          f"{a.jobs} at a time", flush=True)
    t0 = time.perf_counter()
    rows, errors = [], []
    with ThreadPoolExecutor(a.jobs) as ex:
        for i, fu in enumerate([ex.submit(run_one, j) for j in jobs], 1):
            try:
                rows.append(fu.result())
            except (RuntimeError, ValueError, OSError) as e:  # reported; the rest goes on
                errors.append(str(e))
                print(str(e), file=sys.stderr, flush=True)
            if i % 25 == 0 or i == len(jobs):
                print(f"  {i}/{len(jobs)} runs, {time.perf_counter() - t0:.0f} s", flush=True)
    order = {s: i for i, s in enumerate(SETTINGS)}
    rows.sort(key=lambda r: (FAMILIES.index(r["family"]), r["case"], order[r["setting"]]))
    with open(os.path.join(a.out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    disagree = [f"{r['family']}/{r['case']}/{r['setting']}" for r in rows if not r["counts_agree"]]
    text = (f"# Robustness: {a.split} split, sequential, settings {', '.join(settings)}"
            + (f"; --set {' '.join(a.set)}" if a.set else "") + "\n\n" + summary(rows, settings, a.spread))
    if disagree:
        text += "\nWARNING: counts differ from rover_replay's own line: " + ", ".join(disagree) + "\n"
    with open(os.path.join(a.out, "summary.md"), "w") as f:
        f.write(text)
    meta = {"split": a.split, "families": a.families, "settings": {s: SETTINGS[s] for s in settings}, "set": a.set,
            "commit": commit(), "runs": len(rows),
            "failed": errors, "counts_disagree_with_replay": disagree,
            "wall_seconds": round(time.perf_counter() - t0, 1)}
    with open(os.path.join(a.out, "meta.json"), "w") as f:
        json.dump(meta, f, indent=1)
    print(text)
    print(f"{len(rows)} runs into {a.out} in {meta['wall_seconds']} s; {len(errors)} failed")
    return 1 if errors or disagree else 0


if __name__ == "__main__":
    sys.exit(main())
