#!/usr/bin/env python3
"""Cost side by side: rover_benchmark_cost of two builds of this package, run in turn on this
machine, every verdict compared (how a speed change is measured against its parent: in one
run, deciding as its parent did; docs/results.md, "Cost and memory").

  ./scripts/bench.sh cost_ab save DIR    keep the workspace's build (its libraries and
                                         rover_benchmark_cost) in DIR, e.g. before a change
  ./scripts/bench.sh cost_ab run --old DIR [--new DIR] [--rounds 3] [--out results/cost_ab]
                                 [-- rover_benchmark_cost options]

run: each round runs the old build, then the new one (default: the workspace's), each with its
own libraries (LD_LIBRARY_PATH=DIR/lib), on the same rows (default: --modes 4dof --sizes
20000,100000 --spans 10000,19000,99000 --queries 20 --full-repeats 1). Then:
  decisions  every verdict row of every run against the first old run's, the timing columns
             (*_ms) aside: identical, or the rows that differ (exit status 1)
  cost       per row (dof, keyframes, span): each run's summed verify_ms and its p50 and p99
             (nearest rank: p99 of fewer than 100 verifications is their largest), and the
             ratio of the new build's summed verify_ms to the old one's over all rounds
Writes runs/ (each run's verdicts and output), rows.csv and summary.md to --out. Run it on an
otherwise idle machine: the numbers are wall-clock times; the ratio is the result. Options that
read a file (--config YAML) must suit both builds: an older build refuses a key it does not know."""
import argparse
import csv
import glob
import math
import os
import shutil
import subprocess
import sys

from roverlib import bench

DEFAULT_ARGS = ["--modes", "4dof", "--sizes", "20000,100000", "--spans", "10000,19000,99000", "--queries", "20",
                "--full-repeats", "1"]
TOOL = "rover_benchmark_cost"


def save(directory):
    """Copies the workspace's rover_benchmark_cost and its libraries to DIR and DIR/lib."""
    lib = os.path.join(directory, "lib")
    os.makedirs(lib, exist_ok=True)
    tool = bench.tool(TOOL)
    shutil.copy2(tool, os.path.join(directory, TOOL))
    libs = glob.glob(os.path.join(os.path.dirname(os.path.dirname(tool)), "*.so*"))
    if not libs:
        sys.exit(f"no libraries beside {tool}")
    for f in libs:
        shutil.copy2(f, lib, follow_symlinks=False)
    print(f"saved {TOOL} and {len(libs)} libraries to {directory}")


def build_of(directory):
    """(binary, library directory) of a saved build, or of the workspace for None."""
    if directory is None:
        tool = bench.tool(TOOL)
        return tool, os.path.dirname(os.path.dirname(tool))
    tool = os.path.join(directory, TOOL)
    if not os.path.exists(tool):
        sys.exit(f"{tool} not found: keep a build with ./scripts/bench.sh cost_ab save {directory}")
    return tool, os.path.join(directory, "lib")


def run_once(build, args, verdicts, log):
    tool, lib = build
    env = dict(os.environ, LD_LIBRARY_PATH=lib + os.pathsep + os.environ.get("LD_LIBRARY_PATH", ""))
    with open(log, "w") as out:
        res = subprocess.run([tool] + args + ["--verdicts", verdicts], stdout=out, stderr=subprocess.STDOUT, env=env)
    if res.returncode != 0:
        sys.exit(f"{tool} failed ({res.returncode}): see {log}")
    with open(verdicts) as f:
        return list(csv.DictReader(f))


def decision_differences(reference, rows):
    """Indices of the verdict rows that differ from the reference's (timing columns aside; a
    different number of rows differs everywhere past the shorter)."""
    keys = [k for k in (reference[0] if reference else {}) if not k.endswith("_ms")]
    diff = [i for i, (a, b) in enumerate(zip(reference, rows)) if any(a[k] != b.get(k) for k in keys)]
    return diff + list(range(min(len(reference), len(rows)), max(len(reference), len(rows))))


def nearest_rank(values, p):
    v = sorted(values)
    return v[max(0, math.ceil(p * len(v)) - 1)] if v else float("nan")


