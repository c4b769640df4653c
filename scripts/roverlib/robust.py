"""Batch back ends from gtsam on a roverlib.problem.Problem (the same graph and covariances for
every method): what a user would pick instead of verifying loops one by one, and the converged
back end every selection is also solved with.

  lm      Levenberg-Marquardt, least squares (no robustness): the reference with only true
          loops, or the back end after a verifier's selection ("converged back end");
  gnc     graduated non-convexity (GncLMOptimizer, truncated least squares, odometry and the
          prior known inliers, inlier threshold at chi2 probability 0.99); each GNC step's LM
          is limited to 20 iterations (gtsam's default 100 took 5 min on parking-garage with
          200 + 200 loops, as every step ran to the limit; on manhattan3500 the ATE changed by
          1.4 %). GNC draws no random numbers: given the same graph it is deterministic
          (test_robust.py runs it twice);
  dcs     dynamic covariance scaling (Agarwal et al. 2013, Phi = 1) on the loop edges, LM.

A loop counts as accepted by GNC if its final weight is > 0.5, by DCS if its Gaussian chi2 at
the solution is below the 0.99 quantile.
"""
import numpy as np

from . import geometry as g

CHI2_PROBABILITY = 0.99
GNC_LM_ITERATIONS = 20
LM_ITERATIONS = 100


def _gtsam():
    import gtsam
    return gtsam


def to_gtsam_pose(T, dim):
    gtsam = _gtsam()
    if dim == 2:
        return gtsam.Pose2(float(T[0, 3]), float(T[1, 3]), g.yaw_of(T[:3, :3]))
    return gtsam.Pose3(gtsam.Rot3(np.asarray(T[:3, :3], dtype=float)), np.asarray(T[:3, 3], dtype=float))


def from_gtsam_pose(p, dim):
    if dim == 2:
        return g.pose(g.rot_z(p.theta()), [p.x(), p.y(), 0.0])
    return np.asarray(p.matrix())


def from_values(values, n, dim, first=0):
    at = values.atPose2 if dim == 2 else values.atPose3
    return [from_gtsam_pose(at(i), dim) for i in range(first, first + n)]


def noise(cov):
    return _gtsam().noiseModel.Gaussian.Covariance(np.asarray(cov, dtype=float))


def between(e, dim, kernel=None):
    gtsam = _gtsam()
    model = noise(e.cov)
    if kernel is not None:
        model = gtsam.noiseModel.Robust.Create(kernel, model)
    factor = gtsam.BetweenFactorPose2 if dim == 2 else gtsam.BetweenFactorPose3
    return factor(e.a, e.b, to_gtsam_pose(e.T, dim), model)


def build(problem, loops, initial, loop_kernel=None):
    """(NonlinearFactorGraph, Values, loop factor indices, known-inlier indices): a tight prior
    on vertex 0, the odometry edges, and `loops` (problem.Edge), optionally wrapped in a robust
    kernel (a gtsam mEstimator). The graph holds the vertices of `initial` (a prefix: the
    keyframes so far; every loop must be inside it)."""
    gtsam = _gtsam()
    dim = problem.dim
    Prior = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    fg = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for i, T in enumerate(initial):
        values.insert(i, to_gtsam_pose(T, dim))
    fg.add(Prior(0, to_gtsam_pose(initial[0], dim), gtsam.noiseModel.Isotropic.Sigma(3 if dim == 2 else 6, 1e-4)))
    known = [0]
    for e in problem.odometry[:len(initial) - 1]:
        known.append(fg.size())
        fg.add(between(e, dim))
    loop_idx = []
    for e in loops:
        loop_idx.append(fg.size())
        fg.add(between(e, dim, loop_kernel))
    return fg, values, loop_idx, known


def lm_params(max_iterations=LM_ITERATIONS):
    gtsam = _gtsam()
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(max_iterations)
    p.setRelativeErrorTol(1e-6)
    return p


def solve_lm(problem, loops, initial=None):
    """Poses (4x4) of odometry + `loops`, least squares, from `initial` (default: odometry)."""
    gtsam = _gtsam()
    initial = problem.odometry_poses() if initial is None else initial
    fg, values, _, _ = build(problem, loops, initial)
    result = gtsam.LevenbergMarquardtOptimizer(fg, values, lm_params()).optimize()
    return from_values(result, len(initial), problem.dim)


def solve_gnc(problem, loops):
    """(poses, accepted: bool per loop) from GNC-TLS."""
    gtsam = _gtsam()
    fg, values, loop_idx, known = build(problem, loops, problem.odometry_poses())
    params = gtsam.GncLMParams(lm_params(GNC_LM_ITERATIONS))
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(known)
    opt = gtsam.GncLMOptimizer(fg, values, params)
    opt.setInlierCostThresholdsAtProbability(CHI2_PROBABILITY)
    result = opt.optimize()
    w = np.asarray(opt.getWeights())
    return from_values(result, problem.n, problem.dim), [bool(w[i] > 0.5) for i in loop_idx]


def solve_dcs(problem, loops, phi=1.0):
    """(poses, accepted per loop): DCS kernel on the loops; a loop counts as accepted if its
    Gaussian chi2 at the solution is below the 0.99 quantile."""
    gtsam = _gtsam()
    from scipy.stats import chi2
    initial = problem.odometry_poses()
    fg, values, loop_idx, _ = build(problem, loops, initial, gtsam.noiseModel.mEstimator.DCS.Create(phi))
    result = gtsam.LevenbergMarquardtOptimizer(fg, values, lm_params()).optimize()
    plain, _, plain_idx, _ = build(problem, loops, initial)
    limit = chi2.ppf(CHI2_PROBABILITY, problem.dof)
    accepted = [bool(2.0 * plain.at(i).error(result) < limit) for i in plain_idx]
    return from_values(result, problem.n, problem.dim), accepted
