"""Evaluation metrics: ranking metrics of verdicts (AP, MR, PR curves) with scikit-learn, and
trajectory errors (ATE, temporal ATE): evo reads and pairs the trajectories, roverlib/alignment.py
aligns them. Needs the venv of scripts/venv.sh.

Conventions (as GV-Bench): positives are TRUE loops. A verdict's `score` is the decision
function of the verifier with higher = more likely false, so the ranking score handed to
scikit-learn is -score. Candidates without a finite score (verdicts of a reason other than
reasons.SCORED: gate, no convergence, time budget, bad input, ...) rank last (+inf): rejected,
and no evidence for a true loop.

AP = sklearn.metrics.average_precision_score(labels, -score).
MR = maximum recall at 100 % precision = max recall over the points of
     sklearn.metrics.precision_recall_curve(labels, -score) whose precision is 1.0 (0 if the
     top-ranked candidate is false; sklearn's curve always ends in (recall 0, precision 1)).
"""
import csv
import math

import numpy as np

from . import alignment, reasons


# --- verdict logs and labels ---------------------------------------------------------------

def _dict_rows(path):
    with open(path, newline="") as f:
        lines = [l for l in f if l.strip() and not l.lstrip().startswith("#")]
    return list(csv.DictReader(lines))


def read_verdicts(path):
    """Rows of a verdict CSV (rover_replay's verdicts.csv or the node's ~verdict_log)."""
    rows = _dict_rows(path)
    if rows and not {"query_index", "match_index", "accepted", "reason", "score"} <= set(rows[0]):
        raise ValueError(f"{path}: not a verdict log (needs query_index, match_index, accepted, "
                         f"reason, score)")
    return rows


def read_final_verdicts(path):
    """The final verdict of each candidate of a verdict CSV (rows with final=0 are a held
    candidate's deferral; a log without the column has final verdicts only)."""
    return [r for r in read_verdicts(path) if r.get("final", "1") == "1"]


def read_labels(path):
    """{(query_index, match_index): [label, ...]} from a scenario's candidates.csv or any CSV
    with the columns query_index, match_index, label (1 true, 0 false, -1 unknown)."""
    out = {}
    rows = _dict_rows(path)
    if rows and not {"query_index", "match_index", "label"} <= set(rows[0]):
        raise ValueError(f"{path}: needs the columns query_index, match_index, label")
    for r in rows:
        out.setdefault((int(r["query_index"]), int(r["match_index"])), []).append(int(r["label"]))
    return out


def ranking_score(row):
    """The verdict's score [m] or, where it has none (decision chi2), its d2; +inf where the
    verdict has neither to rank by."""
    if row["reason"] not in reasons.SCORED:
        return math.inf
    for key in ("score", "d2"):
        try:
            s = float(row.get(key, ""))
        except (TypeError, ValueError):
            continue
        if math.isfinite(s):
            return s
    return math.inf


def join(verdicts, labels):
    """Labelled verdicts as arrays: dict(label, score, accepted, reason, row). Verdicts of
    candidates with an unknown label (-1 or not in `labels`) are left out. Several candidates
    of one (query, match) pair take their labels in order."""
    pending = {k: list(v) for k, v in labels.items()}
    y, s, acc, reason, kept = [], [], [], [], []
    for r in verdicts:
        key = (int(r["query_index"]), int(r["match_index"]))
        if not pending.get(key):
            continue
        lab = pending[key].pop(0)
        if lab not in (0, 1):
            continue
        y.append(lab)
        s.append(ranking_score(r))
        acc.append(int(r["accepted"]) == 1)
        reason.append(r["reason"])
        kept.append(r)
    return {"label": np.array(y, dtype=int), "score": np.array(s, dtype=float),
            "accepted": np.array(acc, dtype=bool), "reason": np.array(reason, dtype=object),
            "rows": kept}


# --- ranking and decision metrics -------------------------------------------------------------

def _finite_scores(score):
    s = np.asarray(score, dtype=float).copy()
    finite = np.isfinite(s)
    s[~finite] = (s[finite].max() + 1.0) if finite.any() else 1.0  # ranked last, tied
    return s


def ranking_metrics(label, score):
    """AP, MR and the PR curve of detecting true loops (label 1) from score (low = true)."""
    from sklearn.metrics import average_precision_score, precision_recall_curve
    label = np.asarray(label, dtype=int)
    out = {"n": int(label.size), "positives": int(label.sum()), "negatives": int((label == 0).sum())}
    if out["positives"] == 0 or out["negatives"] == 0:
        out.update(ap=float("nan"), mr=float("nan"), precision=np.array([]), recall=np.array([]))
        return out
    decision = -_finite_scores(score)
    precision, recall, _ = precision_recall_curve(label, decision)
    out["ap"] = float(average_precision_score(label, decision))
    out["mr"] = float(recall[precision >= 1.0].max())
    out["precision"], out["recall"] = precision, recall
    return out


