#!/usr/bin/env python3
"""Cost: time of one verification next to loop_fusion's full optimisation of the same graph
(rover_benchmark_cost, measured in one run, as a ratio) for graphs of 1k .. 20k keyframes and
a short and a long loop span (keyframes from the match to the query), and peak memory.

  ./scripts/bench.sh cost [--quick] [--sizes 1000,2000,5000,10000,20000] [--spans 100,1000]
                          [--six-dof-sizes 1000,2000] [--repeats 20] [--out results/cost]

Each (mode, size, span) runs in its own process, so that its peak RSS (getrusage) is its own:
building the graph, the verifications and the full solves. verify = median (and p90) over
--repeats verifications of the same candidate; loop_fusion = Verifier::solveLikeLoopFusion(5):
the whole graph from the earliest loop, initialised from VIO, 5 iterations, as optimize4DoF.
4-DoF (VIO) for every size; 6-DoF (VO, autodiff residuals) for --six-dof-sizes. The trial
solve's time budget is lifted (the cost is what is measured). Run it on an otherwise idle
machine: the numbers are wall-clock times. Targets: median verification <= 1 ms at 1k and
<= 5 ms at 10k keyframes (4-DoF, short span). Writes cost.csv, summary.md, cost.png and
summary.csv (roverlib.bench.SUMMARY_COLUMNS: per row, method "rover" = one verification and
"loop_fusion_full" = loop_fusion's full solve; split "-": synthetic graphs, nothing is tuned on
them; verify_ms_p99 empty: the tool reports median and p90, in cost.csv).
--quick (CI): 4-DoF, 1k and 2k keyframes, span 100, 5 repeats."""
import csv
import functools
import os
import subprocess
import sys
import tempfile

from roverlib import bench, metrics

COLUMNS = [("mode", "mode", ""), ("keyframes", "keyframes", "d"), ("span", "span", "d"), ("window", "window", "d"),
           ("iterations", "iters", "d"), ("verify_median_ms", "verify median [ms]", ".3f"),
           ("verify_p90_ms", "p90 [ms]", ".3f"), ("loop_fusion_full_ms", "loop_fusion full [ms]", ".1f"),
           ("ratio_full_over_verify", "ratio", ".1f"), ("peak_rss_mb", "peak RSS [MB]", ".1f"), ("target", "target", "")]
TARGETS = {1000: 1.0, 10000: 5.0}  # keyframes -> median verification [ms], 4-DoF short span


def measure(mode, n, span, repeats):
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "row.csv")
        subprocess.run([bench.tool("rover_benchmark_cost"), "--sizes", str(n), "--spans", str(span), "--repeats",
                        str(repeats), "--mode", mode, "--csv", path], check=True, capture_output=True, text=True)
        with open(path) as f:
            rows = list(csv.DictReader(f))
    if not rows:
        raise RuntimeError(f"rover_benchmark_cost wrote no row for {mode} {n} {span}")
    r = {"mode": mode}
    for k, v in rows[0].items():
        r[k] = float(v) if "." in v else int(v)
    return r


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=100)
    for mode in dict.fromkeys(r["mode"] for r in rows):
        for span in sorted({r["span"] for r in rows if r["mode"] == mode}):
            sel = sorted((r for r in rows if r["mode"] == mode and r["span"] == span), key=lambda r: r["keyframes"])
            ls = "-" if mode == "4dof" else ":"
            ax.plot([r["keyframes"] for r in sel], [r["verify_median_ms"] for r in sel], "o" + ls,
                    label=f"verify, {mode}, span {span}")
        sel = sorted((r for r in rows if r["mode"] == mode), key=lambda r: r["keyframes"])
        seen = {}
        for r in sel:
            seen.setdefault(r["keyframes"], r["loop_fusion_full_ms"])
        ax.plot(list(seen), list(seen.values()), "s--", color="grey" if mode == "4dof" else "black",
                label=f"loop_fusion full solve, {mode}")
    for n, ms in TARGETS.items():
        ax.plot([n], [ms], "r*", markersize=10)
    ax.plot([], [], "r*", label="target (4-DoF)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("keyframes in the graph")
    ax.set_ylabel("time [ms]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    metrics.save_figure(fig, path)


def arguments(ap):
    ap.add_argument("--quick", action="store_true", help="CI: 4-DoF, 1k and 2k keyframes, span 100, 5 repeats")
    ap.add_argument("--sizes", default="1000,2000,5000,10000,20000")
    ap.add_argument("--spans", default="100,1000")
    ap.add_argument("--six-dof-sizes", default="1000,2000", help="6-DoF sizes ('' for none)")
    ap.add_argument("--repeats", type=int, default=20)


def plan(a):
    """The (mode, keyframes, span) rows to measure, spans shorter than the graph."""
    if a.quick:
        a.sizes, a.spans, a.six_dof_sizes, a.repeats = "1000,2000", "100", "", 5
    spans = [int(s) for s in a.spans.split(",")]
    rows = [("4dof", int(n), s) for n in a.sizes.split(",") for s in spans]
    rows += [("6dof", int(n), s) for n in a.six_dof_sizes.split(",") if n for s in spans]
    return [r for r in rows if r[2] < r[1]]


def run_row(job):
    """One row of the plan, measured in its own rover_benchmark_cost process; checked against
    TARGETS where one applies (4-DoF, the shortest span)."""
    (mode, n, span), repeats, shortest_span = job
    r = measure(mode, n, span, repeats)
    if mode == "4dof" and span == shortest_span and n in TARGETS:
        r["target"] = f"<= {TARGETS[n]:g} ms: " + ("met" if r["verify_median_ms"] <= TARGETS[n] else "UNMET")
    print(f"  {mode} {n} keyframes, span {span}: verify {r['verify_median_ms']:.3f} ms, "
          f"loop_fusion {r['loop_fusion_full_ms']:.1f} ms, peak RSS {r['peak_rss_mb']:.1f} MB", flush=True)
    return r


def report(a, cases, rows):
    title = ("Cost of one verification vs loop_fusion's full optimisation of the same graph (one process per row; "
             f"median of {a.repeats} verifications)")
    summary = []
    for r in rows:
        case = f"{r['mode']}_{r['keyframes']}kf_span{r['span']}"
        for method, ms in (("rover", r["verify_median_ms"]), ("loop_fusion_full", r["loop_fusion_full_ms"])):
            summary.append({"family": "cost", "split": "-", "case": case, "method": method, "verify_ms_p50": ms})
    return bench.FamilyReport(summary, [(title, rows, COLUMNS)], csvs={"cost.csv": rows},
                              figures=[("cost.png", functools.partial(plot, rows))])


def main(argv=None):
    # one row after the other in this process (each in its own child): the numbers are times
    return bench.run_family("cost", __doc__, run_row, report, argv, arguments=arguments, cases=plan,
                            job=lambda row, a: (row, a.repeats, min(int(s) for s in a.spans.split(","))),
                            shared_options=False)


if __name__ == "__main__":
    sys.exit(main())
