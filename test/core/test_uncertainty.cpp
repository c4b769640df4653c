// The uncertainty of the odometry: the drift model's chain covariance from prefix moments
// (core/drift.h) against step-by-step sums and against the marginal of the full linearised
// chain, and the condensed graph (core/condensed.h): a chain condensed to one edge gives the
// same marginals and solution as the chain keyframe by keyframe.
#include "rover_loop_fusion/core/condensed.h"
#include "rover_loop_fusion/core/drift.h"
#include "rover_loop_fusion/core/geometry.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <cmath>

using namespace rover_loop_fusion;

namespace {

struct Chain {
  std::vector<Eigen::Vector3d> p;
  std::vector<Eigen::Matrix3d> R;
  std::vector<double> yaw, pitch, roll;
  std::vector<Eigen::Matrix4d> cov;  // of the step ending at j
};

/// A winding 3-D path with small pitch/roll, like a VIO keyframe trajectory.
Chain makeChain(size_t n, const core::DriftModel& model, uint32_t seed = 3) {
  sim::Gaussian g(seed);
  Chain c;
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  double yaw = 0.0;
  for (size_t j = 0; j < n; ++j) {
    const double pitch = g(0.03), roll = g(0.03);
    if (j > 0) {
      yaw += g(0.15);
      p += core::yawPitchRollToRotation(yaw, 0, 0) * Eigen::Vector3d(0.3 + 0.4 * g.uniform(), 0.0, g(0.05));
    }
    c.p.push_back(p);
    c.yaw.push_back(yaw);
    c.pitch.push_back(pitch);
    c.roll.push_back(roll);
    c.R.push_back(core::yawPitchRollToRotation(yaw, pitch, roll));
    c.cov.push_back(j == 0 ? Eigen::Matrix4d::Zero() : model.stepCovariance((c.p[j] - c.p[j - 1]).norm()));
  }
  return c;
}

core::StoredChainMoments moments(const Chain& c) {
  core::StoredChainMoments m;
  for (size_t j = 0; j < c.p.size(); ++j) m.append(c.p[j], c.R[j], c.cov[j]);
  return m;
}

/// sum_{j in (a,b]} H(p_b - p_j) W_j H(p_b - p_j)^T, then into a's frame: the definition.
Eigen::Matrix4d bySteps(const Chain& c, size_t a, size_t b) {
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  E(0, 1) = -1;
  E(1, 0) = 1;
  Eigen::Matrix4d C = Eigen::Matrix4d::Zero();
  for (size_t j = a + 1; j <= b; ++j) {
    Eigen::Matrix4d B = Eigen::Matrix4d::Identity();
    B.topLeftCorner<3, 3>() = c.R[j];
    const Eigen::Matrix4d W = B * c.cov[j] * B.transpose();
    Eigen::Matrix4d H = Eigen::Matrix4d::Identity();
    H.topRightCorner<3, 1>() = E * (c.p[b] - c.p[j]);
    C += H * W * H.transpose();
  }
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = c.R[a].transpose();
  return T * C * T.transpose();
}

double relErr(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) { return (a - b).norm() / b.norm(); }

core::AnchorState stateOf(const Chain& c, size_t j) {
  core::AnchorState s;
  s.p = c.p[j];
  s.yaw = c.yaw[j];
  return s;
}

core::CondensedEdge odometryEdge(const Chain& c, size_t a, size_t b, const Eigen::Matrix4d& cov, int ia, int ib) {
  core::CondensedEdge e;
  e.from = ia;
  e.to = ib;
  e.t = c.R[a].transpose() * (c.p[b] - c.p[a]);
  e.yaw = core::wrapAngle(c.yaw[b] - c.yaw[a]);
  e.covariance = cov;
  return e;
}

}  // namespace

TEST(ChainMoments, RelativeCovarianceEqualsTheStepByStepSumForAnyPair) {
  core::DriftModel model;
  const Chain c = makeChain(100, model);
  const core::StoredChainMoments m = moments(c);
  const size_t pairs[][2] = {{0, 1}, {0, 99}, {7, 8}, {8, 16}, {3, 61}, {15, 17}, {40, 99}};
  for (const auto& ab : pairs) {
    const Eigen::Matrix4d expected = bySteps(c, ab[0], ab[1]);
    const Eigen::Matrix4d got = m.relative(ab[0], ab[1], c.R[ab[0]]);
    EXPECT_LT(relErr(got, expected), 1e-10) << ab[0] << " -> " << ab[1] << "\n" << got << "\n" << expected;
  }
  // Grows with the distance, and the yaw lever arm makes it grow faster than linearly.
  const double v20 = m.relative(0, 20, c.R[0]).topLeftCorner<2, 2>().trace();
  const double v80 = m.relative(0, 80, c.R[0]).topLeftCorner<2, 2>().trace();
  EXPECT_GT(v80, 4.0 * v20);
}

