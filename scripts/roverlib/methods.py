"""Every method of a benchmark case, on the same candidates in the same order, and what each
gets (one summary row per method and back end):

  rover       rover_replay, sequential, at the shipped configuration of the case's environment
              (--config config/rover_<env>.yaml; time budget lifted);
  accept_all  every candidate (loop_fusion without a verifier);
  pcm, ipc    the incremental peers (roverlib/peers.py) with the problem's covariances;
  gnc, dcs    gtsam's batch robust back ends (roverlib/robust.py), under a time limit;
  odometry    no loop at all.

A selection is solved with two back ends, each named in the method ("rover+lf", "rover+lm"):
  lf  loop_fusion's own optimisation (unit weights, Huber(0.1) loops, 5 iterations from VIO:
      rover_replay's solveLikeLoopFusion), the trajectory a VINS-Fusion user sees;
  lm  gtsam Levenberg-Marquardt to convergence with the problem's covariances.
Each ATE is reported next to the true-only solution of the same back end (ate_true_only): a
back end that cannot use the true loops well shows in that column, not as a verifier failure.
GNC and DCS are back ends themselves (their true-only reference is lm's).
tATE (temporal ATE): the mean ATE of what the method showed after k/K of the keyframes,
k = 1..K, each against the truth of the keyframes so far; with the selection as it stood then
(PCM's clique changes over time). Batch methods decide once at the end: no tATE ("-").
"""
import math
import os
import shutil

import numpy as np

from . import bench, metrics, peers, robust

# rover_replay flags that make every verification a cheap rejection (a zero innovation gate)
# so that, with --protocol none, the run is just loop_fusion's back end on the scenario's
# candidates (its accept-all graph): how any selection is solved with loop_fusion's back end.
LF_ONLY = ["--max_innovation", 1e-9, "--max_innovation_per_metre", 0, "--max_relative_yaw_deg", 180,
           "--max_relative_translation", 100, "--time_budget_ms", 0]
ALL_METHODS = ("rover", "accept_all", "pcm", "ipc", "gnc", "dcs")


