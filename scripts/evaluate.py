#!/usr/bin/env python3
"""Evaluates a verdict log against labels: average precision (AP), maximum recall at 100 %
precision (MR), precision/recall of the verifier's own decisions, a PR-curve PNG, and, given
trajectories, ATE and temporal ATE against ground truth.

  evaluate.py --verdicts verdicts.csv --labels candidates.csv [--out DIR]
              [--groundtruth gt.tum --trajectory NAME=est.tum ...] [--align se3|sim3|none]
  evaluate.py --run REPLAY_OUT_DIR --labels SCENARIO_DIR [--out DIR]

--verdicts: a verdict CSV (rover_replay's verdicts.csv or the loop_fusion adapter's
~verdict_log). --labels: a scenario's candidates.csv (or its directory), or any CSV with the
columns query_index, match_index, label. --run takes everything from an output directory of
rover_replay (verdicts.csv, groundtruth.tum, odometry/verified/loop_fusion_*.tum and, if
written with --snapshots K, the temporal ATE over those K times).

Conventions (as GV-Bench): positives are true loops, ranked by -score; candidates without a
finite score (not_converged, time_budget_exceeded, invalid_input, no_trajectory_prior) rank
last. Run it with the venv's Python (./scripts/bench.sh evaluate ... does).

Malformed input (an empty or truncated verdict log, a label that is not an integer, a missing
column, a --run directory without ground truth) ends with one line
"evaluate.py: error: FILE:LINE: what" and exit status 2. A UTF-8 byte-order mark is ignored."""
import argparse
import csv
import json
import os
import sys


from roverlib import bench, metrics  # noqa: E402


class InputError(Exception):
    """Malformed input; the message names the file and, where there is one, the line."""


VERDICT_COLUMNS = ("query_index", "match_index", "accepted", "reason", "score")
LABEL_COLUMNS = ("query_index", "match_index", "label")


