#!/usr/bin/env python3
"""Why decisions went wrong, from the verdict logs a benchmark left behind (no new runs):
for every run of a results folder, the accepted false loops and the rejected true loops with
their loop span (keyframes from match to query), score, innovation (candidate vs current
estimate) and path length (odometry since the two places were last tied together); what a
gate "reject if innovation > A + B * path_length" would have done to the accepted loops; and
the average precision of the score next to alternatives computed from the same verdicts
(score / path length, innovation).

  ./scripts/bench.sh diagnostics results/posegraph [--gate 1.0,0.05] [--run rover]

A family's folder holds scenarios/<case>/ and runs/<case>/<run>/verdicts.csv (roverlib/methods.py:
"rover" is the product's sequential run; the PoC and real families also have "oracle" and
"none")."""
import argparse
import glob
import os
import sys

import numpy as np

from roverlib import bench, metrics

COLUMNS = [("run", "run", ""), ("fp", "FP", "d"), ("fp_span", "FP span med", ".0f"), ("fp_score", "FP score med", ".2f"),
           ("fp_innovation", "FP innov med", ".2f"), ("fp_score_per_innovation", "FP score/innov", ".3f"),
           ("tp", "TP", "d"), ("fn", "FN", "d"), ("fn_score", "FN score med", ".2f"), ("fn_path", "FN path med", ".0f"),
           ("gate_fp", "gate: FP left", "d"), ("gate_tp", "gate: TP left", "d"),
           ("ap_score", "AP score", ".3f"), ("ap_score_per_path", "AP score/path", ".3f"),
           ("ap_innovation", "AP innov", ".3f")]


def med(values):
    return float(np.median(values)) if len(values) else float("nan")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("family", help="a results folder with runs/ and scenarios/ (e.g. results/posegraph)")
    ap.add_argument("--gate", default="1.0,0.05", help="A,B of the counterfactual innovation gate [m, m/m]")
    ap.add_argument("--run", default="rover", help="which run of each case (rover, oracle, none)")
    a = ap.parse_args(argv)
    ga, gb = (float(x) for x in a.gate.split(","))
    rows = []
    for run in sorted(glob.glob(os.path.join(a.family, "runs", "*", a.run))):
        name = os.path.basename(os.path.dirname(run))
        scn = os.path.join(a.family, "scenarios", name)
        if not os.path.exists(os.path.join(run, "verdicts.csv")) or not os.path.isdir(scn):
            continue
        j = bench.labelled(run, os.path.join(scn, "candidates.csv"))
        r = {"run": name}
        f = lambda key, sel: np.array([float(x[key]) for x, s in zip(j["rows"], sel) if s])  # noqa: E731
        fp = (j["label"] == 0) & j["accepted"]
        tp = (j["label"] == 1) & j["accepted"]
        fn = (j["label"] == 1) & ~j["accepted"]
        span = np.array([int(x["query_index"]) - int(x["match_index"]) for x in j["rows"]])
        r.update(fp=int(fp.sum()), tp=int(tp.sum()), fn=int(fn.sum()), fp_span=med(span[fp]),
                 fp_score=med(f("score", fp)), fp_innovation=med(f("innovation", fp)),
                 fp_score_per_innovation=med(f("score", fp) / f("innovation", fp)) if fp.any() else float("nan"),
                 fn_score=med(f("score", fn)), fn_path=med(f("path_length", fn)))
        gate = lambda sel: int(np.sum(f("innovation", sel) <= ga + gb * f("path_length", sel)))  # noqa: E731
        r["gate_fp"], r["gate_tp"] = gate(fp), gate(tp)
        every = np.ones(len(j["rows"]), dtype=bool)
        score, path, innov = f("score", every), f("path_length", every), f("innovation", every)
        scored = np.isfinite(j["score"])  # unscored verdicts rank last in every variant
        alt = lambda x: metrics.ranking_metrics(j["label"], np.where(scored, x, np.inf))["ap"]  # noqa: E731
        with np.errstate(divide="ignore", invalid="ignore"):
            r["ap_score"], r["ap_score_per_path"], r["ap_innovation"] = alt(score), alt(score / path), alt(innov)
        rows.append(r)
    bench.print_table(rows, COLUMNS, f"{a.family}: accepted false (FP) and rejected true (FN) loops; counterfactual "
                                     f"gate innovation <= {ga:g} m + {gb:g} * path_length on the accepted ones")
    tot = {k: sum(r[k] for r in rows) for k in ("fp", "tp", "gate_fp", "gate_tp")}
    print(f"total: FP {tot['fp']} -> {tot['gate_fp']} with the gate; TP {tot['tp']} -> {tot['gate_tp']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