def per_row(rows):
    """{(dof, keyframes, span): [verify_ms, ...]} in the order the rows first appear."""
    out = {}
    for r in rows:
        out.setdefault((r["dof"], r["keyframes"], r["span"]), []).append(float(r["verify_ms"]))
    return out


def summarise(runs):
    """runs: [(build "old"|"new", round, verdict rows)] -> table rows per (dof, keyframes, span)."""
    table = []
    keys = list(per_row(runs[0][2]))
    for key in keys:
        r = {"dof": key[0], "keyframes": key[1], "span": key[2]}
        sums = {"old": 0.0, "new": 0.0}
        for build, rnd, rows in runs:
            ms = per_row(rows).get(key, [])
            r[f"{build}{rnd}_sum_ms"] = sum(ms)
            r[f"{build}{rnd}_p50_ms"] = nearest_rank(ms, 0.5)
            r[f"{build}{rnd}_p99_ms"] = nearest_rank(ms, 0.99)
            sums[build] += sum(ms)
        r["ratio_new_over_old"] = sums["new"] / sums["old"] if sums["old"] > 0 else float("nan")
        table.append(r)
    return table


def run(a):
    args = a.args or DEFAULT_ARGS
    old, new = build_of(a.old), build_of(a.new)
    runs_dir = os.path.join(a.out, "runs")
    os.makedirs(runs_dir, exist_ok=True)
    runs = []
    for rnd in range(1, a.rounds + 1):
        for name, build in (("old", old), ("new", new)):
            base = os.path.join(runs_dir, f"{name}{rnd}")
            runs.append((name, rnd, run_once(build, args, base + ".csv", base + ".txt")))
            print(f"round {rnd}: {name} done", flush=True)
    reference = runs[0][2]
    differing = {f"{b}{r}": decision_differences(reference, rows) for b, r, rows in runs}
    table = summarise(runs)
    columns = list(table[0]) if table else []
    with open(os.path.join(a.out, "rows.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(table)
    lines = [f"# Cost side by side: {a.old} (old) against {a.new or 'the workspace'} (new)", "",
             f"rover_benchmark_cost {' '.join(args)}; {a.rounds} round(s), old then new in each.", ""]
    bad = {k: v for k, v in differing.items() if v}
    lines.append("Decisions: " + ("every verdict row identical to old1's, timing aside." if not bad else
                                  "DIFFER: " + "; ".join(f"{k}: {len(v)} rows (first {v[:5]})" for k, v in bad.items())))
    lines += ["", "| dof | keyframes | span | summed verify_ms old | new | new / old | p50 old | new | p99 old | new |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    rounds = range(1, a.rounds + 1)
    for r in table:
        def cells(what, build):
            return " ".join(f"{r[f'{build}{i}_{what}_ms']:.{1 if what == 'sum' else 3}f}" for i in rounds)
        lines.append(f"| {r['dof']} | {r['keyframes']} | {r['span']} | {cells('sum', 'old')} | {cells('sum', 'new')} | "
                     f"{r['ratio_new_over_old']:.3f} | {cells('p50', 'old')} | {cells('p50', 'new')} | "
                     f"{cells('p99', 'old')} | {cells('p99', 'new')} |")
    text = "\n".join(lines) + "\n"
    with open(os.path.join(a.out, "summary.md"), "w") as f:
        f.write(text)
    print(text)
    return 1 if bad else 0


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    s = sub.add_parser("save", help="keep the workspace's build in DIR")
    s.add_argument("dir")
    r = sub.add_parser("run", help="both builds in turn, verdicts compared, cost side by side")
    r.add_argument("--old", required=True, help="a build kept with save")
    r.add_argument("--new", help="another kept build (default: the workspace's)")
    r.add_argument("--rounds", type=int, default=3)
    r.add_argument("--out", default=os.path.join(bench.ROOT, "results", "cost_ab"))
    a = ap.parse_args(argv)
    if a.command == "save":
        save(a.dir)
        return 0
    if a.rounds < 1:
        ap.error("--rounds must be at least 1")
    a.args = extra
    return run(a)


if __name__ == "__main__":
    sys.exit(main())
