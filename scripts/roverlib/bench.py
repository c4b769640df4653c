"""Shared plumbing of the benchmark scripts: the main() every family runs (run_family: the
command line every family shares, its cases in a process pool, its tables, summary.md and the
one machine-readable summary per family, results/<family>/summary.csv), running rover_replay,
evaluating its output directory, time-limited baselines, printing tables and writing CSV."""
import argparse
import collections
import csv
import dataclasses
import glob
import os
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor

from . import config, metrics

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", ".."))  # the clone, not .ws/src
TOOLS = os.path.join(os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws")), "devel", "lib", "rover_loop_fusion")
RESULTS = os.path.join(ROOT, "results")
# rover_replay flags that switch the innovation gate off: the scoring protocols (oracle, none)
# rank candidates by the ROVER score alone, the paper's metric.
GATE_OFF = ["--max_innovation", 0, "--max_innovation_per_metre", 0]
DECISION_KEYS = ("threshold", "max_innovation", "max_innovation_per_metre")


# results/<family>/summary.csv: one row per case x method. Other tools read it: keep the names.
SUMMARY_COLUMNS = ("family", "split", "case", "method", "tp", "fp", "fn", "precision", "recall", "ate",
                   "ate_true_only", "tate", "verify_ms_p50", "verify_ms_p99")


def family_arguments(ap, family, jobs=True):
    """The options every family shares (README/docs: `./scripts/bench.sh FAMILY --help`)."""
    ap.add_argument("--split", choices=("test", "tuning"), default="test",
                    help="which cases (roverlib/splits.py): the docs report test; choose defaults on tuning")
    ap.add_argument("--quick", action="store_true", help="the CI subset of the split")
    ap.add_argument("--cases", help="only these case names (comma-separated)")
    ap.add_argument("--out", default=os.path.join(RESULTS, family))
    ap.add_argument("--decision", choices=("metric", "chi2", "revisit"),
                    help="ROVER's decision mode instead of the shipped YAML's (rover_replay --decision after "
                         "--config; 6-DoF cases too: chi2 then tests x, y, z and yaw)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a verifier parameter for ROVER's sequential run, after the YAML and --decision "
                         "(rover_replay --KEY VALUE; e.g. revoke_group=3); repeatable")
    ap.add_argument("--time-limit", type=float, default=600.0,
                    help="seconds per baseline (GNC, DCS, PCM, IPC) and case; a run that hits it is reported")
    ap.add_argument("--snapshots", type=int, default=10, help="K of the temporal ATE")
    if jobs:
        ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)


@dataclasses.dataclass
class FamilyReport:
    """What a family's report() hands to run_family: the rows of summary.csv (SUMMARY_COLUMNS),
    the tables of summary.md [(title, rows, columns)], printed too, the notes above them, more CSV
    files {file name: rows} and figures [(file name, draw(path))]."""
    summary: list
    tables: list
    notes: list = dataclasses.field(default_factory=list)
    csvs: dict = dataclasses.field(default_factory=dict)
    figures: list = dataclasses.field(default_factory=list)


