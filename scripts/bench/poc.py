#!/usr/bin/env python3
"""Simulated scenes: the paper's proof of concept (Room, Sports ground, Warehouse at odometry
noise sigma 0.01 .. 0.175) and the hard cases (near look-alikes laterally, vertically and along
the track, rows of them, a row before the first true loop, sigma up to 0.35, many laps, city
laps with the first loop after 1-2 km, a scene without true loops); roverlib/splits.py lists
them, tuning and test.

  ./scripts/bench.sh poc [--split test|tuning] [--quick] [--cases A,B] [--snapshots 10]
                         [--decision metric|chi2|revisit] [--time-limit 600] [--jobs 2]
                         [--out results/poc]

Per case (rover_replay, the trial solve's wall-clock time budget lifted: ">200ms" is the share
of verifications that took longer and would have failed closed):
  AP, MR       the ROVER score as a ranking (innovation gate off: the paper's metric), from two
               scoring protocols: oracle (only true loops committed) and none (nothing
               committed, the paper's PoC setting);
  decisions    the product: sequential, at config/rover_<environment>.yaml (threshold and
               innovation gate): TP/FP/FN, precision ("-": nothing accepted), recall, counts per
               verdict reason; accept-all and the peers beside it on the same candidates in the
               same order (PCM, IPC incremental; GNC, DCS gtsam batch, under --time-limit;
               covariances from the drift model, roverlib/methods.py);
  trajectories ATE and tATE (evo, SE(3)) with loop_fusion's back end (lf) and gtsam LM with the
               indoor/outdoor drift model (roverlib/drift_model.py), each next to the true-only
               solution of the same back end (roverlib/methods.py).
Writes summary.csv (one row per case x method, roverlib.bench.SUMMARY_COLUMNS), cases.csv,
summary.md, pr_oracle.png, pr_none.png, poc.png into --out."""
import functools
import os
import sys

from roverlib import bench, drift_model, methods, metrics, problem, scenario

SELECTIONS = ("rover", "pcm", "ipc", "gnc", "dcs")

CASE_COLUMNS = [("case", "case", ""), ("environment", "env", ""), ("keyframes", "kf", "d"), ("true", "true", "d"),
                ("false", "false", "d"), ("ap_oracle", "AP oracle", ".3f"), ("mr_oracle", "MR oracle", ".2f"),
                ("ap_none", "AP none", ".3f"), ("mr_none", "MR none", ".2f"),
                ("rover_tp", "TP", "d"), ("rover_fp", "FP", "d"), ("rover_fn", "FN", "d"),
                ("rover_precision", "P", ".3f"), ("rover_recall", "R", ".3f"), ("rover_reasons", "verdicts", ""),
                ("rover_over_200ms", ">200ms", ".2f")]
TRAJ_COLUMNS = [("case", "case", ""), ("ate_odometry", "odometry", ".2f"),
                ("ate_true_only_lf", "LF true-only", ".2f"), ("ate_accept_all+lf", "LF accept-all", ".2f"),
                ("ate_rover+lf", "LF ROVER", ".2f"), ("tate_rover+lf", "LF ROVER tATE", ".2f"),
                ("ate_true_only_lm", "LM true-only", ".2f"), ("ate_accept_all+lm", "LM accept-all", ".2f"),
                ("ate_rover+lm", "LM ROVER", ".2f"), ("tate_rover+lm", "LM ROVER tATE", ".2f")]


def setup(case, out, decision=()):
    """The case's scenario, written to out/scenarios/<case>: (the Scenario, its directory, the
    Problem, ROVER's rover_replay flags after the shipped YAML and mode: methods.evaluate's
    replay_args). bench/agreement.py builds its cases with it too."""
    s = case.build()
    d = os.path.join(out, "scenarios", case.name)
    scenario.write(s, d)
    return s, d, problem.from_scenario(s, drift_model.MODELS[case.environment], "4dof"), list(decision)


def run_case(job):
    case, out, snapshots, time_limit, decision = job
    _, d, prob, rover_args = setup(case, out, decision)
    labels = os.path.join(d, "candidates.csv")
    curves = {}
    row = {"environment": case.environment}
    for p in ("oracle", "none"):
        run = bench.replay(d, os.path.join(out, "runs", case.name, p), p,
                           bench.shipped(case.environment, "--mode", "4dof", "--time_budget_ms", 0, *bench.GATE_OFF))
        j = bench.labelled(run, labels)
        r = metrics.ranking_metrics(j["label"], j["score"])
        row[f"ap_{p}"], row[f"mr_{p}"] = r["ap"], r["mr"]
        curves[p] = r
    info, rows = methods.evaluate(case, d, prob, rover_args, out, snapshots=snapshots, time_limit=time_limit)
    row.update(info)
    for r in rows:
        if r["method"].startswith("rover"):
            row.update({f"rover_{k}": r[k] for k in ("tp", "fp", "fn", "precision", "recall")})
        row[f"ate_{r['method']}"], row[f"tate_{r['method']}"] = r["ate"], r["tate"]
    row["ate_odometry"] = row.pop("ate_odometry", float("nan"))
    print(f"  {case.name}: " + ", ".join(f"{r['method']} {r['tp']}/{r['fp']}/{r['fn']}" for r in rows
                                         if r["method"] in ("rover+lf", "pcm+lf", "ipc+lf", "gnc", "dcs")), flush=True)
    return row, rows, curves


