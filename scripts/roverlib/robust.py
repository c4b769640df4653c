"""Batch back ends from gtsam on the same pose graph as the verifier: what a user would pick
instead of verifying loops one by one.

  lm      Levenberg-Marquardt, least squares (no robustness): the reference with only true
          loops, or the back end after the verifier's selection;
  gnc     graduated non-convexity (GncLMOptimizer, truncated least squares, odometry and the
          prior known inliers, inlier threshold at chi2 probability 0.99); each GNC step's LM
          is limited to 20 iterations (gtsam's default 100 took 5 min on parking-garage with
          200 + 200 loops, as every step ran to the limit; on manhattan3500 the ATE changed by
          1.4 %);
  dcs     dynamic covariance scaling (Agarwal et al. 2013, Phi = 1) on the loop edges, LM.

Every edge keeps the information matrix of the g2o file (outliers get the file's loop
information); EDGE_SE3:QUAT information is reordered from g2o's (translation, rotation) to
gtsam's (rotation, translation) tangent order, as gtsam's own g2o reader does.
"""
import numpy as np

from . import geometry as g

CHI2_PROBABILITY = 0.99
GNC_LM_ITERATIONS = 20


def _gtsam():
    import gtsam
    return gtsam


def to_gtsam_pose(T, dim):
    gtsam = _gtsam()
    if dim == 2:
        return gtsam.Pose2(float(T[0, 3]), float(T[1, 3]), g.yaw_of(T[:3, :3]))
    return gtsam.Pose3(gtsam.Rot3(np.asarray(T[:3, :3], dtype=float)), np.asarray(T[:3, 3], dtype=float))


def from_values(values, n, dim):
    out = []
    for i in range(n):
        if dim == 2:
            p = values.atPose2(i)
            out.append(g.pose(g.rot_z(p.theta()), [p.x(), p.y(), 0.0]))
        else:
            out.append(np.asarray(values.atPose3(i).matrix()))
    return out


def noise_model(info, dim):
    gtsam = _gtsam()
    info = np.asarray(info, dtype=float)
    if dim == 3:
        P = np.zeros((6, 6))
        P[:3, 3:] = np.eye(3)
        P[3:, :3] = np.eye(3)
        info = P @ info @ P.T
    return gtsam.noiseModel.Gaussian.Information(info)


def build(graph, loops, initial, loop_kernel=None):
    """(NonlinearFactorGraph, Values, loop factor indices, known-inlier indices): a tight
    prior on vertex 0, the odometry edges, and `loops` (g2o.Edge), optionally wrapped in a
    robust kernel (a gtsam mEstimator)."""
    gtsam = _gtsam()
    dim = graph.dim
    Between = gtsam.BetweenFactorPose2 if dim == 2 else gtsam.BetweenFactorPose3
    Prior = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
    fg = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for i, T in enumerate(initial):
        values.insert(i, to_gtsam_pose(T, dim))
    fg.add(Prior(0, to_gtsam_pose(initial[0], dim), gtsam.noiseModel.Isotropic.Sigma(3 if dim == 2 else 6, 1e-4)))
    known = [0]
    for e in graph.odometry:
        known.append(fg.size())
        fg.add(Between(e.a, e.b, to_gtsam_pose(e.T, dim), noise_model(e.info, dim)))
    loop_idx = []
    for e in loops:
        model = noise_model(e.info, dim)
        if loop_kernel is not None:
            model = gtsam.noiseModel.Robust.Create(loop_kernel, model)
        loop_idx.append(fg.size())
        fg.add(Between(e.a, e.b, to_gtsam_pose(e.T, dim), model))
    return fg, values, loop_idx, known


def _lm_params(max_iterations=100):
    gtsam = _gtsam()
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(max_iterations)
    p.setRelativeErrorTol(1e-6)
    return p


def solve_lm(graph, loops, initial):
    gtsam = _gtsam()
    fg, values, _, _ = build(graph, loops, initial)
    result = gtsam.LevenbergMarquardtOptimizer(fg, values, _lm_params()).optimize()
    return from_values(result, graph.n, graph.dim)


def solve_gnc(graph, loops, initial):
    """(poses, accepted: bool per loop) from GNC-TLS."""
    gtsam = _gtsam()
    fg, values, loop_idx, known = build(graph, loops, initial)
    params = gtsam.GncLMParams(_lm_params(GNC_LM_ITERATIONS))
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(known)
    opt = gtsam.GncLMOptimizer(fg, values, params)
    opt.setInlierCostThresholdsAtProbability(CHI2_PROBABILITY)
    result = opt.optimize()
    w = np.asarray(opt.getWeights())
    return from_values(result, graph.n, graph.dim), [bool(w[i] > 0.5) for i in loop_idx]


def solve_dcs(graph, loops, initial, phi=1.0):
    """(poses, accepted per loop): DCS kernel on the loops; a loop counts as accepted if its
    Gaussian chi2 at the solution is below the 0.99 quantile."""
    gtsam = _gtsam()
    from scipy.stats import chi2
    fg, values, loop_idx, _ = build(graph, loops, initial, gtsam.noiseModel.mEstimator.DCS.Create(phi))
    result = gtsam.LevenbergMarquardtOptimizer(fg, values, _lm_params()).optimize()
    plain, _, plain_idx, _ = build(graph, loops, initial)
    limit = chi2.ppf(CHI2_PROBABILITY, 3 if graph.dim == 2 else 6)
    accepted = [bool(2.0 * plain.at(i).error(result) < limit) for i in plain_idx]
    return from_values(result, graph.n, graph.dim), accepted
