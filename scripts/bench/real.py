#!/usr/bin/env python3
"""Real drift: keyframes from real VIO/VO runs (../shared/data: EuRoC stereo and monocular VIO,
KITTI 09 visual odometry), labelled candidates from their ground truth (roverlib/real_data.py):
far-apart false candidates, and near look-alikes (1.5 m indoors, 3 m outdoors, sideways,
vertically or along the heading) in rows with a row before the first true loop. Tuning and
test sequences: roverlib/splits.py (never the same sequence on both sides).

  ./scripts/bench.sh real [--split test|tuning] [--quick] [--cases A,B] [--snapshots 10]
                          [--time-limit 600] [--decision metric|chi2|revisit] [--jobs 2]
                          [--out results/real]

Per case, on the same candidates in the same order (roverlib/methods.py):
  ROVER        rover_replay, sequential, at the environment's shipped YAML (EuRoC indoor 4-DoF,
               KITTI outdoor 6-DoF), time budget lifted (">200ms": share that would have failed
               closed); AP/MR of its score (gate off; protocols oracle and none, as the paper);
  accept-all   every candidate;
  PCM, IPC     incremental peers (roverlib/peers.py), covariances from the drift model;
  GNC, DCS     gtsam batch robust back ends, under --time-limit;
every selection solved with loop_fusion's back end (LF) and gtsam LM, each against its own
true-only solution; ATE and tATE SE(3)-aligned (roverlib/metrics.py).
Writes summary.csv (roverlib.bench.SUMMARY_COLUMNS), cases.csv, summary.md, pr_real.png,
real.png into --out."""
import functools
import os
import sys

from roverlib import bench, drift_model, methods, metrics, problem, scenario

SELECTIONS = ("rover", "pcm", "ipc", "gnc", "dcs")
CASE_COLUMNS = [("case", "case", ""), ("keyframes", "kf", "d"), ("true", "true", "d"), ("false", "false", "d"),
                ("threshold", "thr [m]", "g"), ("ap_oracle", "AP oracle", ".3f"), ("mr_oracle", "MR oracle", ".2f"),
                ("ap_none", "AP none", ".3f"), ("mr_none", "MR none", ".2f"), ("rover_reasons", "ROVER verdicts", ""),
                ("rover_over_200ms", ">200ms", ".2f"), ("pcm_reasons", "PCM", ""), ("ipc_reasons", "IPC", ""),
                ("limits", "time limit hit", "")]


def setup(case, out, decision=()):
    """poc.setup() for a real-drift case: (the Scenario, its directory out/scenarios/<case>, the Problem,
    ROVER's replay_args for methods.evaluate)."""
    s = case.build()
    d = os.path.join(out, "scenarios", case.name)
    scenario.write(s, d)
    prob = problem.from_scenario(s, drift_model.MODELS[s.meta["environment"]], s.meta["mode"])
    return s, d, prob, ["--alignment", s.meta["alignment"], *decision]


def run_case(job):
    case, out, snapshots, time_limit, decision = job
    s, d, prob, rover_args = setup(case, out, decision)
    mode, alignment, env = s.meta["mode"], s.meta["alignment"], s.meta["environment"]
    params = bench.defaults(env)
    row = {"threshold": params["threshold"]}
    curves = {}
    for p in ("oracle", "none"):
        run = bench.replay(d, os.path.join(out, "runs", case.name, p), p,
                           bench.shipped(env, "--mode", mode, "--alignment", alignment, "--time_budget_ms", 0,
                                         *bench.GATE_OFF))
        j = bench.labelled(run, os.path.join(d, "candidates.csv"))
        r = metrics.ranking_metrics(j["label"], j["score"])
        row[f"ap_{p}"], row[f"mr_{p}"] = r["ap"], r["mr"]
        curves[p] = r
    info, rows = methods.evaluate(case, d, prob, rover_args, out, snapshots=snapshots,
                                  time_limit=time_limit)
    row.update(info)
    print(f"  {case.name}: " + ", ".join(f"{r['method']} {r['tp']}/{r['fp']}/{r['fn']}" for r in rows
                                         if r["method"] in ("rover+lf", "pcm+lf", "ipc+lf", "gnc", "dcs")), flush=True)
    return row, rows, curves


