"""Trajectory alignment and ATE, the Python side of core/alignment.h: Umeyama's least-squares
S* = {R, t, s} that maps the positions `moved` onto `reference` (3 x N each, paired by column),
and the RMSE of the aligned positions. The one implementation of both in Python: the demo's
summary (roverlib/bag_replay.py, the system Python of the ROS nodes) and the evaluation
(roverlib/metrics.ate, which pairs evo trajectories by stamp first) call it. numpy only."""
import numpy as np

ALIGNMENTS = ("se3", "sim3", "none")


class AlignmentError(ValueError):
    """The positions cannot be aligned: sizes differ, or they have too little spread (all on one
    line or one point: the rotation about that line is not determined)."""


def umeyama(moved, reference, with_scale=False):
    """(R, t, s) minimising sum_i ||reference_i - (s R moved_i + t)||^2 (Umeyama 1991, eqs.
    34-43, as evo's geometry.umeyama_alignment); s = 1 without with_scale. Raises
    AlignmentError when the shapes differ or the cross-covariance has rank < 2."""
    x = np.asarray(moved, dtype=float)
    y = np.asarray(reference, dtype=float)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] == 0:
        raise AlignmentError(f"cannot align positions of shapes {x.shape} and {y.shape}")
    m, n = x.shape
    mean_x, mean_y = x.mean(axis=1), y.mean(axis=1)
    dx, dy = x - mean_x[:, None], y - mean_y[:, None]
    sigma_x = np.linalg.norm(dx) ** 2 / n
    u, d, vt = np.linalg.svd(dy @ dx.T / n)
    if np.count_nonzero(d > np.finfo(d.dtype).eps) < m - 1:
        raise AlignmentError("degenerate covariance rank (positions on one line or one point): "
                             "Umeyama alignment is not possible")
    S = np.eye(m)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:
        S[m - 1, m - 1] = -1.0  # a rotation, not a reflection
    R = u @ S @ vt
    s = float(np.trace(np.diag(d) @ S) / sigma_x) if with_scale else 1.0
    return R, mean_y - s * R @ mean_x, s


def ate(reference, moved, align="se3"):
    """ATE [m]: RMSE of the positions `moved` (3 x N) against `reference` (3 x N, same order)
    after aligning moved to reference: se3 (R, t), sim3 (R, t, scale) or none. Raises
    AlignmentError where umeyama() does, ValueError for another `align`."""
    x = np.asarray(moved, dtype=float)
    y = np.asarray(reference, dtype=float)
    if align in ("se3", "sim3"):
        R, t, s = umeyama(x, y, with_scale=align == "sim3")
        x = s * R @ x + t[:, None]
    elif align != "none":
        raise ValueError(f"unknown alignment {align} (one of {', '.join(ALIGNMENTS)})")
    elif x.shape != y.shape:
        raise AlignmentError(f"cannot compare positions of shapes {x.shape} and {y.shape}")
    return float(np.sqrt(np.mean(np.sum((y - x) ** 2, axis=0))))
