#!/usr/bin/env python3
"""Pose graphs with injected outliers (../shared/data/posegraphs): the verifier, sequentially,
next to the incremental peers and the batch robust back ends a user would pick instead, on the
same graphs, candidates and order. Tuning and test graphs: roverlib/splits.py (tuning
manhattan3500, ring; test ringCity, kitti_00, parking-garage).

  ./scripts/bench.sh posegraph [--split test|tuning] [--quick] [--cases A,B] [--max-loops N]
                               [--snapshots 10] [--time-limit 600] [--decision metric|chi2|revisit] [--jobs 2]
                               [--out results/posegraph]

Per case (graph, outlier kind, fraction; roverlib/g2o.py says how each kind is made, seeds fixed):
the odometry chain is the "VIO", the file's loops (a fixed-seed subsample: at most 200, 100 on
parking-garage) the true candidates, the injected outliers the false ones, in the order of the
later vertex. Methods (roverlib/methods.py): ROVER (rover_replay at config/rover_outdoor.yaml,
4-DoF for the 2D graphs, 6-DoF for parking-garage; time budget and loop_fusion's |yaw| < 30 deg
limit lifted: these files' loops come from any direction), accept-all, PCM and IPC
(roverlib/peers.py), GNC and DCS (gtsam), every method with the files' information matrices;
each selection solved with loop_fusion's back end (LF) and gtsam LM, each against its own
true-only solution. Reference: ground truth; parking-garage has none: gtsam LM with every loop
of the file. --quick (CI): two ringCity cases with 40 true loops.
Writes summary.csv (roverlib.bench.SUMMARY_COLUMNS), cases.csv, summary.md and one PNG per
graph into --out."""
import functools
import os
import sys

import numpy as np

from roverlib import bench, g2o, methods, metrics, problem, robust, scenario

SELECTIONS = ("rover", "pcm", "ipc", "gnc", "dcs")
MAX_LOOPS = {"parking-garage": 100}  # others: 200
QUICK_MAX_LOOPS = 40  # --quick (CI), every graph
# the costliest graphs first, so that no worker is left alone with them at the end
COST_ORDER = {"kitti_00": 0, "parking-garage": 1, "manhattan3500": 2, "ringCity": 3, "ring": 4}
CASE_COLUMNS = [("case", "case", ""), ("true", "true", "d"), ("false", "false", "d"),
                ("rover_reasons", "ROVER verdicts", ""), ("rover+lf:verify_ms_p50", "ROVER ms p50", ".1f"),
                ("rover+lf:verify_ms_p99", "p99", ".1f"), ("rover_over_200ms", ">200ms", ".2f"),
                ("pcm_reasons", "PCM", ""), ("ipc_reasons", "IPC", ""), ("gnc_seconds", "GNC s", ".0f"),
                ("limits", "time limit hit", "")]
_GRAPHS = {}


def graph_and_truth(name):
    """(graph, reference poses, what the reference is), once per process."""
    if name not in _GRAPHS:
        graph = g2o.load(name)
        gt = g2o.groundtruth(name, graph.n)
        source = "ground truth"
        if gt is None:
            every = problem.from_g2o(graph, [(e, 1) for e in graph.loops])
            gt, source = robust.solve_lm(every, every.loops), "gtsam LM with every loop of the file"
        _GRAPHS[name] = (graph, gt, source)
    return _GRAPHS[name]


def setup(case, out, decision=(), max_loops=None):
    """poc.setup() for a pose-graph case, at most max_loops true loops (default MAX_LOOPS): (the
    Scenario, its directory out/scenarios/<case>, the Problem, ROVER's replay_args for
    methods.evaluate)."""
    k = case.kwargs
    graph, truth, _ = graph_and_truth(k["graph"])
    true_loops = g2o.subsample_loops(graph, max_loops or MAX_LOOPS.get(k["graph"], 200), seed=k["seed"])
    outliers = g2o.inject_outliers(graph, len(true_loops), k["kind"], k["fraction"], truth, seed=k["seed"],
                                   first_true_query=min(e.query for e in true_loops))
    d = os.path.join(out, "scenarios", case.name)
    s = g2o.to_scenario(graph, true_loops, outliers, truth, seed=k["seed"],
                        meta={"outliers": k["kind"], "fraction": k["fraction"]})
    scenario.write(s, d)
    prob = problem.from_g2o(graph, g2o.ordered_candidates(true_loops, outliers, k["seed"]), truth)
    return s, d, prob, ["--max_relative_yaw_deg", 180, *decision]


def run_case(job):
    case, out, snapshots, time_limit, max_loops, decision = job
    k = case.kwargs
    _, d, prob, rover_args = setup(case, out, decision, max_loops)
    info, rows = methods.evaluate(case, d, prob, rover_args, out, snapshots=snapshots, time_limit=time_limit)
    info.update(graph=k["graph"], kind=k["kind"], pct=int(round(100 * k["fraction"])))
    print(f"  {case.name}: " + ", ".join(f"{r['method']} {r['tp']}/{r['fp']}/{r['fn']}" for r in rows
                                         if r["method"] in ("rover+lf", "pcm+lf", "ipc+lf", "gnc", "dcs")), flush=True)
    return info, rows