def snapshot_sizes(n, k):
    """Keyframes held at rover_replay's snapshots 1..k: ceil(i * n / k)."""
    return [-(-i * n // k) for i in range(1, k + 1)]


def write_selection(scn_dir, pairs, out_dir, n_keyframes=None):
    """A copy of a scenario directory with only the candidates in `pairs` ((query, match)) and,
    with n_keyframes, only the first n keyframes."""
    os.makedirs(out_dir, exist_ok=True)
    for name in ("keyframes.csv", "groundtruth.csv"):
        src = os.path.join(scn_dir, name)
        if not os.path.exists(src):
            continue
        with open(src) as f:
            lines = f.readlines()
        if n_keyframes is not None:
            head = [l for l in lines if l.startswith("#")]
            body = [l for l in lines if not l.startswith("#")]
            lines = head + body[:1 + n_keyframes]
        with open(os.path.join(out_dir, name), "w") as f:
            f.writelines(lines)
    with open(os.path.join(scn_dir, "candidates.csv")) as f:
        lines = f.readlines()
    keep = [lines[0]] + [l for l in lines[1:] if (int(l.split(",")[0]), int(l.split(",")[1])) in pairs]
    with open(os.path.join(out_dir, "candidates.csv"), "w") as f:
        f.writelines(keep)
    return out_dir


def lf_errors(scn_dir, sets, sizes, out_dir, mode, gt, align):
    """(ATE, tATE) of loop_fusion's back end with the final set sets[-1] and, per snapshot, the
    set as it stood then (sets[i]: pairs after snapshot i). One rover_replay run when every
    snapshot's set is the final set cut at that time (a selection that never drops a loop),
    else one run per snapshot."""
    final = set(sets[-1])
    run = bench.replay(write_selection(scn_dir, final, os.path.join(out_dir, "scenario")), os.path.join(out_dir, "run"),
                       "none", ["--mode", mode] + LF_ONLY, snapshots=len(sizes))
    est = os.path.join(run, "loop_fusion_accept_all.tum")
    ate = metrics.ate(gt, est, align)
    monotone = all(set(s) == {p for p in final if p[0] < n} for s, n in zip(sets, sizes))
    if monotone:
        snaps = [os.path.join(run, "snapshots", f"loop_fusion_accept_all_{i}.tum") for i in range(1, len(sizes) + 1)]
    else:
        snaps = []
        for i, (s, n) in enumerate(zip(sets, sizes)):
            d = os.path.join(out_dir, f"snapshot_{i + 1}")
            r = bench.replay(write_selection(scn_dir, set(s), os.path.join(d, "scenario"), n), os.path.join(d, "run"),
                             "none", ["--mode", mode] + LF_ONLY)
            snaps.append(os.path.join(r, "loop_fusion_accept_all.tum"))
    shutil.rmtree(os.path.join(out_dir, "scenario"), ignore_errors=True)
    return ate, metrics.temporal_ate(gt, snaps, align)


def lm_errors(problem, sets, sizes, stamps, gt, align):
    """(ATE, tATE) of gtsam LM with the final set and with each snapshot's set on the keyframes
    so far."""
    def traj(poses):
        return metrics.trajectory(stamps[:len(poses)], [T[:3, 3] for T in poses])
    odo = problem.odometry_poses()
    ate = metrics.ate(gt, traj(robust.solve_lm(problem, problem.subset(sets[-1]), odo)), align)
    snaps = [traj(robust.solve_lm(problem, problem.subset(s), odo[:n])) for s, n in zip(sets, sizes)]
    return ate, metrics.temporal_ate(gt, snaps, align)


def sets_at(sizes, loops, per_candidate):
    """The selection at each snapshot: after the last candidate whose query had arrived.
    per_candidate[i]: indices into `loops` accepted after candidate i."""
    out = []
    for n in sizes:
        last = max([i for i, e in enumerate(loops) if e.b < n], default=-1)
        out.append({loops[k].pair for k in per_candidate[last]} if last >= 0 else set())
    return out


def rover_flags(environment, problem, replay_args=()):
    """rover_replay flags of ROVER's sequential run in evaluate() (bench/agreement.py runs the
    same): the environment's shipped YAML, the problem's mode, the family's replay_args, time
    budget lifted."""
    mode = "4dof" if problem.dof in (3, 4) else "6dof"
    return bench.shipped(environment, "--mode", mode, *replay_args, "--time_budget_ms", 0)


def evaluate(case, scn_dir, problem, replay_args, out_dir, methods=ALL_METHODS, snapshots=10, time_limit=600.0,
             align="se3"):
    """Runs every method on one case. Returns (info: dict for the family's case table,
    rows: summary rows, one per method and back end). Every method gets the keyframes that
    ROVER's run kept (a keyframe its intake refused is left out of the problem, with the
    candidates that name it: Problem.on_keyframes)."""
    mode = "4dof" if problem.dof in (3, 4) else "6dof"
    runs = os.path.join(out_dir, "runs", case.name)
    # ROVER, sequential, the product's mode
    seq = bench.replay(scn_dir, os.path.join(runs, "rover"), "sequential",
                       rover_flags(case.environment, problem, replay_args), snapshots)
    intake = bench.intake(seq)
    if not all(kept for _, kept in intake):
        problem = problem.on_keyframes(i for i, kept in intake if kept)
    loops, labels = problem.loops, problem.labels()
    n = problem.n
    sizes = snapshot_sizes(n, snapshots)
    gt = metrics.read_tum(os.path.join(seq, "groundtruth.tum"))
    stamps = np.array(gt.timestamps)
    j = bench.labelled(seq, os.path.join(scn_dir, "candidates.csv"))
    verdict = {}
    for r in j["rows"]:
        verdict.setdefault((int(r["query_index"]), int(r["match_index"])), []).append(r)
    rover_rows = [verdict[e.pair].pop(0) for e in loops]
    rover_acc = np.array([int(r["accepted"]) == 1 for r in rover_rows])
    elapsed = [float(r["elapsed_ms"]) for r in rover_rows]
    info = {"case": case.name, "split": case.split, "notes": case.notes, "keyframes": n, "true": int(labels.sum()),
            "false": int((labels == 0).sum()), "rover_reasons": bench.reason_counts(r["reason"] for r in rover_rows),
            "rover_over_200ms": float(np.mean(np.array(elapsed) > 200.0)) if elapsed else float("nan"),
            "limits": []}
    true_sets = [{e.pair for e in loops if e.label == 1 and e.b < m} for m in sizes]
    lf_true, _ = lf_errors(scn_dir, true_sets, sizes, os.path.join(runs, "true_only_lf"), mode, gt, align)
    lm_true, _ = lm_errors(problem, true_sets, sizes, stamps, gt, align)
    info.update(ate_true_only_lf=lf_true, ate_true_only_lm=lm_true)
    odo_ate = metrics.ate(gt, os.path.join(seq, "odometry.tum"), align)
    rows = []

    def add(method, accepted, ate, ate_true, tate, ms=()):
        d = metrics.decision_metrics(labels, accepted) if accepted is not None else \
            {"tp": None, "fp": None, "fn": None, "precision": float("nan"), "recall": float("nan")}
        rows.append({"family": case.family, "split": case.split, "case": case.name, "method": method,
                     "tp": d["tp"], "fp": d["fp"], "fn": d["fn"], "precision": d["precision"], "recall": d["recall"],
                     "ate": ate, "ate_true_only": ate_true, "tate": tate,
                     "verify_ms_p50": bench.percentile(ms, 50), "verify_ms_p99": bench.percentile(ms, 99)})

    add("odometry", np.zeros(len(loops), dtype=bool),
        odo_ate, float("nan"), metrics.temporal_ate(gt, metrics.prefixes(os.path.join(seq, "odometry.tum"), snapshots),
                                                     align))
    selections = {}  # method -> (accepted per loop, per-candidate accepted index lists, ms)
    if "rover" in methods:
        per = [list(np.flatnonzero(rover_acc[:i + 1])) for i in range(len(loops))]
        selections["rover"] = (rover_acc, per, elapsed)
    if "accept_all" in methods:
        selections["accept_all"] = (np.ones(len(loops), dtype=bool), [list(range(i + 1)) for i in range(len(loops))], ())
    for m in ("pcm", "ipc"):
        if m in methods:
            r = peers.run(m, problem, deadline_s=time_limit)
            if r["time_limit_hit"]:
                info["limits"].append(m)
            selections[m] = (r["accepted"], r["sets"], r["ms"])
            info[f"{m}_reasons"] = bench.reason_counts(r["reasons"])
    for m, (accepted, per, ms) in selections.items():
        sets = sets_at(sizes, loops, per)
        if m == "rover":  # its own run holds loop_fusion's solve and snapshots of its selection
            t = bench.trajectory_errors(seq, align, names=("loop_fusion_verified",))["loop_fusion_verified"]
        elif m == "accept_all":
            t = bench.trajectory_errors(seq, align, names=("loop_fusion_accept_all",))["loop_fusion_accept_all"]
        else:
            t = lf_errors(scn_dir, sets, sizes, os.path.join(runs, f"{m}_lf"), mode, gt, align)
        add(f"{m}+lf", accepted, t[0], lf_true, t[1], ms)
        a, ta = lm_errors(problem, sets, sizes, stamps, gt, align)
        add(f"{m}+lm", accepted, a, lm_true, ta, ms)
    for m, solve in (("gnc", robust.solve_gnc), ("dcs", robust.solve_dcs)):
        if m not in methods:
            continue
        result, seconds, hit = bench.run_limited(solve, (problem, loops), time_limit)
        info[f"{m}_seconds"] = seconds
        if hit:
            info["limits"].append(m)
            add(m, None, float("nan"), lm_true, float("nan"))
            continue
        poses, accepted = result
        traj = metrics.trajectory(stamps, [T[:3, 3] for T in poses])
        add(m, np.array(accepted, dtype=bool), metrics.ate(gt, traj, align), lm_true, float("nan"))
    info["limits"] = ", ".join(info["limits"]) or "-"
    return info, rows


def ratio(a, b):
    return a / b if b and math.isfinite(a) and math.isfinite(b) else float("nan")


NAMES = {"rover": "ROVER", "accept_all": "accept-all", "pcm": "PCM", "ipc": "IPC", "gnc": "GNC", "dcs": "DCS"}


def wide_rows(infos, summary):
    """One row per case for the families' tables: the case's info plus, per summary row,
    'method:metric' keys and '<selection>:counts' = 'TP/FP/FN'."""
    out = []
    for info in infos:
        row = dict(info)
        for r in summary:
            if r["case"] != info["case"]:
                continue
            for k in ("tp", "fp", "fn", "precision", "recall", "ate", "ate_true_only", "tate", "verify_ms_p50",
                      "verify_ms_p99"):
                row[f"{r['method']}:{k}"] = r[k]
            sel = r["method"].split("+")[0]
            row[f"{sel}:counts"] = "-" if r["tp"] is None else f"{r['tp']}/{r['fp']}/{r['fn']}"
            row[f"{r['method']}:ratio"] = ratio(r["ate"], r["ate_true_only"])
        out.append(row)
    return out


def decision_columns(selections):
    cols = [("case", "case", ""), ("true", "true", "d"), ("false", "false", "d")]
    for m in selections:
        key = m if m in ("gnc", "dcs") else m + "+lf"
        cols += [(f"{m}:counts", f"{NAMES[m]} TP/FP/FN", ""), (f"{key}:precision", f"{NAMES[m]} P", ".2f"),
                 (f"{key}:recall", f"{NAMES[m]} R", ".2f")]
    return cols


def trajectory_columns(selections, metric="ate"):
    """ATE (or tATE) per back end: loop_fusion's (LF) then gtsam LM; true-only first."""
    label = "ATE" if metric == "ate" else "tATE"
    cols = [("case", "case", ""), (f"odometry:{metric}", f"odometry {label}", ".2f")]
    for backend in ("lf", "lm"):
        if metric == "ate":
            cols.append((f"ate_true_only_{backend}", f"{backend.upper()} true-only", ".2f"))
        for m in selections:
            if m in ("gnc", "dcs"):
                if backend == "lm" and metric == "ate":
                    cols.append((f"{m}:ate", f"{NAMES[m]}", ".2f"))
                continue
            cols.append((f"{m}+{backend}:{metric}", f"{backend.upper()} {NAMES[m]}", ".2f"))
    return cols


POOLED_COLUMNS = [("method", "method", ""), ("cases", "cases", "d"), ("tp", "TP", "d"), ("fp", "FP", "d"),
                  ("fn", "FN", "d"), ("precision", "P", ".3f"), ("recall", "R", ".3f"),
                  ("cases_with_fp", "cases with FP", "d"), ("cases_p_lt_099", "cases P < 0.99", "d"),
                  ("cases_r_lt_09", "cases R < 0.9", "d"), ("median_ratio", "median ATE/true-only", ".2f"),
                  ("worst_ratio", "worst ATE/true-only", ".1f")]


def pooled(summary):
    """Per method over every case of a summary: summed TP/FP/FN and their P/R, how many cases
    fail a precision or recall bar, and the ATE over the true-only ATE (same back end)."""
    out = []
    for method in dict.fromkeys(r["method"] for r in summary):
        rows = [r for r in summary if r["method"] == method and r["tp"] not in (None, "")]
        if not rows or method == "odometry":
            continue
        tp, fp, fn = (sum(int(r[k]) for r in rows) for k in ("tp", "fp", "fn"))
        prec = [float(r["precision"]) if r["precision"] not in (None, "") else float("nan") for r in rows]
        rec = [float(r["recall"]) if r["recall"] not in (None, "") else float("nan") for r in rows]
        ratios = [ratio(float(r["ate"]), float(r["ate_true_only"])) for r in rows
                  if r["ate"] not in (None, "") and r["ate_true_only"] not in (None, "")]
        ratios = [x for x in ratios if math.isfinite(x)]
        out.append({"method": method, "cases": len(rows), "tp": tp, "fp": fp, "fn": fn,
                    "precision": tp / (tp + fp) if tp + fp else float("nan"),
                    "recall": tp / (tp + fn) if tp + fn else float("nan"),
                    "cases_with_fp": sum(int(r["fp"]) > 0 for r in rows),
                    "cases_p_lt_099": sum(p < 0.99 for p in prec), "cases_r_lt_09": sum(x < 0.9 for x in rec),
                    "median_ratio": float(np.median(ratios)) if ratios else float("nan"),
                    "worst_ratio": max(ratios) if ratios else float("nan")})
    return out


def main(argv=None):
    """python -m roverlib.methods results/<family>/summary.csv: the pooled table of a run."""
    import argparse
    import csv
    ap = argparse.ArgumentParser(description=main.__doc__)
    ap.add_argument("summary")
    a = ap.parse_args(argv)
    with open(a.summary) as f:
        rows = list(csv.DictReader(f))
    bench.print_table(pooled(rows), POOLED_COLUMNS, f"{a.summary}: pooled over {len({r['case'] for r in rows})} cases")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
