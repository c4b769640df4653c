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

The verdict log must hold exactly one verdict per candidate of the label file: the figures
describe a run only if no verdict was lost and none belongs to another run. A node's log (one
row when a candidate is verified, another when a held one is released or dropped or an
accepted one revoked: columns final, decision) is read as each candidate's final verdict, as
rover_replay writes it; the later decisions about one pair (a candidate proposed again while
held) complete its rows first in, first out. Refused, with one line "evaluate.py: error:
FILE[:LINE]: what" and exit status 2 (nothing is scored):
- malformed input: an empty or truncated verdict log, a label or index that is not an integer,
  a missing column, a --run directory without ground truth, a TUM ground truth or trajectory
  with a value that is not finite or a repeated stamp;
- a score that is not a number, or a negative one (a score is an RMSE or a squared distance:
  -1e308 would rank first); "nan" and "inf" (no score) rank last;
- candidates of the label file without a verdict (lost verdicts: a run that stopped early, a
  full disk), verdicts for candidates the label file does not have (another run's log, a
  repeated row, a log appended to twice).
A candidate still held when the log ends (a host that ended without its final verdict) is scored
as not accepted, with a warning on stderr.
Label -1 (unknown) candidates need their verdict too; they are not scored. metrics.json is
strict JSON: an undefined figure (AP without a false candidate, precision of no accepted loop)
is null. A UTF-8 byte-order mark is ignored."""
import argparse
import csv
import json
import math
import os
import sys


from roverlib import bench, metrics, reasons  # noqa: E402


class InputError(Exception):
    """Malformed input; the message names the file and, where there is one, the line."""


VERDICT_COLUMNS = ("query_index", "match_index", "accepted", "reason", "score")
LABEL_COLUMNS = ("query_index", "match_index", "label")
# A node's later decision about a candidate it verified earlier (LoopVerdict.msg, decision).
LATER = {"release": "held", "drop": "held", "revoke": "accepted"}


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


def _score(path, n, row):
    """The score column as a float: a number >= 0, or nan / inf (no score: ranked last)."""
    text = row["score"].strip()
    try:
        score = float(text)
    except ValueError:
        raise InputError(f"{path}:{n}: score '{text}' is not a number")
    if score < 0.0:
        raise InputError(f"{path}:{n}: score {text} is negative (a score is an RMSE or a squared distance; "
                         f"it would rank first)")
    return score


def read_verdict_rows(path):
    """[(line number, row)] of a verdict log, checked: integer indices, accepted 0/1, a
    numeric score (read_verdicts' checks, row by row)."""
    rows = _csv_rows(path, VERDICT_COLUMNS, "verdict log")
    if not rows:
        raise InputError(f"{path}: the verdict log has no verdicts (only a header)")
    for n, r in rows:
        for column in ("query_index", "match_index"):
            r[column] = str(_int(path, n, r, column))
        r["accepted"] = str(_int(path, n, r, "accepted", (0, 1)))
        _score(path, n, r)
        if "final" in r:
            r["final"] = str(_int(path, n, r, "final", (0, 1)))
        decision = r.get("decision", "verify").strip() or "verify"
        if decision != "verify" and decision not in LATER:
            raise InputError(f"{path}:{n}: decision '{decision}' is not one of verify, {', '.join(LATER)}")
        r["decision"] = decision
    return rows


def _held(row):
    return row.get("final", "1") == "0" or row["reason"] == reasons.DEFERRED


def final_verdicts(path, rows):
    """One (line, row) per candidate, in the order they were verified: a node's later decision
    (release or drop of a held candidate, revoke of an accepted loop) replaces accepted, reason
    and detail of the candidate's row, which keeps its score (as rover_replay's one row per
    candidate has it). A later-decision row without such an earlier row is the candidate's only
    row (rover_replay's form). A candidate still held when the log ends is dropped, as
    rover_replay drops it at the end of a run (not accepted), with a warning on stderr."""
    out = []
    # (query, match) -> {"held": [index of out, ...], "accepted": [...]}, oldest first: the same
    # loop proposed again while held is decided copy by copy, in the order they came (a host's
    # later decisions about one pair come first in, first out).
    open_ = {}
    for n, r in rows:
        key = (int(r["query_index"]), int(r["match_index"]))
        later = LATER.get(r["decision"])
        slots = open_.setdefault(key, {"held": [], "accepted": []})
        if later and slots[later]:
            i = slots[later].pop(0)
            first = out[i][1]
            out[i] = (out[i][0], dict(first, accepted=r["accepted"], reason=r["reason"], detail=r.get("detail", ""),
                                      final="1", decision=r["decision"]))
            if r["accepted"] == "1":
                slots["accepted"].append(i)
            continue
        out.append((n, dict(r)))
        if _held(r):
            slots["held"].append(len(out) - 1)
        elif r["accepted"] == "1":
            slots["accepted"].append(len(out) - 1)
    undecided = [i for i, (_, r) in enumerate(out) if _held(r)]
    if undecided:
        n, r = out[undecided[0]]
        print(f"evaluate.py: warning: {path}:{n}: {len(undecided)} candidate(s) still held when the log ends (the "
              f"first: loop {r['query_index']} -> {r['match_index']}; a host that ended without their final verdict: "
              f"loop_fusion's abort, a killed node): scored as not accepted, as the run never used them",
              file=sys.stderr)
        for i in undecided:
            n, r = out[i]
            out[i] = (n, dict(r, accepted="0", reason=reasons.UNCONFIRMED, final="1", decision="drop"))
    return out


def read_verdicts(path):
    """Each candidate's final verdict row of a verdict log, checked (final_verdicts)."""
    return [r for _, r in final_verdicts(path, read_verdict_rows(path))]


def check_correspondence(verdicts_path, candidates, labels_path, labels):
    """Refuses (InputError) a verdict log that does not hold exactly one verdict per candidate
    of the label file: lost verdicts, verdicts for pairs the label file does not have or more
    verdicts for a pair than it has candidates of it (a repeated row, two runs in one log)."""
    by_key = {}
    for n, r in candidates:
        by_key.setdefault((int(r["query_index"]), int(r["match_index"])), []).append(n)
    lost, extra = [], []
    for key, labs in labels.items():
        missing = len(labs) - len(by_key.get(key, []))
        lost += [key] * max(0, missing)
    for key, lines in by_key.items():
        expected = len(labels.get(key, []))
        extra += [(n, key) for n in lines[expected:]]
    if not lost and not extra:
        return
    n_labels = sum(len(v) for v in labels.values())
    parts = []
    if lost:
        q, m = lost[0]
        parts.append(f"{len(lost)} of the {n_labels} candidates in {labels_path} have no verdict (lost verdicts; the "
                     f"first: loop {q} -> {m})")
    if extra:
        n, (q, m) = min(extra)
        known = (q, m) in labels
        why = (f"more verdicts for loop {q} -> {m} than {labels_path} has candidates of it: a repeated row or "
               f"two runs in one log" if known else f"loop {q} -> {m} is not in {labels_path}: another run's log "
               f"or the wrong label file")
        parts.append(f"{len(extra)} verdict(s) for no candidate of the label file (the first at line {n}: {why})")
    raise InputError(f"{verdicts_path}: " + "; ".join(parts) + "; the figures would not describe the run: not scored")


def read_labels(path):
    """{(query_index, match_index): [label, ...]} (metrics.read_labels' result, checked)."""
    out = {}
    for n, r in _csv_rows(path, LABEL_COLUMNS, "label file"):
        key = (_int(path, n, r, "query_index"), _int(path, n, r, "match_index"))
        out.setdefault(key, []).append(_int(path, n, r, "label", (-1, 0, 1)))
    return out


TUM_FIELDS = ("stamp", "x", "y", "z", "qx", "qy", "qz", "qw")


def check_tum(path, what):
    """Refuses (InputError, FILE:LINE) a TUM trajectory with a line that is not 8 numbers, a
    value that is not finite or a stamp that repeats: the ATE against it would be NaN, fail in
    the alignment ("SVD did not converge"), or pair a pose with the wrong one."""
    seen = {}
    try:
        with open(path, encoding="utf-8-sig") as f:
            lines = list(enumerate(f, 1))
    except (OSError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: cannot read the {what}: {getattr(e, 'strerror', None) or e}")
    for n, line in lines:
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        fields = text.replace(",", " ").split()
        if len(fields) != len(TUM_FIELDS):
            raise InputError(f"{path}:{n}: {len(fields)} values, a line of a TUM {what} has 8 "
                             f"({' '.join(TUM_FIELDS)})")
        for name, value in zip(TUM_FIELDS, fields):
            try:
                number = float(value)
            except ValueError:
                raise InputError(f"{path}:{n}: {name} '{value}' is not a number")
            if not math.isfinite(number):
                raise InputError(f"{path}:{n}: {name} '{value}' is not finite")
        stamp = float(fields[0])
        if stamp in seen:
            raise InputError(f"{path}:{n}: stamp {fields[0]} repeats line {seen[stamp]} (two poses at one time)")
        seen[stamp] = n


def strict_json(value):
    """value with every NaN or infinite float as None: metrics.json is JSON (RFC 8259 has no NaN)."""
    if isinstance(value, dict):
        return {k: strict_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict_json(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def evaluate(verdicts, labels, out=None, groundtruth=None, trajectories=(), align="se3", run=None,
             title="", quiet=False):
    """Returns a dict of the metrics (and writes metrics.json + pr_curve.png into `out`).
    Raises InputError for malformed input."""
    if run and not os.path.exists(os.path.join(run, "groundtruth.tum")):
        raise InputError(f"{run}: no groundtruth.tum: --run needs an output directory of rover_replay on a "
                         f"scenario with ground truth (use --verdicts for the verdicts alone)")
    if run:
        check_tum(os.path.join(run, "groundtruth.tum"), "ground truth")
    elif groundtruth:
        check_tum(groundtruth, "ground truth")
        for _, path in trajectories:
            check_tum(path, "trajectory")
    candidates = final_verdicts(verdicts, read_verdict_rows(verdicts))
    label_rows = read_labels(labels)
    check_correspondence(verdicts, candidates, labels, label_rows)
    j = metrics.join([r for _, r in candidates], label_rows)
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
        print(f"AP {bench.fmt(r['ap'], '.4f')}  MR (max recall at precision 1) {bench.fmt(r['mr'], '.4f')}")
        print(f"decisions: TP {d['tp']} FP {d['fp']} TN {d['tn']} FN {d['fn']}  "
              f"precision {bench.fmt(d['precision'], '.3f')} recall {bench.fmt(d['recall'], '.3f')}")
        for name, m in result["trajectories"].items():
            print(f"ATE {name}: {m['ate']:.4f} m" + (f"  tATE {m['tate']:.4f} m" if m["tate"] == m["tate"] else ""))
    if out:
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "metrics.json"), "w") as f:
            json.dump(strict_json(result), f, indent=1, allow_nan=False)
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
