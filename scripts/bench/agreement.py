#!/usr/bin/env python3
"""Agreement of the bounded (condensed) trial with the full-window trial: on every
benchmark family, does ROVER decide each candidate the same way with condense_min_window N as
with the full Ceres trial over [match, newest]?

  ./scripts/bench.sh agreement [--split test|tuning] [--quick] [--families poc,real,posegraph]
                               [--cases A,B] [--condense-min-window N] [--gate-off]
                               [--a-args "..."] [--b-args "..."] [--decision metric|chi2|revisit]
                               [--jobs 2] [--out results/agreement]

Protocol. Each case is built as its family builds it (the family script's setup(): the same
scenario, candidates and order; --quick: the family's CI subset) and rover_replay runs at the
family's ROVER settings (methods.rover_flags: the shipped YAML of the case's environment, the
case's mode, the family's overrides, time budget lifted: --time_budget_ms 0). Full (A) is the
trial with --condense_min_window 0, condensed (B) the trial with --condense_min_window N (N: the
YAML's condense_min_window or --condense-min-window). Three comparisons:
  same-state  the headline, per candidate: one oracle run at A's settings with
              --compare-trials N, which before each candidate's verify() decides it with both
              trials against the same graph and estimate X (trials.csv); the run commits exactly
              the true-labelled candidates;
  oracle      two runs, A and B, each committing exactly the true-labelled candidates: the same
              loops, but a commit adopts the run's own trial solution (Verifier::commitLocked),
              so X, and with it the innovation gate, can drift apart between A and B;
  sequential  two runs, A and B, each committing what it accepts (the product): one
              disagreement changes the graph every later candidate of that run sees.
The innovation gate rejects candidates before any trial; --gate-off switches it off everywhere
(bench.GATE_OFF) so that every candidate gets a trial. --a-args/--b-args replace A's and B's
condense flags (a stand-in pair; no same-state comparison then).
Candidates are paired by (query, match, occurrence). Per family and comparison: candidates; the
decisions (accepted flag) that agree, count and %; the candidates only A accepts and only B
accepts (and of them, the false ones); the disagreements where one run had a trial and the other
none (the innovation gate, applied to estimates that the runs' own earlier trial solutions
made differ); the agreement over the candidates with a trial solve in A or B (verdict accepted,
score_above_threshold or not_converged); A's trials over more than N keyframes (those B
condenses, 4-DoF and 6-DoF); |score_B - score_A| over the candidates scored in both (median, p99, max); the
verification time (elapsed_ms, every candidate) p50/p99/max of A and B and their ratio B/A,
measured in this run (same-state: both trials of a candidate back to back; oracle, sequential:
A's and B's runs of a case back to back).
Per case too: the cases whose agreement is below 99.5 % in a comparison (table "Cases below
99.5 %", and a count per comparison), since a pooled figure can hide a case that one disagreement
turns.
Writes summary.md, summary.csv (a row per family x comparison, per mode too where a family mixes
4-DoF and 6-DoF cases, and "all"), cases.csv (a row per case x comparison) and disagreements.csv
(every disagreement) into --out.
Exit status non-zero only on errors, never on low agreement."""
import argparse
import collections
import csv
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from roverlib import bench, methods, metrics, programs, reasons

poc, posegraph, real = (programs.load(f"bench/{f}.py") for f in ("poc", "posegraph", "real"))  # the families

FAMILIES = {"poc": poc, "real": real, "posegraph": posegraph}
PROTOCOLS = ("oracle", "sequential")  # two runs each, A and B
COMPARISONS = ("same-state",) + PROTOCOLS
SHOWN = 100  # disagreements in the printed table and summary.md (disagreements.csv: every one)
COLUMNS = [("family", "family", ""), ("comparison", "comparison", ""), ("cases", "cases", "d"),
           ("candidates", "cand", "d"), ("agree", "agree", "d"), ("agree_pct", "agree %", ".2f"),
           ("a_only", "A-only acc", "d"), ("a_only_false", "(false)", "d"), ("b_only", "B-only acc", "d"),
           ("b_only_false", "(false)", "d"), ("gate_differs", "gate differs", "d"), ("trialled", "trials", "d"),
           ("trialled_agree_pct", "agree % (trials)", ".2f"), ("condensable", "trials > N kf", "d"),
           ("scored", "scored both", "d"), ("dscore_median", "|dscore| med", ".2g"),
           ("dscore_p99", "p99", ".2g"), ("dscore_max", "max", ".2g"),
           ("a_ms_p50", "A ms p50", ".1f"), ("a_ms_p99", "p99", ".1f"), ("a_ms_max", "max", ".1f"),
           ("b_ms_p50", "B ms p50", ".1f"), ("b_ms_p99", "p99", ".1f"), ("b_ms_max", "max", ".1f"),
           ("ratio_p50", "B/A p50", ".2f"), ("ratio_p99", "B/A p99", ".2f")]