def _csv_rows(path, required, what):
    """[(line number, {column: value})] of a CSV file with a header; '#' comments and blank
    lines are skipped, a byte-order mark is ignored."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            lines = [(n, line) for n, line in enumerate(f, 1) if line.strip() and not line.lstrip().startswith("#")]
    except UnicodeDecodeError as e:
        raise InputError(f"{path}: not a text file ({e.reason})")
    except OSError as e:
        raise InputError(f"{path}: cannot read the {what}: {e.strerror}")
    if not lines:
        raise InputError(f"{path}: the {what} is empty (not even a header)")
    rows = list(csv.reader([line for _, line in lines]))
    header = [c.strip() for c in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(f"{path}:{lines[0][0]}: not a {what}: no column {', '.join(missing)} "
                         f"(the header has {', '.join(header[:8])}{', ...' if len(header) > 8 else ''})")
    out = []
    for (n, _), values in zip(lines[1:], rows[1:]):
        if len(values) != len(header):
            raise InputError(f"{path}:{n}: {len(values)} fields, the header has {len(header)}")
        out.append((n, dict(zip(header, values))))
    return out


def _int(path, n, row, column, allowed=None):
    value = row[column].strip()
    try:
        i = int(value)
    except ValueError:
        raise InputError(f"{path}:{n}: {column} '{value}' is not an integer")
    if allowed is not None and i not in allowed:
        raise InputError(f"{path}:{n}: {column} {i} is not one of {', '.join(map(str, allowed))}")
    return i


def read_verdicts(path):
    """The rows of a verdict log, checked (metrics.read_verdicts' result, with file:line errors)."""
    rows = _csv_rows(path, VERDICT_COLUMNS, "verdict log")
    if not rows:
        raise InputError(f"{path}: the verdict log has no verdicts (only a header)")
    for n, r in rows:
        for column in ("query_index", "match_index"):
            r[column] = str(_int(path, n, r, column))
        r["accepted"] = str(_int(path, n, r, "accepted", (0, 1)))
    return [r for _, r in rows]


def read_labels(path):
    """{(query_index, match_index): [label, ...]} (metrics.read_labels' result, checked)."""
    out = {}
    for n, r in _csv_rows(path, LABEL_COLUMNS, "label file"):
        key = (_int(path, n, r, "query_index"), _int(path, n, r, "match_index"))
        out.setdefault(key, []).append(_int(path, n, r, "label", (-1, 0, 1)))
    return out


def evaluate(verdicts, labels, out=None, groundtruth=None, trajectories=(), align="se3", run=None,
             title="", quiet=False):
    """Returns a dict of the metrics (and writes metrics.json + pr_curve.png into `out`).
    Raises InputError for malformed input."""
    if run and not os.path.exists(os.path.join(run, "groundtruth.tum")):
        raise InputError(f"{run}: no groundtruth.tum: --run needs an output directory of rover_replay on a "
                         f"scenario with ground truth (use --verdicts for the verdicts alone)")
    j = metrics.join(read_verdicts(verdicts), read_labels(labels))
    r = metrics.ranking_metrics(j["label"], j["score"])
    d = metrics.decision_metrics(j["label"], j["accepted"])
    result = {"candidates": r["n"], "true": r["positives"], "false": r["negatives"], "ap": r["ap"],
              "mr": r["mr"], **d, "trajectories": {}}
    if run:
        for name, (a, t) in bench.trajectory_errors(run, align).items():
            result["trajectories"][name] = {"ate": a, "tate": t}
    elif groundtruth:
        for name, path in trajectories:
            result["trajectories"][name] = {"ate": metrics.ate(groundtruth, path, align), "tate": float("nan")}
    if not quiet:
        print(f"{r['n']} labelled candidates ({r['positives']} true, {r['negatives']} false)")
        print(f"AP {r['ap']:.4f}  MR (max recall at precision 1) {r['mr']:.4f}")
        print(f"decisions: TP {d['tp']} FP {d['fp']} TN {d['tn']} FN {d['fn']}  "
              f"precision {d['precision']:.3f} recall {d['recall']:.3f}")
        for name, m in result["trajectories"].items():
            print(f"ATE {name}: {m['ate']:.4f} m" + (f"  tATE {m['tate']:.4f} m" if m["tate"] == m["tate"] else ""))
    if out:
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "metrics.json"), "w") as f:
            json.dump(result, f, indent=1)
        metrics.plot_pr([(title or "verifier", r)], os.path.join(out, "pr_curve.png"), title)
        if not quiet:
            print(f"wrote {os.path.join(out, 'metrics.json')} and pr_curve.png")
    return result


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--verdicts", help="verdict CSV")
    src.add_argument("--run", help="output directory of rover_replay")
    ap.add_argument("--labels", required=True, help="candidates.csv (or scenario directory) with labels")
    ap.add_argument("--groundtruth", help="TUM ground truth (with --verdicts)")
    ap.add_argument("--trajectory", action="append", default=[], metavar="NAME=TUM",
                    help="estimated trajectory to score against --groundtruth (repeatable)")
    ap.add_argument("--align", default="se3", choices=("se3", "sim3", "none"))
    ap.add_argument("--title", default="")
    ap.add_argument("--out", help="directory for metrics.json and pr_curve.png")
    a = ap.parse_args(argv)
    labels = os.path.join(a.labels, "candidates.csv") if os.path.isdir(a.labels) else a.labels
    verdicts = os.path.join(a.run, "verdicts.csv") if a.run else a.verdicts
    trajs = []
    for t in a.trajectory:
        if "=" not in t:
            ap.error(f"--trajectory {t}: expected NAME=FILE")
        trajs.append(tuple(t.split("=", 1)))
    if trajs and not a.groundtruth:
        ap.error("--trajectory needs --groundtruth")
    try:
        evaluate(verdicts, labels, a.out, a.groundtruth, trajs, a.align, a.run, a.title)
    except (InputError, OSError, ValueError) as e:
        # One line, no traceback: what is wrong with which input (ValueError: trajectory files).
        message = (str(e).strip().splitlines() or [type(e).__name__])[0]
        print(f"evaluate.py: error: {message}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
