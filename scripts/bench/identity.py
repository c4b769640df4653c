#!/usr/bin/env python3
"""Verdict identity across a change that must not change decisions (a restructure, a speed-up):
rover_replay's verdicts on every case of every family (both splits) and on the shipped bags'
scenarios, in several configurations and protocols, written without their timing columns, so
that two builds can be compared file by file.

  ./scripts/bench.sh identity build  [--out results/identity] [--families poc,real,posegraph] [--jobs 2]
  ./scripts/bench.sh identity run    --tag NAME [--replay PATH/rover_replay] [--jobs 2]
  ./scripts/bench.sh identity compare NAME_A NAME_B

build    writes every case's scenario (the family's setup(): same candidates, same order) and a
         manifest (cases.json) once; scenarios do not depend on the C++ build. A case of both
         splits (the simulated scenes share ten names, with other seeds) gets one per split.
run      replays every scenario (a run interrupted goes on where it stopped) with one rover_replay build (default: the workspace's; another
         build's binary with its libraries beside it: --replay DIR/rover_replay, LD_LIBRARY_PATH
         DIR/lib), in every configuration of CONFIGS and both protocols (sequential, oracle),
         into out/NAME/<family>/<split>/<case>/<config>-<protocol>.csv (verdicts.csv without solve_ms,
         elapsed_ms, and the time in a detail text) and the trajectories' TUM files.
compare  counts the verdict rows and trajectory files that are identical between two runs and
         lists every difference; exit status 1 if anything differs.
"""
import argparse
import csv
import filecmp
import json
import os
import re
import shutil
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor

from roverlib import bench, methods, programs

poc, posegraph, real = (programs.load(f"bench/{f}.py") for f in ("poc", "posegraph", "real"))  # the families

FAMILIES = {"poc": poc, "real": real, "posegraph": posegraph}
SHIPPED = (("corridor", "indoor"), ("warehouse", "indoor"), ("euroc_mh05", "indoor"))
# Configurations beyond the shipped YAML: flags appended to the case's ROVER flags.
CONFIGS = {
    "shipped": [],
    "chi2": ["--decision", "chi2"],
    "revoke": ["--revoke_group", "3"],
    "full": ["--condense_min_window", "0"],  # not on the pose graphs: minutes per case
    "reloc": ["--confirm_without_prior", "true"],
    # the opt-in global pass: its outcome on ringCity moved by tens of loops across commits
    # that moved no other configuration's decision (docs/results.md)
    "global": ["--global_check", "true"],
}
PROTOCOLS = ("sequential", "oracle")
SKIP = {("full", "posegraph")}  # (config, family) pairs not run
TIMING = ("solve_ms", "elapsed_ms")
# Wall-clock figures inside detail texts ("... 12.3 ms ...").
TIME_IN_TEXT = re.compile(r"[0-9.]+ ?ms\b")


def build(a):
    os.makedirs(a.out, exist_ok=True)
    manifest = []
    from roverlib import splits
    for family in a.families.split(","):
        module = FAMILIES[family]
        for split in splits.SPLITS:
            for case in splits.cases(family, split, False):
                base = os.path.join(a.out, "scenarios", family, split)
                _, d, prob, rover_args = module.setup(case, base)
                manifest.append({"family": family, "case": case.name, "split": split, "dir": d,
                                 "flags": [str(x) for x in methods.rover_flags(case.environment, prob, rover_args)]})
                print(f"  {family}/{split}/{case.name}", flush=True)
    for name, env in SHIPPED:
        manifest.append({"family": "shipped", "case": name, "split": "-", "dir": os.path.join(bench.ROOT, "data", name),
                         "flags": bench.shipped(env, "--time_budget_ms", "0")})
    dirs = [e["dir"] for e in manifest]
    if len(set(dirs)) != len(dirs):  # one scenario written over another: a run would compare less
        raise SystemExit("identity build: two cases share a scenario directory")
    with open(os.path.join(a.out, "cases.json"), "w") as f:
        json.dump(manifest, f, indent=1)
    print(f"{len(manifest)} scenarios; manifest {os.path.join(a.out, 'cases.json')}")
    return 0