def decision_metrics(label, accepted):
    """TP/FP/TN/FN, precision and recall of accept/reject decisions. Precision is NaN (shown
    as "-") when nothing was accepted, recall NaN when there is no true loop: no decision is no
    evidence, and a table must not read 1.0 there."""
    label = np.asarray(label, dtype=int)
    accepted = np.asarray(accepted, dtype=bool)
    tp = int(np.sum(accepted & (label == 1)))
    fp = int(np.sum(accepted & (label == 0)))
    fn = int(np.sum(~accepted & (label == 1)))
    tn = int(np.sum(~accepted & (label == 0)))
    return {"tp": tp, "fp": fp, "tn": tn, "fn": fn,
            "precision": tp / (tp + fp) if tp + fp else float("nan"),
            "recall": tp / (tp + fn) if tp + fn else float("nan")}


def _pr_axes(ax, curves, title):
    for name, m in curves:
        if len(m["recall"]):
            ax.step(m["recall"], m["precision"], where="post",
                    label=f"{name} (AP {m['ap']:.3f}, MR {m['mr']:.2f})")
    ax.set_xlabel("recall (true loops)")
    ax.set_ylabel("precision")
    ax.set_xlim(0.0, 1.02)
    ax.set_ylim(0.0, 1.05)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=9)
    if any(len(m["recall"]) for _, m in curves):  # no curve (AP undefined): no legend
        ax.legend(fontsize=6, loc="lower left")


def plot_pr(curves, path, title=""):
    """curves: [(name, ranking_metrics dict), ...] -> PNG of the precision-recall curves."""
    plot_pr_grid([(title, curves)], path, ncols=1)


def plot_pr_grid(panels, path, ncols=3, suptitle=""):
    """panels: [(title, curves), ...] -> one PNG with a PR plot per panel."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    ncols = min(ncols, len(panels))
    nrows = -(-len(panels) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(4.6 * ncols, 3.9 * nrows), dpi=100, squeeze=False)
    for ax, (title, curves) in zip(axes.flat, panels):
        _pr_axes(ax, curves, title)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    if suptitle:
        fig.suptitle(suptitle, fontsize=10)
    save_figure(fig, path)


def save_figure(fig, path):
    """Lays out, writes and closes a matplotlib figure (every PNG of the benchmarks)."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# --- trajectories ------------------------------------------------------------------------------

def read_tum(path):
    from evo.tools import file_interface
    return file_interface.read_tum_trajectory_file(path)


def trajectory(stamps, positions, quats_xyzw=None):
    """An evo PoseTrajectory3D from stamps, Nx3 positions and Nx4 (x, y, z, w) quaternions."""
    from evo.core.trajectory import PoseTrajectory3D
    positions = np.asarray(positions, dtype=float)
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(positions), 1)) if quats_xyzw is None else np.asarray(quats_xyzw)
    return PoseTrajectory3D(positions_xyz=positions, orientations_quat_wxyz=q[:, [3, 0, 1, 2]],
                            timestamps=np.asarray(stamps, dtype=float))


def ate(reference, estimate, align="se3", max_diff=0.01):
    """ATE RMSE [m] of the positions after aligning `estimate` to `reference`: stamps associated
    within max_diff by evo, then roverlib.alignment.ate (Umeyama SE(3) / Sim(3) or no alignment;
    AlignmentError where the positions cannot be aligned). Trajectories are evo
    PoseTrajectory3D or TUM file paths; neither is modified."""
    from evo.core import sync
    ref = read_tum(reference) if isinstance(reference, str) else reference
    est = read_tum(estimate) if isinstance(estimate, str) else estimate
    ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff)
    return alignment.ate(ref.positions_xyz.T, est.positions_xyz.T, align)


def temporal_ate(reference, snapshots, align="se3", max_diff=0.01):
    """Temporal ATE: the mean of the ATEs of what the system showed at k evenly spaced times,
    each against the ground truth of the keyframes it had by then. `snapshots` is the list of
    those k trajectories (e.g. rover_replay --snapshots K), each holding only the keyframes
    registered so far. A snapshot that cannot be aligned (its keyframes still on one line, e.g.
    the first stretch of a corridor: the rotation about that line is not determined) is left out
    of the mean."""
    ref = read_tum(reference) if isinstance(reference, str) else reference
    values = []
    for s in snapshots:
        try:
            values.append(ate(ref, s, align, max_diff))
        except alignment.AlignmentError:
            continue
    return float(np.mean(values)) if values else float("nan")


def prefixes(traj, k):
    """The first ceil(i * n / k) poses of `traj`, i = 1..k (the odometry as it stood at the same
    times as rover_replay's snapshots)."""
    from evo.core.trajectory import PoseTrajectory3D
    traj = read_tum(traj) if isinstance(traj, str) else traj
    n = traj.num_poses
    out = []
    for i in range(1, k + 1):
        m = -(-i * n // k)
        out.append(PoseTrajectory3D(poses_se3=traj.poses_se3[:m], timestamps=traj.timestamps[:m]))
    return out