CASE_COLUMNS = [("family", "family", ""), ("case", "case", ""), ("mode", "mode", ""), ("comparison", "comparison", ""),
                ("candidates", "cand", "d"), ("agree", "agree", "d"), ("agree_pct", "agree %", ".2f")]
DISAGREEMENT_COLUMNS = [("family", "family", ""), ("comparison", "comparison", ""), ("case", "case", ""),
                        ("query", "query", "d"), ("match", "match", "d"), ("label", "label", ""),
                        ("a_accepted", "A acc", "d"), ("a_reason", "A reason", ""), ("a_score", "A score", ".4g"),
                        ("a_threshold", "A thr", ".3g"), ("b_accepted", "B acc", "d"),
                        ("b_reason", "B reason", ""), ("b_score", "B score", ".4g"), ("b_threshold", "B thr", ".3g"),
                        ("a_window", "A window", "d")]


def build_stamp(replay):
    """Modification times of rover_replay and the workspace's libraries it loads (a rebuild
    during the run would mix two builds)."""
    lib_dir = os.path.dirname(os.path.dirname(replay))
    ldd = subprocess.run(["ldd", replay], capture_output=True, text=True).stdout.split()
    return [os.stat(p).st_mtime for p in [replay] + sorted(w for w in ldd if w.startswith(lib_dir + os.sep))]


def fields(p, verdict):
    """The paired row's entries of run p ("a", "b") from a verdict row (accepted, reason, score,
    threshold, elapsed_ms)."""
    return {f"{p}_accepted": int(verdict["accepted"]), f"{p}_reason": verdict["reason"],
            f"{p}_score": float(verdict["score"]), f"{p}_threshold": float(verdict["threshold"]),
            f"{p}_ms": float(verdict["elapsed_ms"]), f"{p}_scored": bool(np.isfinite(metrics.ranking_score(verdict))),
            f"{p}_trial": verdict["reason"] in reasons.TRIALLED}


def same_state(run):
    """Paired rows (A = full, B = condensed) of a --compare-trials run's trials.csv."""
    rows = []
    with open(os.path.join(run, "trials.csv")) as f:
        for t in csv.DictReader(f):
            if t["label"] not in ("0", "1"):
                continue
            row = {"query": int(t["query_index"]), "match": int(t["match_index"]),
                   "label": "true" if t["label"] == "1" else "false", "a_window": int(t["full_window"])}
            for p, k in (("a", "full"), ("b", "condensed")):
                row.update(fields(p, {x: t[f"{k}_{x}"] for x in ("accepted", "reason", "score", "threshold")} |
                                  {"elapsed_ms": t[f"{k}_ms"]}))
            rows.append(row)
    return rows


def paired(run_a, run_b, labels_path):
    """One dict per candidate of both runs' verdicts, paired by (query, match, occurrence)."""
    def keyed(run):
        j = bench.labelled(run, labels_path)
        seen = collections.Counter()
        out = {}
        for lab, r in zip(j["label"], j["rows"]):
            k = (int(r["query_index"]), int(r["match_index"]))
            out[k + (seen[k],)] = (int(lab), r)
            seen[k] += 1
        return out
    a, b = keyed(run_a), keyed(run_b)
    if a.keys() != b.keys():
        raise RuntimeError(f"{run_a} and {run_b} hold verdicts of different candidates")
    rows = []
    for k, (lab, ra) in a.items():
        rb = b[k][1]
        row = {"query": k[0], "match": k[1], "label": "true" if lab else "false", "a_window": int(ra["window_size"])}
        rows.append({**row, **fields("a", ra), **fields("b", rb)})
    return rows