TEST(ChainMoments, IsotropicStepsAndAKeptPrefixGiveTheStepByStepSum) {
  // loop_fusion's unit weighting: the same variance on x, y, z (the moments skip the rotation
  // then), on a chain that turns and tilts; and cross() from a prefix the caller keeps.
  core::DriftModel model;
  Chain c = makeChain(100, model, 3);
  for (size_t j = 1; j < c.cov.size(); ++j) {
    c.cov[j] = Eigen::Matrix4d::Identity() / 30.0;
    c.cov[j](3, 3) = 1e-4;
  }
  const core::StoredChainMoments m = moments(c);
  const size_t pairs[][2] = {{0, 99}, {3, 61}, {8, 16}, {40, 99}};
  for (const auto& ab : pairs)
    EXPECT_LT(relErr(m.relative(ab[0], ab[1], c.R[ab[0]]), bySteps(c, ab[0], ab[1])), 1e-10) << ab[0] << " -> " << ab[1];
  core::StoredChainMoments general;  // the same steps, one of them not isotropic
  for (size_t j = 0; j < c.p.size(); ++j) {
    Eigen::Matrix4d cov = c.cov[j];
    if (j == 50) cov(0, 0) *= 2.0;
    general.append(c.p[j], c.R[j], cov);
  }
  Chain c50 = c;
  c50.cov[50](0, 0) *= 2.0;
  EXPECT_LT(relErr(general.relative(3, 61, c.R[3]), bySteps(c50, 3, 61)), 1e-10);
  EXPECT_GT(relErr(general.relative(3, 61, c.R[3]), bySteps(c, 3, 61)), 1e-6);
  // cross(a, k, b) from a kept prefix(a): the same numbers, for every k.
  core::ChainMoments cm;
  cm.extend(m, m.size());
  const size_t a = 13, b = 77;
  const core::ChainMoments::Sums prefix_a = cm.prefix(m, a);
  for (size_t k = a; k <= b; ++k) {
    const Eigen::Matrix4d kept = cm.cross(m, prefix_a, a, k, b);
    EXPECT_TRUE((kept.array() == cm.cross(m, a, k, b).array()).all()) << k;
    EXPECT_TRUE((kept.array() == m.cross(a, k, b).array()).all()) << k;
  }
}

TEST(ChainMoments, MatchesTheMarginalOfTheFullChainSolvedKeyframeByKeyframe) {
  core::DriftModel model;
  const Chain c = makeChain(60, model, 11);
  core::CondensedGraph full;
  for (size_t j = 0; j < c.p.size(); ++j) full.addAnchor(stateOf(c, j), c.pitch[j], c.roll[j], false);
  for (size_t j = 1; j < c.p.size(); ++j)
    ASSERT_TRUE(full.addEdge(odometryEdge(c, j - 1, j, bySteps(c, j - 1, j), j - 1, j)));
  Eigen::Matrix4d marginal;
  ASSERT_TRUE(full.marginal(5, 50, c.R[5], &marginal));
  const Eigen::Matrix4d moments_cov = moments(c).relative(5, 50, c.R[5]);
  EXPECT_LT(relErr(moments_cov, marginal), 1e-6) << moments_cov << "\n" << marginal;
}

TEST(CondensedGraph, ChainsCondensedToOneEdgeGiveTheSameMarginalWithLoops) {
  core::DriftModel model;
  const Chain c = makeChain(120, model, 5);
  Eigen::Matrix4d loop_cov = Eigen::Matrix4d::Identity() * 0.05 * 0.05;
  loop_cov(3, 3) = std::pow(M_PI / 180.0, 2);
  const std::vector<std::pair<size_t, size_t>> loops = {{10, 70}, {30, 100}, {12, 110}};
  const core::StoredChainMoments m = moments(c);
  // Full graph: every keyframe.
  core::CondensedGraph full;
  for (size_t j = 0; j < c.p.size(); ++j) full.addAnchor(stateOf(c, j), c.pitch[j], c.roll[j], false);
  for (size_t j = 1; j < c.p.size(); ++j)
    ASSERT_TRUE(full.addEdge(odometryEdge(c, j - 1, j, bySteps(c, j - 1, j), j - 1, j)));
  for (const auto& l : loops) ASSERT_TRUE(full.addEdge(odometryEdge(c, l.first, l.second, loop_cov, l.first, l.second)));
  // Condensed: anchors = loop ends and the two keyframes asked about.
  const std::vector<size_t> anchors = {10, 12, 30, 45, 70, 100, 110};
  core::CondensedGraph cg;
  for (size_t a : anchors) cg.addAnchor(stateOf(c, a), c.pitch[a], c.roll[a], false);
  for (size_t i = 1; i < anchors.size(); ++i)
    ASSERT_TRUE(cg.addEdge(odometryEdge(c, anchors[i - 1], anchors[i],
                                        m.relative(anchors[i - 1], anchors[i], c.R[anchors[i - 1]]), i - 1, i)));
  auto id = [&](size_t p) { return static_cast<int>(std::find(anchors.begin(), anchors.end(), p) - anchors.begin()); };
  for (const auto& l : loops)
    ASSERT_TRUE(cg.addEdge(odometryEdge(c, l.first, l.second, loop_cov, id(l.first), id(l.second))));
  Eigen::Matrix4d a, b;
  ASSERT_TRUE(full.marginal(45, 110, c.R[45], &a));
  ASSERT_TRUE(cg.marginal(id(45), id(110), c.R[45], &b));
  EXPECT_LT(relErr(b, a), 1e-6) << b << "\n" << a;
  // The loops shrink it well below the chain's own.
  const double chain_only = m.relative(45, 110, c.R[45]).topLeftCorner<3, 3>().trace();
  const double with_loops = b.topLeftCorner<3, 3>().trace();
  EXPECT_LT(with_loops, 0.5 * chain_only);
}