def plot(rows, path):
    """Per case: ROVER's precision and recall, and its ATE over the true-only ATE per back end."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    fig, (ax, bx) = plt.subplots(2, 1, figsize=(max(8.0, 0.45 * len(rows) + 2), 7.0), dpi=100, sharex=True)
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["rover_precision"] for r in rows], 0.4, label="precision (no bar: nothing accepted)")
    ax.bar(x + 0.2, [r["rover_recall"] for r in rows], 0.4, label="recall")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("ROVER decisions")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=7, loc="lower left")
    for key, lab, m in (("rover+lf", "ROVER, loop_fusion back end", "o"), ("rover+lm", "ROVER, gtsam LM", "s"),
                        ("accept_all+lf", "accept-all, loop_fusion", "x"), ("accept_all+lm", "accept-all, LM", "+")):
        ref = "ate_true_only_lf" if key.endswith("lf") else "ate_true_only_lm"
        bx.plot(x, [methods.ratio(r[f"ate_{key}"], r[ref]) for r in rows], m, label=lab)
    bx.axhline(1.0, color="k", lw=0.8)
    bx.set_yscale("log")
    bx.set_ylabel("ATE / true-only ATE\n(same back end)")
    bx.set_xticks(x)
    bx.set_xticklabels([r["case"] for r in rows], rotation=60, ha="right", fontsize=7)
    bx.grid(alpha=0.3, which="both", axis="y")
    bx.legend(fontsize=7)
    metrics.save_figure(fig, path)


def report(a, cases, results):
    case_rows = [r for r, _, _ in results]
    summary = [x for _, rows, _ in results for x in rows]
    ind, outd = bench.defaults("indoor"), bench.defaults("outdoor")
    notes = [bench.decision_note(a),
             f"split: {a.split}{' (quick)' if a.quick else ''}; cases and seeds: roverlib/splits.py",
             f"ROVER at the shipped defaults: indoor {ind['threshold']:g} m, gate {ind['max_innovation']:g} m + "
             f"{ind['max_innovation_per_metre']:g} x path; outdoor {outd['threshold']:g} m, gate "
             f"{outd['max_innovation']:g} m + {outd['max_innovation_per_metre']:g} x path; 4-DoF; time budget lifted",
             f"PCM, IPC, GNC, DCS and the LM back end: drift model {drift_model.INDOOR} (indoor) / "
             f"{drift_model.OUTDOOR} (outdoor); time limit per peer and case: {a.time_limit:g} s",
             "P '-': nothing accepted; ATE/tATE RMSE [m], SE(3)-aligned"] + \
        [f"{c.name}: {c.notes}" for c in cases if c.notes]
    wide = methods.wide_rows(case_rows, summary)
    tables = [("Pooled over the cases", methods.pooled(summary), methods.POOLED_COLUMNS),
              ("Decisions (ROVER, sequential, shipped defaults)", case_rows, CASE_COLUMNS),
              ("Decisions, every method (same candidates, same order)", wide, methods.decision_columns(SELECTIONS)),
              ("Trajectories: ATE [m] per back end (LF = loop_fusion's, LM = gtsam LM)", case_rows, TRAJ_COLUMNS)]
    figures = []
    for p in ("oracle", "none"):
        panels = [(f"{r['case']} ({p})", [("ROVER score", cv[p])]) for r, _, cv in results if cv[p]["recall"].size]
        if panels:
            figures.append((f"pr_{p}.png", functools.partial(
                metrics.plot_pr_grid, panels, ncols=5,
                suptitle=f"Simulated scenes, precision-recall of the score, protocol {p}")))
    figures.append(("poc.png", functools.partial(plot, case_rows)))
    return bench.FamilyReport(summary, tables, notes, {"cases.csv": case_rows}, figures)


def main(argv=None):
    return bench.run_family("poc", __doc__, run_case, report, argv,
                            job=lambda c, a: (c, a.out, a.snapshots, a.time_limit, bench.decision_args(a)))


if __name__ == "__main__":
    sys.exit(main())
