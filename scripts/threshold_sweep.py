#!/usr/bin/env python3
"""Sequential verification at several fixed thresholds over the TUNING cases only
(roverlib/splits.py: the simulated scenes and real runs of one environment), as the product
decides (every candidate verified when it arrives, accepted ones committed), with that
environment's shipped innovation gate: what a user gets from each threshold. Defaults may be
chosen from this table; the docs report the test sets (scripts/bench.sh).

  ./scripts/bench.sh sweep [--environment indoor|outdoor] [--thresholds 0.1,0.15,0.2,0.3,0.5]
                           [--per-metre 0] [--quick] [--jobs 2] [--out results/threshold_sweep]

Prints one line per threshold (TP, FP, FN summed over the cases; precision "-" if nothing was
accepted; the cases with false positives or more than 30 % missed true loops) and writes
results.csv (one row per case and threshold)."""
import argparse
import os
import sys
from concurrent.futures import ThreadPoolExecutor

from roverlib import bench, metrics, scenario, splits


def sweep_cases(environment, quick=False):
    """The tuning cases of `environment` the sweep runs on (never a test case)."""
    chosen = [c for c in splits.cases(split="tuning") if c.family in ("poc", "real") and c.environment == environment]
    return chosen[:4] if quick else chosen


def replay(case_dir, mode, out, threshold, per_metre, environment):
    run = bench.replay(case_dir, out, "sequential", bench.shipped(environment, "--mode", mode, "--threshold", threshold,
                                                                  "--threshold_per_metre", per_metre, "--time_budget_ms", 0))
    j = bench.labelled(run, os.path.join(case_dir, "candidates.csv"))
    return metrics.decision_metrics(j["label"], j["accepted"])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--environment", choices=("indoor", "outdoor"), default="indoor")
    ap.add_argument("--thresholds", default="0.1,0.15,0.2,0.3,0.5")
    ap.add_argument("--per-metre", type=float, default=0.0)
    ap.add_argument("--quick", action="store_true", help="the first 4 tuning cases (for CI)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "threshold_sweep"))
    a = ap.parse_args(argv)
    params = bench.defaults(a.environment)
    thresholds = [float(t) for t in a.thresholds.split(",")]
    cases = sweep_cases(a.environment, a.quick)
    dirs = {}
    for c in cases:
        s = c.build()
        dirs[c.name] = (os.path.join(a.out, "scenarios", c.name), s.meta.get("mode", "4dof"))
        scenario.write(s, dirs[c.name][0])
    print(f"{len(cases)} tuning cases ({a.environment}), gate {params['max_innovation']:g} m + "
          f"{params['max_innovation_per_metre']:g} x path: " + ", ".join(c.name for c in cases))
    rows = []
    with ThreadPoolExecutor(max_workers=a.jobs) as pool:
        for th in thresholds:
            jobs = {n: pool.submit(replay, d, mode, os.path.join(a.out, "runs", f"{n}_t{th:g}"), th, a.per_metre, a.environment)
                    for n, (d, mode) in dirs.items()}
            tp = fp = fn = 0
            notes = []
            for n, job in jobs.items():
                d = job.result()
                rows.append({"case": n, "threshold": th, "per_metre": a.per_metre, "tp": d["tp"], "fp": d["fp"],
                             "tn": d["tn"], "fn": d["fn"]})
                tp, fp, fn = tp + d["tp"], fp + d["fp"], fn + d["fn"]
                if d["fp"]:
                    notes.append(f"{n}:FP{d['fp']}")
                if d["tp"] + d["fn"] and d["fn"] > 0.3 * (d["tp"] + d["fn"]):
                    notes.append(f"{n}:FN{d['fn']}/{d['tp'] + d['fn']}")
            total = metrics.decision_metrics([1] * (tp + fn) + [0] * fp, [True] * tp + [False] * fn + [True] * fp)
            print(f"threshold {th:5.2f} (+{a.per_metre:g}/m): TP {tp:5d} FP {fp:5d} FN {fn:5d}  "
                  f"precision {bench.fmt(total['precision'], '.3f')} recall {bench.fmt(total['recall'], '.3f')}  | "
                  f"{' '.join(notes) or '-'}", flush=True)
    bench.write_csv(rows, os.path.join(a.out, "results.csv"))
    print(f"wrote {os.path.join(a.out, 'results.csv')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