def plot(rows, name, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in rows if r["graph"] == name]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(max(9.0, 0.9 * len(rows) + 5), 4.4), dpi=100,
                                 gridspec_kw={"width_ratios": [2, 1]})
    x = np.arange(len(rows))
    keys = ["accept_all+lm", "rover+lf", "rover+lm", "pcm+lm", "ipc+lm", "gnc", "dcs"]
    w = 0.8 / len(keys)
    for j, key in enumerate(keys):
        sel, _, backend = key.partition("+")
        lab = methods.NAMES[sel] + (f" ({backend.upper()})" if backend else "")
        ax.bar(x + (j - len(keys) / 2 + 0.5) * w, [r.get(f"{key}:ratio", np.nan) for r in rows], w, label=lab)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.set_yscale("log")
    ax.set_xticks(x)
    ax.set_xticklabels([f"{r['kind']}\n{r['pct']}%" for r in rows], fontsize=7)
    ax.set_ylabel("ATE / true-only ATE (same back end)")
    ax.set_title(f"{name}: final ATE", fontsize=9)
    ax.grid(alpha=0.3, axis="y", which="both")
    ax.legend(fontsize=6, ncol=2)
    for sel, m in (("rover", "o"), ("pcm", "v"), ("ipc", "D"), ("gnc", "s"), ("dcs", "^")):
        key = sel if sel in ("gnc", "dcs") else sel + "+lf"
        bx.scatter([r.get(f"{key}:recall", np.nan) for r in rows], [r.get(f"{key}:precision", np.nan) for r in rows],
                   marker=m, label=methods.NAMES[sel])
    bx.set_xlabel("loop recall")
    bx.set_ylabel("loop precision (no point: nothing accepted)")
    bx.set_xlim(-0.02, 1.02)
    bx.set_ylim(-0.02, 1.05)
    bx.grid(alpha=0.3)
    bx.legend(fontsize=7)
    bx.set_title("decisions, every case", fontsize=9)
    metrics.save_figure(fig, path)


def loops_per_graph(a):
    """True loops per graph: --max-loops, else 40 with --quick, else None (MAX_LOOPS per graph)."""
    return a.max_loops or (QUICK_MAX_LOOPS if a.quick else None)


def report(a, cases, results):
    summary = [x for _, rows in results for x in rows]
    wide = methods.wide_rows([r for r, _ in results], summary)
    params = bench.defaults("outdoor")
    graphs = list(dict.fromkeys(c.kwargs["graph"] for c in cases))
    n = loops_per_graph(a)
    notes = [bench.decision_note(a),
             f"split: {a.split}{' (quick)' if a.quick else ''}; graphs, kinds, fractions, seeds: roverlib/splits.py",
             f"ROVER at config/rover_outdoor.yaml: {params['threshold']:g} m, gate {params['max_innovation']:g} m + "
             f"{params['max_innovation_per_metre']:g} x path; time budget and |yaw| limit lifted",
             f"true loops per graph: at most {n or 200} ({n or MAX_LOOPS['parking-garage']} on "
             "parking-garage), fixed-seed subsample; every method uses the files' information matrices",
             f"time limit per baseline and case: {a.time_limit:g} s",
             "P '-': nothing accepted; TP/FP/FN of PCM: its final clique; ATE/tATE RMSE [m], SE(3)-aligned; "
             "batch methods (GNC, DCS) have no tATE"] + \
        [f"{g}: {graph_and_truth(g)[0].n} vertices, reference: {graph_and_truth(g)[2]}" for g in graphs]
    tables = [("Pooled over the cases", methods.pooled(summary), methods.POOLED_COLUMNS),
              ("Cases", wide, CASE_COLUMNS),
              ("Decisions", wide, methods.decision_columns(SELECTIONS)),
              ("ATE [m]", wide, methods.trajectory_columns(("accept_all",) + SELECTIONS, "ate")),
              ("tATE [m]", wide, methods.trajectory_columns(("accept_all",) + SELECTIONS, "tate"))]
    figures = [(f"{g}.png", functools.partial(plot, wide, g)) for g in graphs]
    return bench.FamilyReport(summary, tables, notes, {"cases.csv": wide}, figures)


def main(argv=None):
    def arguments(ap):
        ap.add_argument("--max-loops", type=int, help="true loops per graph (default 200, parking-garage 100; --quick 40)")
    return bench.run_family("posegraph", __doc__, run_case, report, argv, arguments=arguments,
                            job=lambda c, a: (c, a.out, a.snapshots, a.time_limit, loops_per_graph(a),
                                              bench.decision_args(a)),
                            order=lambda c: COST_ORDER.get(c.kwargs["graph"], 5))


if __name__ == "__main__":
    sys.exit(main())