def strip(src, dst):
    with open(src, newline="") as f:
        rows = list(csv.DictReader(f))
    with open(dst, "w", newline="") as f:
        if not rows:
            return
        keys = [k for k in rows[0] if k not in TIMING]
        w = csv.DictWriter(f, fieldnames=keys, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            r["detail"] = TIME_IN_TEXT.sub("<t> ms", r.get("detail", ""))
            w.writerow(r)


def replay_one(job):
    entry, config, protocol, out, replay, libdir, config_dir = job
    d = os.path.join(out, entry["family"], entry["split"] if entry["split"] != "-" else "", entry["case"])
    os.makedirs(d, exist_ok=True)
    if os.path.exists(os.path.join(d, f"{config}-{protocol}.csv")):  # done by an interrupted run
        return None
    tmp = os.path.join(d, f".{config}-{protocol}")
    shutil.rmtree(tmp, ignore_errors=True)  # left by an interrupted run
    flags = list(entry["flags"])
    if config_dir:  # the YAMLs of another commit (a build that does not know today's keys)
        flags = [os.path.join(config_dir, os.path.basename(f)) if f.endswith(".yaml") else f for f in flags]
        # A commit before the template (full YAMLs, config/rover_template.yaml absent): its file alone.
        for i in range(len(flags) - 1, 0, -1):
            if flags[i - 1] == "--config" and not os.path.exists(flags[i]) and flags[i].endswith("rover_template.yaml"):
                del flags[i - 1:i + 1]
    cmd = [replay, "--scenario", entry["dir"], "--out", tmp, "--protocol", protocol, "--quiet"] + \
        flags + CONFIGS[config]
    env = dict(os.environ)
    if libdir:
        env["LD_LIBRARY_PATH"] = libdir
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if res.returncode != 0:
        return f"{entry['family']}/{entry['case']} {config}-{protocol}: exit {res.returncode}: {res.stderr.strip()[-300:]}"
    strip(os.path.join(tmp, "verdicts.csv"), os.path.join(d, f"{config}-{protocol}.csv"))
    for name in ("verified", "loop_fusion_verified"):
        src = os.path.join(tmp, f"{name}.tum")
        if os.path.exists(src):
            os.replace(src, os.path.join(d, f"{config}-{protocol}-{name}.tum"))
    shutil.rmtree(tmp)
    return None


def run(a):
    with open(os.path.join(a.out, "cases.json")) as f:
        manifest = json.load(f)
    replay = a.replay or bench.tool("rover_replay")
    libdir = a.lib or (os.path.join(os.path.dirname(replay), "lib") if a.replay else None)
    out = os.path.join(a.out, a.tag)
    configs = a.configs.split(",") if a.configs else list(CONFIGS)
    jobs = [(e, c, p, out, replay, libdir, a.config_dir) for e in manifest for c in configs for p in PROTOCOLS
            if (c, e["family"]) not in SKIP]
    errors = []
    with ProcessPoolExecutor(a.jobs) as ex:
        for i, err in enumerate(ex.map(replay_one, jobs), 1):
            if err:
                errors.append(err)
                print(err, file=sys.stderr)
            if i % 50 == 0:
                print(f"  {i}/{len(jobs)} runs", flush=True)
    print(f"{len(jobs)} runs into {out}; {len(errors)} failed")
    return 1 if errors else 0


def compare(a):
    da, db = os.path.join(a.out, a.names[0]), os.path.join(a.out, a.names[1])
    files = sorted({os.path.relpath(os.path.join(r, f), da) for r, _, fs in os.walk(da) for f in fs})
    other = sorted({os.path.relpath(os.path.join(r, f), db) for r, _, fs in os.walk(db) for f in fs})
    missing = sorted(set(files) ^ set(other))
    rows = same_rows = tum = same_tum = 0
    diffs = []
    for rel in sorted(set(files) & set(other)):
        pa, pb = os.path.join(da, rel), os.path.join(db, rel)
        if rel.endswith(".csv"):
            with open(pa) as f:
                ra = f.readlines()
            with open(pb) as f:
                rb = f.readlines()
            n = max(len(ra), len(rb)) - 1
            same = sum(x == y for x, y in zip(ra[1:], rb[1:]))
            rows += n
            same_rows += same
            if same != n or ra[:1] != rb[:1]:
                diffs.append(f"{rel}: {n - same} of {n} verdict rows differ")
        else:
            tum += 1
            if filecmp.cmp(pa, pb, shallow=False):
                same_tum += 1
            else:
                diffs.append(f"{rel}: trajectory differs")
    for d in diffs[:200]:
        print("  " + d)
    for m in missing[:50]:
        print(f"  only in one run: {m}")
    print(f"verdict rows identical: {same_rows} of {rows} ({len([f for f in files if f.endswith('.csv')])} files); "
          f"trajectories identical: {same_tum} of {tum}; files in one run only: {len(missing)}")
    return 0 if same_rows == rows and same_tum == tum and not missing else 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("command", choices=("build", "run", "compare"))
    ap.add_argument("names", nargs="*", help="compare: the two run tags")
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "identity"))
    ap.add_argument("--families", default="poc,real,posegraph")
    ap.add_argument("--tag", help="run: the name of this build's run")
    ap.add_argument("--replay", help="run: a rover_replay binary (default: the workspace's)")
    ap.add_argument("--lib", help="run: its libraries (default with --replay: DIR/lib beside it)")
    ap.add_argument("--configs", help=f"run: a subset of {','.join(CONFIGS)}")
    ap.add_argument("--config-dir", help="run: read the shipped YAMLs from this directory (e.g. those of the "
                    "commit a baseline build was made at: git show COMMIT:config/rover_indoor.yaml > DIR/...)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    a = ap.parse_args(argv)
    if a.command == "build":
        return build(a)
    if a.command == "run":
        if not a.tag:
            ap.error("run needs --tag")
        return run(a)
    if len(a.names) != 2:
        ap.error("compare needs two run tags")
    return compare(a)


if __name__ == "__main__":
    sys.exit(main())