def plot(rows, path):
    """Per case: ATE over the true-only ATE of the same back end, every method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    fig, axes = plt.subplots(1, 2, figsize=(max(10.0, 0.9 * len(rows) + 4), 4.6), dpi=100, sharey=True)
    x = np.arange(len(rows))
    for ax, backend in zip(axes, ("lf", "lm")):
        keys = [f"{m}+{backend}" for m in ("accept_all", "rover", "pcm", "ipc")] + \
            (["gnc", "dcs"] if backend == "lm" else [])
        w = 0.8 / len(keys)
        for k, key in enumerate(keys):
            ax.bar(x + (k - len(keys) / 2 + 0.5) * w, [r.get(f"{key}:ratio", np.nan) for r in rows], w,
                   label=methods.NAMES[key.split("+")[0]])
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_yscale("log")
        ax.set_xticks(x)
        ax.set_xticklabels([r["case"] for r in rows], rotation=40, ha="right", fontsize=7)
        ax.set_title("loop_fusion's back end" if backend == "lf" else "gtsam LM (drift model)", fontsize=9)
        ax.grid(alpha=0.3, axis="y", which="both")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("ATE / true-only ATE (same back end)")
    metrics.save_figure(fig, path)


def report(a, cases, results):
    summary = [x for _, rows, _ in results for x in rows]
    wide = methods.wide_rows([r for r, _, _ in results], summary)
    ind, outd = bench.defaults("indoor"), bench.defaults("outdoor")
    notes = [bench.decision_note(a),
             f"split: {a.split}{' (quick)' if a.quick else ''}; sequences and seeds: roverlib/splits.py",
             f"ROVER at the shipped defaults: EuRoC indoor {ind['threshold']:g} m, gate {ind['max_innovation']:g} m + "
             f"{ind['max_innovation_per_metre']:g} x path, 4-DoF; KITTI outdoor {outd['threshold']:g} m, gate "
             f"{outd['max_innovation']:g} m + {outd['max_innovation_per_metre']:g} x path, 6-DoF; time budget lifted",
             f"PCM, IPC, GNC, DCS and the LM back end: drift model {drift_model.INDOOR} / {drift_model.OUTDOOR}",
             f"time limit per baseline and case: {a.time_limit:g} s",
             "P '-': nothing accepted; TP/FP/FN of PCM: its final clique; ATE/tATE RMSE [m], SE(3)-aligned; "
             "batch methods (GNC, DCS) have no tATE"] + [f"{c.name}: {c.notes}" for c in cases]
    tables = [("Pooled over the cases", methods.pooled(summary), methods.POOLED_COLUMNS),
              ("Cases", wide, CASE_COLUMNS),
              ("Decisions", wide, methods.decision_columns(SELECTIONS)),
              ("ATE [m]", wide, methods.trajectory_columns(("accept_all",) + SELECTIONS, "ate")),
              ("tATE [m]", wide, methods.trajectory_columns(("accept_all",) + SELECTIONS, "tate"))]
    panels = [(r["case"], [(p, cv[p]) for p in ("oracle", "none") if cv[p]["recall"].size]) for r, _, cv in results]
    figures = [("pr_real.png", functools.partial(
                   metrics.plot_pr_grid, [p for p in panels if p[1]], ncols=4,
                   suptitle="Real drift: precision-recall of the ROVER score (positives: true loops)")),
               ("real.png", functools.partial(plot, wide))]
    return bench.FamilyReport(summary, tables, notes, {"cases.csv": wide}, figures)


def main(argv=None):
    return bench.run_family("real", __doc__, run_case, report, argv,
                            job=lambda c, a: (c, a.out, a.snapshots, a.time_limit, bench.decision_args(a)))


if __name__ == "__main__":
    sys.exit(main())