def run_family(family, doc, run_case, report, argv=None, *, arguments=None, cases=None, job=None, order=None,
               shared_options=True):
    """The main() of a benchmark family (scripts/bench/<family>.py); the family brings its parts:
      arguments(ap)              its own options, after the shared ones (family_arguments; with
                                 shared_options=False only --out)
      cases(a)                   what to run (default: select_cases(family, a))
      job(case, a)               run_case's argument for one case (default: the case), built here
                                 before anything runs, so that a bad option stops the run first
      run_case(job)              one case: in a pool of --jobs worker processes, or in this
                                 process one after the other where the family has no --jobs
      order(case)                sort key: which cases go to the pool first (default: as listed)
      report(a, cases, results)  -> FamilyReport, results in the order of the cases
    Then writes into --out: summary.csv, the report's CSV files, summary.md (its tables, printed
    too) and its figures, and prints what it wrote. Returns 0 (main()'s exit status)."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    if shared_options:
        family_arguments(ap, family)
    else:
        ap.add_argument("--out", default=os.path.join(RESULTS, family))
    if arguments:
        arguments(ap)
    a = ap.parse_args(argv)
    chosen = cases(a) if cases else select_cases(family, a)
    jobs = [job(c, a) if job else c for c in chosen]
    os.makedirs(a.out, exist_ok=True)
    first = sorted(range(len(chosen)), key=lambda i: order(chosen[i])) if order else list(range(len(chosen)))
    if getattr(a, "jobs", None):
        with ProcessPoolExecutor(max_workers=a.jobs) as pool:
            done = dict(zip(first, pool.map(run_case, [jobs[i] for i in first])))
    else:
        done = {i: run_case(jobs[i]) for i in first}
    r = report(a, chosen, [done[i] for i in range(len(chosen))])
    write_summary(r.summary, os.path.join(a.out, "summary.csv"))
    for name, rows in r.csvs.items():
        write_csv(rows, os.path.join(a.out, name))
    report_tables(r.tables, a.out, r.notes)
    for name, draw in r.figures:
        draw(os.path.join(a.out, name))
    print(f"wrote {a.out}/" + ", ".join(["summary.csv", *r.csvs, "summary.md", *(n for n, _ in r.figures)]))
    return 0


def select_cases(family, a):
    """The cases of the family's --split (--quick: its CI subset, with 40 + 40 candidates where
    the family draws candidates), filtered by --cases."""
    import dataclasses
    from . import splits
    chosen = splits.cases(family, a.split, a.quick)
    if a.quick and family in ("poc", "real"):
        chosen = [dataclasses.replace(c, args=tuple(sorted({**c.kwargs, "n_true": 40, "n_false": 40}.items())))
                  for c in chosen]
    if a.cases:
        names = set(a.cases.split(","))
        chosen = [c for c in chosen if c.name in names]
        if not chosen:
            sys.exit(f"no {a.split} case of {family} is named {a.cases}")
    return chosen


def decision_args(a):
    """The rover_replay flags of --decision and --set for ROVER's sequential run (none: the YAML's)."""
    args = ["--decision", a.decision] if a.decision else []
    for o in getattr(a, "overrides", []):
        key, sep, value = o.partition("=")
        if not sep or not key:
            sys.exit(f"--set {o}: expected KEY=VALUE")
        args += [f"--{key}", value]
    return args


def decision_note(a):
    """The summary.md note that says which decision mode (and --set parameters) ROVER ran with."""
    note = f"ROVER decision: {a.decision} (--decision)" if a.decision else "ROVER decision: the YAML's (decision:)"
    overrides = getattr(a, "overrides", [])
    return note + (f"; --set {' '.join(overrides)}" if overrides else "")


def run_limited(fn, args=(), limit_s=600.0):
    """fn(*args) in a forked child, killed after limit_s seconds: (result or None, seconds,
    limit hit). For the batch baselines, whose solvers cannot be stopped from outside."""
    import multiprocessing as mp
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)

    def child():
        try:
            send.send(("ok", fn(*args)))
        except Exception as e:  # reported by the parent
            send.send(("error", repr(e)))

    t0 = time.perf_counter()
    p = ctx.Process(target=child)
    p.start()
    send.close()
    got = recv.poll(limit_s)
    if not got:
        p.kill()
        p.join()
        return None, time.perf_counter() - t0, True
    status, value = recv.recv()
    p.join()
    if status != "ok":
        raise RuntimeError(f"{getattr(fn, '__name__', fn)} failed: {value}")
    return value, time.perf_counter() - t0, False


def reason_counts(reasons):
    """'accepted 40, innovation_above_bound 58, ...' (most frequent first)."""
    return ", ".join(f"{k} {v}" for k, v in collections.Counter(reasons).most_common())


def percentile(values, q):
    """The q-th percentile (numpy's linear interpolation) of the finite values; NaN if none."""
    import numpy as np
    v = np.asarray([x for x in values if x == x], dtype=float)
    return float(np.percentile(v, q)) if v.size else float("nan")


def write_summary(rows, path):
    """results/<family>/summary.csv with exactly SUMMARY_COLUMNS (NaN written empty)."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(SUMMARY_COLUMNS)
        for r in rows:
            w.writerow(["" if (isinstance(r.get(k), float) and r[k] != r[k]) or r.get(k) is None else
                        (f"{r[k]:.6g}" if isinstance(r[k], float) else r[k]) for k in SUMMARY_COLUMNS])


def shipped_config(environment):
    """Every parameter `environment` ships with (config/rover_template.yaml, then
    config/rover_<environment>.yaml: roverlib/config.py) as a dict."""
    return config.effective(environment)


def defaults(environment):
    """The decision parameters of `environment` as a dict, for tables and titles (the runs
    themselves read the files: shipped())."""
    c = shipped_config(environment)
    return {k: float(c[k]) for k in DECISION_KEYS}


def config_paths(environment):
    """The files `environment` loads, in order: the template, then its override."""
    return config.files(environment)


def shipped(environment, *overrides):
    """rover_replay flags that run the shipped configuration of `environment` (--config
    TEMPLATE --config OVERRIDE), then `overrides` (later flags win). With --decision chi2 or
    revisit among them, the override's opt-in keys for those decisions come first."""
    return config.replay_args(environment) + config.opt_in_args(environment, overrides) + list(overrides)


def tool(name):
    path = os.path.join(TOOLS, name)
    if not os.path.exists(path):
        sys.exit(f"{path} not found: build first (./scripts/bench.sh or ./scripts/test.sh do)")
    return path


def replay(scenario_dir, out_dir, protocol="sequential", args=(), snapshots=0):
    """Runs rover_replay; returns out_dir. Raises CalledProcessError with its stderr."""
    cmd = [tool("rover_replay"), "--scenario", scenario_dir, "--out", out_dir, "--protocol", protocol,
           "--quiet"] + [str(a) for a in args]
    if snapshots:
        cmd += ["--snapshots", str(snapshots)]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise subprocess.CalledProcessError(res.returncode, cmd, res.stdout, res.stderr)
    return out_dir


def intake(run_dir):
    """[(keyframe index, kept)] of a replay directory, in keyframes.csv's order: its intake.csv,
    what rover_replay's addKeyframe() kept or refused (docs/scenario-format.md)."""
    path = os.path.join(run_dir, "intake.csv")
    if not os.path.exists(path):
        raise FileNotFoundError(f"{path} missing: a rover_replay that writes intake.csv (rebuild the workspace)")
    with open(path, newline="") as f:
        return [(int(r["index"]), r["kept"] == "1") for r in csv.DictReader(f)]


def labelled(run_dir, labels_path):
    """metrics.join of a replay directory's verdicts with a scenario's labels."""
    return metrics.join(metrics.read_verdicts(os.path.join(run_dir, "verdicts.csv")),
                        metrics.read_labels(labels_path))


def trajectory_errors(run_dir, align="se3", names=("odometry", "loop_fusion_accept_all", "loop_fusion_verified",
                                                   "verified")):
    """{name: (ATE, tATE)} of a replay directory's trajectories against its groundtruth.tum;
    tATE only where --snapshots were written (NaN otherwise)."""
    gt = metrics.read_tum(os.path.join(run_dir, "groundtruth.tum"))
    snaps_dir = os.path.join(run_dir, "snapshots")
    k = len(glob.glob(os.path.join(snaps_dir, "verified_*.tum")))
    out = {}
    for name in names:
        path = os.path.join(run_dir, f"{name}.tum")
        if not os.path.exists(path):
            continue
        value = metrics.ate(gt, path, align)
        if not k:
            t = float("nan")
        elif name == "odometry":
            t = metrics.temporal_ate(gt, metrics.prefixes(path, k), align)
        else:
            t = metrics.temporal_ate(gt, [os.path.join(snaps_dir, f"{name}_{i}.tum") for i in range(1, k + 1)], align)
        out[name] = (value, t)
    return out


def fmt(v, spec):
    """A table cell: NaN (undefined: precision of no decision, a metric a method has not) is "-"."""
    if isinstance(v, float):
        return "-" if v != v else format(v, spec)
    return str(v)


def print_table(rows, columns, title=None, file=None):
    """columns: [(key, header, format spec)]; right-aligned plain-text table (stdout by default)."""
    file = file or sys.stdout
    cells = [[h for _, h, _ in columns]] + [[fmt(r.get(k, ""), s) for k, _, s in columns] for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(len(columns))]
    if title:
        print(title, file=file)
    for j, c in enumerate(cells):
        print("  ".join(x.rjust(w) if i else x.ljust(w) for i, (x, w) in enumerate(zip(c, widths))), file=file)
        if j == 0:
            print("  ".join("-" * w for w in widths), file=file)
    file.flush()


def report_tables(sections, out_dir, notes=()):
    """Several tables [(title, rows, columns)]: printed, and written to out_dir/summary.md."""
    with open(os.path.join(out_dir, "summary.md"), "w") as f:
        f.write("".join(f"- {n}\n" for n in notes) + ("\n" if notes else ""))
        for title, rows, columns in sections:
            print_table(rows, columns, title)
            print()
            f.write(f"### {title}\n\n" + markdown_table(rows, columns) + "\n")


def markdown_table(rows, columns):
    out = ["| " + " | ".join(h for _, h, _ in columns) + " |", "|" + "---|" * len(columns)]
    out += ["| " + " | ".join(fmt(r.get(k, ""), s) for k, _, s in columns) + " |" for r in rows]
    return "\n".join(out) + "\n"


def write_csv(rows, path):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