TEST(CondensedGraph, ChordStepsReachGaussNewtonsSolution) {
  // Every keyframe an anchor, three loops that pull (one by 2 m and 10 degrees), robust as a
  // trial's: the solve that keeps its factorisation ends where the one that refactorises does.
  core::DriftModel model;
  const Chain c = makeChain(120, model, 5);
  Eigen::Matrix4d loop_cov = Eigen::Matrix4d::Identity() * 0.05 * 0.05;
  loop_cov(3, 3) = std::pow(M_PI / 180.0, 2);
  auto build = [&]() {
    core::CondensedGraph g;
    for (size_t j = 0; j < c.p.size(); ++j) g.addAnchor(stateOf(c, j), c.pitch[j], c.roll[j], j == 0);
    for (size_t j = 1; j < c.p.size(); ++j) g.addEdge(odometryEdge(c, j - 1, j, bySteps(c, j - 1, j), j - 1, j));
    const std::vector<std::pair<size_t, size_t>> loops = {{10, 70}, {30, 100}, {12, 110}};
    for (size_t i = 0; i < loops.size(); ++i) {
      core::CondensedEdge e = odometryEdge(c, loops[i].first, loops[i].second, loop_cov, loops[i].first, loops[i].second);
      if (i == 2) {
        e.t += Eigen::Vector3d(2.0, -1.0, 0.0);
        e.yaw = core::wrapAngle(e.yaw + 10.0 * M_PI / 180.0);
      }
      e.huber = 0.1;
      g.addEdge(e);
    }
    return g;
  };
  core::CondensedGraph newton = build(), chord = build();
  bool ok_n = false, ok_c = false, conv_n = false, conv_c = false;
  newton.solve(200, 1e-10, &ok_n, &conv_n, 0.0, 0.0);
  const int it = chord.solve(200, 1e-10, &ok_c, &conv_c, 0.0, 0.5);
  ASSERT_TRUE(ok_n && ok_c && conv_n && conv_c);
  EXPECT_LT(it, 200);
  double far = 0.0;
  for (size_t j = 1; j < c.p.size(); ++j) {
    far = std::max(far, (newton.state(j).p - chord.state(j).p).norm());
    far = std::max(far, std::abs(core::wrapAngle(newton.state(j).yaw - chord.state(j).yaw)));
  }
  EXPECT_LT(far, 1e-8);
  EXPECT_GT((newton.state(110).p - c.p[110]).norm(), 0.05) << "the loops moved the graph";
}

TEST(CondensedGraph, SolveMovesAnchorsToSatisfyALoopAndReportsSingularSystems) {
  core::DriftModel model;
  const Chain c = makeChain(80, model, 9);
  const core::StoredChainMoments m = moments(c);
  core::CondensedGraph cg;
  cg.addAnchor(stateOf(c, 0), c.pitch[0], c.roll[0], true);
  cg.addAnchor(stateOf(c, 79), c.pitch[79], c.roll[79], false);
  ASSERT_TRUE(cg.addEdge(odometryEdge(c, 0, 79, m.relative(0, 79, c.R[0]), 0, 1)));
  // A loop that says keyframe 79 is 1 m to the side of where odometry has it.
  core::CondensedEdge loop = odometryEdge(c, 0, 79, Eigen::Matrix4d::Identity() * 1e-4, 0, 1);
  loop.t += Eigen::Vector3d(0.0, 1.0, 0.0);
  ASSERT_TRUE(cg.addEdge(loop));
  const double before = cg.chi2(0) + cg.chi2(1);
  bool ok = false;
  const int iterations = cg.solve(10, 1e-9, &ok);
  ASSERT_TRUE(ok);
  EXPECT_LE(iterations, 10);
  EXPECT_LT(cg.chi2(0) + cg.chi2(1), 0.1 * before);
  EXPECT_LT(cg.residual(1).head<3>().norm(), 0.05) << "the precise loop wins over the long chain";
  // Nothing ties anchor 2 to the rest: no marginal.
  cg.addAnchor(stateOf(c, 40), c.pitch[40], c.roll[40], false);
  Eigen::Matrix4d cov;
  EXPECT_FALSE(cg.marginal(0, 2, c.R[0], &cov));
  // A covariance that is not positive definite is refused.
  core::CondensedEdge bad = loop;
  bad.covariance = -Eigen::Matrix4d::Identity();
  EXPECT_FALSE(cg.addEdge(bad));
}