def run_case(job):
    """Every comparison of one case: {comparison: [paired rows]} (same-state only with compare_n)."""
    family, case, out, flags_a, flags_b, compare_n, decision, max_loops = job
    module = FAMILIES[family]
    kw = {"max_loops": max_loops} if family == "posegraph" else {}
    base = os.path.join(out, family)  # scenarios/<case>, runs/<case>/{same-state,<protocol>/{A,B}}
    _, d, prob, rover_args = module.setup(case, base, decision, **kw)
    flags = methods.rover_flags(case.environment, prob, rover_args)
    mode = flags[flags.index("--mode") + 1]
    runs = os.path.join(base, "runs", case.name)
    result = {}
    t0 = time.perf_counter()

    def replay(name, protocol, extra):
        try:
            return bench.replay(d, os.path.join(runs, name), protocol, flags + extra)
        except subprocess.CalledProcessError as e:
            raise RuntimeError(f"{family}/{case.name}: {' '.join(e.cmd)} exited {e.returncode}: {e.stderr.strip()}")
    if compare_n is not None:
        compare = flags_a + ["--compare-trials", str(compare_n)]
        result["same-state"] = same_state(replay("same-state", "oracle", compare))
    for protocol in PROTOCOLS:
        result[protocol] = paired(replay(f"{protocol}/A", protocol, flags_a),
                                  replay(f"{protocol}/B", protocol, flags_b), os.path.join(d, "candidates.csv"))
    for comparison, rows in result.items():
        for r in rows:
            r.update(family=family, comparison=comparison, case=case.name, mode=mode)
    print(f"  {family}/{case.name}: agree " + ", ".join(
        f"{k} {sum(r['a_accepted'] == r['b_accepted'] for r in v)}/{len(v)}" for k, v in result.items()) +
        f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    return result


def summarise(rows, n_of):
    """The summary row of some paired rows; n_of(row): the N of B (None: B is --b-args)."""
    agree = [r["a_accepted"] == r["b_accepted"] for r in rows]
    trial = [r for r in rows if r["a_trial"] or r["b_trial"]]
    both = [r for r in rows if r["a_scored"] and r["b_scored"]]
    d = [abs(r["b_score"] - r["a_score"]) for r in both]
    out = {"cases": len({(r["family"], r["case"]) for r in rows}), "candidates": len(rows), "agree": sum(agree),
           "agree_pct": 100.0 * np.mean(agree) if rows else float("nan"),
           "trialled": len(trial),
           "trialled_agree_pct": 100.0 * np.mean([r["a_accepted"] == r["b_accepted"] for r in trial])
           if trial else float("nan"),
           "condensable": float("nan") if any(n_of(r) is None for r in rows) else
           sum(r["a_trial"] and r["a_window"] > n_of(r) for r in rows),
           "scored": len(both), "dscore_median": bench.percentile(d, 50), "dscore_p99": bench.percentile(d, 99),
           "dscore_max": max(d) if d else float("nan")}
    for p, q in (("a", "b"), ("b", "a")):
        only = [r for r in rows if r[f"{p}_accepted"] and not r[f"{q}_accepted"]]
        out.update({f"{p}_only": len(only), f"{p}_only_false": sum(r["label"] == "false" for r in only)})
    out["gate_differs"] = sum(r["a_accepted"] != r["b_accepted"] and r["a_trial"] != r["b_trial"] for r in rows)
    for p in ("a", "b"):
        ms = [r[f"{p}_ms"] for r in rows]
        out.update({f"{p}_ms_p50": bench.percentile(ms, 50), f"{p}_ms_p99": bench.percentile(ms, 99),
                    f"{p}_ms_max": max(ms) if ms else float("nan")})
    for q in ("p50", "p99"):
        out[f"ratio_{q}"] = methods.ratio(out[f"b_ms_{q}"], out[f"a_ms_{q}"])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", choices=("test", "tuning"), default="test", help="which cases (roverlib/splits.py)")
    ap.add_argument("--quick", action="store_true", help="each family's CI subset (as its own --quick)")
    ap.add_argument("--families", default="poc,real,posegraph", help="comma-separated, of poc, real, posegraph")
    ap.add_argument("--cases", help="only these case names (comma-separated, any family)")
    ap.add_argument("--condense-min-window", type=int,
                    help="N of run B (default: condense_min_window of the case's shipped YAML)")
    ap.add_argument("--a-args", help='rover_replay flags of run A instead of "--condense_min_window 0"')
    ap.add_argument("--b-args", help='rover_replay flags of run B instead of "--condense_min_window N" '
                    '(e.g. a stand-in pair: --a-args "" --b-args "--max_iterations 49")')
    ap.add_argument("--decision", choices=("metric", "chi2", "revisit"),
                    help="as the families' --decision (default: the YAML's; chi2 runs no trial: A and B agree)")
    ap.add_argument("--gate-off", action="store_true",
                    help="innovation gate off in A and B (bench.GATE_OFF): every candidate gets a trial")
    ap.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "agreement"))
    a = ap.parse_args(argv)
    families = [f for f in a.families.split(",") if f]
    unknown = set(families) - set(FAMILIES)
    if unknown:
        ap.error(f"unknown families {sorted(unknown)}; choose from {', '.join(FAMILIES)}")
    chosen = [(f, c) for f in families
              for c in bench.select_cases(f, argparse.Namespace(split=a.split, quick=a.quick, cases=None))]
    if a.cases:
        names = set(a.cases.split(","))
        missing = names - {c.name for _, c in chosen}
        if missing:
            ap.error(f"no {a.split}{' --quick' if a.quick else ''} case of {', '.join(families)} is named "
                     f"{', '.join(sorted(missing))}")
        chosen = [(f, c) for f, c in chosen if c.name in names]

    gate = [str(v) for v in bench.GATE_OFF] if a.gate_off else []
    flags_a = gate + (shlex.split(a.a_args) if a.a_args is not None else ["--condense_min_window", "0"])
    n_env = {}  # environment -> N of run B
    if a.b_args is None:
        for env in sorted({c.environment for _, c in chosen}):
            n = a.condense_min_window
            if n is None:
                n = bench.shipped_config(env).get("condense_min_window")
            if not n:
                sys.exit(f"config/rover_{env}.yaml sets no condense_min_window > 0 (N = {n}): "
                         "pass --condense-min-window N (or a stand-in pair with --a-args/--b-args)")
            n_env[env] = int(n)

    def flags_b(case):
        return gate + (shlex.split(a.b_args) if a.b_args is not None else
                       ["--condense_min_window", str(n_env[case.environment])])

    replay = bench.tool("rover_replay")
    help_text = subprocess.run([replay, "--help"], capture_output=True, text=True).stdout
    if "--condense_min_window" in flags_a + [f for _, c in chosen for f in flags_b(c)] and \
            "--condense_min_window" not in help_text:
        sys.exit(f"{replay} has no --condense_min_window yet: build the package first, or compare a stand-in "
                 "pair with --a-args/--b-args")
    # same-state: A's flags plus --compare-trials N (needs the condense flags, not a stand-in A)
    same = bool(n_env) and a.a_args is None and "--compare-trials" in help_text
    stamp = build_stamp(replay)
    max_loops = posegraph.QUICK_MAX_LOOPS if a.quick else None
    n_text = ", ".join(f"{e}: N = {n}" for e, n in n_env.items())
    runs_text = f"A: {' '.join(flags_a) or '(no extra flags)'}; B: " + \
        (" ".join(gate + [a.b_args]) if a.b_args is not None else " ".join(gate + ["--condense_min_window N"]) +
         f" ({n_text})")
    print(f"agreement: {len(chosen)} cases ({', '.join(families)}, {a.split}{' quick' if a.quick else ''}); "
          f"{runs_text}", flush=True)
    t0 = time.perf_counter()
    os.makedirs(a.out, exist_ok=True)
    with ProcessPoolExecutor(max_workers=max(1, a.jobs)) as pool:
        results = list(pool.map(run_case, [(f, c, a.out, flags_a, flags_b(c), n_env[c.environment] if same else None,
                                            bench.decision_args(a), max_loops) for f, c in chosen]))
    seconds = time.perf_counter() - t0
    rebuilt = build_stamp(replay) != stamp

    env_of = {(f, c.name): c.environment for f, c in chosen}

    def n_of(r):
        return n_env.get(env_of[(r["family"], r["case"])])

    summary, disagreements = [], []
    comparisons = [k for k in COMPARISONS if k in results[0]] if results else []
    for comparison in comparisons:
        every = [r for res in results for r in res[comparison]]
        groups = []
        for f in families:
            rows = [r for r in every if r["family"] == f]
            modes = sorted({r["mode"] for r in rows})
            # a family with 4-DoF and 6-DoF cases (real, posegraph): each mode too
            groups += [(f, rows)] + ([(f"{f} {m}", [r for r in rows if r["mode"] == m]) for m in modes]
                                     if len(modes) > 1 else [])
        for family, rows in groups + ([("all", every)] if len(families) > 1 else []):
            if rows:
                summary.append({"family": family, "comparison": comparison, **summarise(rows, n_of)})
        disagreements += [r for r in every if r["a_accepted"] != r["b_accepted"]]
    per_case = []
    for comparison in comparisons:
        by_case = {}
        for r in (r for res in results for r in res[comparison]):
            by_case.setdefault((r["family"], r["case"], r["mode"]), []).append(r["a_accepted"] == r["b_accepted"])
        per_case += [{"family": f, "case": c, "mode": m, "comparison": comparison, "candidates": len(v),
                      "agree": sum(v), "agree_pct": 100.0 * np.mean(v)} for (f, c, m), v in by_case.items()]
    bench.write_csv(per_case, os.path.join(a.out, "cases.csv"))
    below = [r for r in per_case if r["agree_pct"] < 99.5]
    bench.write_csv(summary, os.path.join(a.out, "summary.csv"))
    with open(os.path.join(a.out, "disagreements.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[k for k, _, _ in DISAGREEMENT_COLUMNS] + ["a_ms", "b_ms"],
                           extrasaction="ignore")
        w.writeheader()
        w.writerows(disagreements)
    notes = [f"split: {a.split}{' (quick)' if a.quick else ''}; cases: roverlib/splits.py, built by each family's "
             "setup()",
             f"{runs_text}; both after the family's ROVER flags (shipped YAML, mode, overrides, "
             "--time_budget_ms 0)",
             "same-state: both trials of each candidate against the same graph and X (rover_replay "
             "--compare-trials N in an oracle run at A's settings)" +
             ("" if same else ": not run (needs N and a rover_replay with --compare-trials; not with --a-args)"),
             "oracle: runs A and B each commit only the true-labelled candidates (each adopts its own trial "
             "solutions, so X and the gate can differ); sequential: each commits what it accepts "
             "(disagreements can cascade)",
             "A-only acc: accepted by A, rejected by B ((false): of them labelled false); gate differs: "
             "disagreements where one run had a trial and the other none (the innovation gate, on estimates that "
             "differ by the runs' earlier trial solutions)",
             "agree % (trials): over the candidates with a trial solve in A or B (verdict accepted, "
             "score_above_threshold or not_converged; the innovation gate rejects others before any trial); "
             "trials > N kf: A's trials whose window has more than N keyframes (the ones B condenses; 6-DoF "
             "too since the 6-DoF condensed trial); "
             "|dscore|: over candidates scored in both [m]",
             "ms: elapsed_ms of every candidate; B/A: ratio of the percentiles, both measured in this run "
             f"(--jobs {a.jobs}; same-state: the two trials of a candidate back to back; else A's and B's runs "
             "of a case back to back)",
             f"run time: {seconds:.0f} s" + ("; WARNING: rover_replay was rebuilt during the run, A and B may "
                                             "come from different builds" if rebuilt else "")]
    shown = f"all {len(disagreements)}" if len(disagreements) <= SHOWN else \
        f"the first {SHOWN} of {len(disagreements)}"
    bench.report_tables([(f"Decisions, {k}", [r for r in summary if r["comparison"] == k], COLUMNS)
                         for k in comparisons] +
                        [("Cases below 99.5 % (every case and comparison in cases.csv)", below, CASE_COLUMNS)] +
                        [(f"Disagreements ({shown}; every one in disagreements.csv)", disagreements[:SHOWN],
                          DISAGREEMENT_COLUMNS)], a.out, notes)
    for n in notes:
        print(f"- {n}")
    for r in summary:
        if r["family"] in families:
            print(f"AGREEMENT {r['family']} {r['comparison']}: {r['agree']}/{r['candidates']} = "
                  f"{r['agree_pct']:.2f} % ({'>=' if r['agree_pct'] >= 99.5 else 'below'} 99.5 %)")
    for comparison in comparisons:
        rows = [r for r in per_case if r["comparison"] == comparison]
        print(f"AGREEMENT per case, {comparison}: {sum(r['agree_pct'] >= 99.5 for r in rows)} of {len(rows)} "
              f"cases >= 99.5 %" + "".join(f"; {r['family']}/{r['case']} {r['agree']}/{r['candidates']}"
                                           for r in rows if r["agree_pct"] < 99.5))
    print(f"wrote {a.out}/summary.md, summary.csv, cases.csv, disagreements.csv")
    return 0


if __name__ == "__main__":
    sys.exit(main())
