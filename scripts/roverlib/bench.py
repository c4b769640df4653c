"""Shared plumbing of the benchmark scripts: running rover_replay, evaluating its output
directory, printing tables and writing CSV."""
import csv
import glob
import os
import subprocess
import sys

from . import metrics

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", ".."))  # the clone, not .ws/src
TOOLS = os.path.join(os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws")), "devel", "lib", "rover_loop_fusion")
RESULTS = os.path.join(ROOT, "results")
# rover_replay flags that switch the innovation gate off: the scoring protocols (oracle, none)
# rank candidates by the ROVER score alone, the paper's metric.
GATE_OFF = ["--max_innovation", 0, "--max_innovation_per_metre", 0]
DECISION_KEYS = ("threshold", "max_innovation", "max_innovation_per_metre")


def defaults(environment):
    """The decision parameters of config/rover_<environment>.yaml (indoor, outdoor) as a dict,
    so that the benchmarks decide exactly as the shipped configuration does."""
    import yaml
    with open(os.path.join(ROOT, "config", f"rover_{environment}.yaml")) as f:
        c = yaml.safe_load(f)
    return {k: float(c[k]) for k in DECISION_KEYS}


def decision_args(params):
    """rover_replay flags for a dict from defaults()."""
    return [x for k in DECISION_KEYS for x in (f"--{k}", params[k])]


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
    if isinstance(v, float):
        return "nan" if v != v else format(v, spec)
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


def report(rows, columns, title, out_dir, csv_name, notes=()):
    """What every family ends with: the table on stdout, rows as CSV, summary.md (title, notes
    as a list, the table) in out_dir."""
    print_table(rows, columns, title)
    write_csv(rows, os.path.join(out_dir, csv_name))
    with open(os.path.join(out_dir, "summary.md"), "w") as f:
        f.write(title + "\n\n" + "".join(f"- {n}\n" for n in notes) + ("\n" if notes else "") +
                markdown_table(rows, columns))


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
