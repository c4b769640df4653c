// The condensed graphs' linear algebra (core/condensed_solver.h): the block LDL^T of the normal
// matrix solves what a dense factorisation of the same matrix solves, for 4x4 and 6x6 blocks,
// in the fill-reducing order of orderedColumns(), and says so when the system is singular.
#include "rover_loop_fusion/core/condensed.h"
#include "rover_loop_fusion/core/condensed6.h"
#include "rover_loop_fusion/core/condensed_solver.h"

#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <cmath>

#include <random>
#include <vector>

using namespace rover_loop_fusion::core::condensed_detail;
namespace core = rover_loop_fusion::core;

namespace {

struct TestEdge {
  int from, to;
};

/// A pose-graph-like pattern: a chain over n anchors, extra edges between random pairs, and the
/// first anchor held fixed (the gauge).
std::vector<TestEdge> randomGraph(int n, int extra, std::mt19937* rng) {
  std::vector<TestEdge> edges;
  for (int i = 1; i < n; ++i) edges.push_back({i - 1, i});
  std::uniform_int_distribution<int> pick(0, n - 1);
  for (int k = 0; k < extra; ++k) {
    const int a = pick(*rng), b = pick(*rng);
    if (a != b) edges.push_back({std::min(a, b), std::max(a, b)});
  }
  return edges;
}

/// The whole symmetric matrix of a NormalMatrix, dense (for the reference solve).
template <int B>
Eigen::MatrixXd dense(const NormalMatrix<B>& H) {
  const int n = H.blocks();
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(B * n, B * n);
  for (int j = 0; j < n; ++j)
    for (int p = H.begin(j); p < H.end(j); ++p) {
      const int i = H.row(p);
      A.block<B, B>(B * i, B * j) = H.value(p);
      if (i != j) A.block<B, B>(B * j, B * i) = H.value(p).transpose();
    }
  return A;
}

template <int B>
void checkAgainstDense(uint32_t seed) {
  std::mt19937 rng(seed);
  const int anchors = 60;
  const std::vector<TestEdge> edges = randomGraph(anchors, 40, &rng);
  std::vector<bool> fixed(anchors, false);
  fixed[0] = true;
  int n = 0;
  const std::vector<int> col = orderedColumns(edges, fixed, -1, &n);
  ASSERT_EQ(n, anchors - 1);
  NormalMatrix<B> H(edges, col, n);
  std::normal_distribution<double> g(0.0, 1.0);
  using Block = Eigen::Matrix<double, B, B>;
  auto random = [&] {
    Block J;
    for (int r = 0; r < B; ++r)
      for (int c = 0; c < B; ++c) J(r, c) = g(rng);
    return J;
  };
  BlockLdlt<B> ldlt;
  ldlt.analyze(H);  // once: a second factorisation of the same pattern with other values too
  for (int round = 0; round < 2; ++round) {
    H.setZero();
    for (size_t e = 0; e < edges.size(); ++e) H.add(e, random(), random());
    ASSERT_TRUE(ldlt.factorize(H));
    const Eigen::MatrixXd A = dense(H);
    Eigen::Matrix<double, Eigen::Dynamic, B> rhs(B * n, B);
    for (int r = 0; r < rhs.rows(); ++r)
      for (int c = 0; c < B; ++c) rhs(r, c) = g(rng);
    Eigen::Matrix<double, Eigen::Dynamic, B> x = rhs;
    ldlt.solveInPlace(x);
    const Eigen::MatrixXd reference = A.llt().solve(rhs);
    EXPECT_LT((x - reference).norm() / reference.norm(), 1e-9) << "B " << B << ", seed " << seed;
    EXPECT_LT((A * x - rhs).norm() / rhs.norm(), 1e-9);
  }
}

}  // namespace

TEST(CondensedSolver, BlockLdltSolvesAsADenseFactorisation) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    checkAgainstDense<4>(seed);
    checkAgainstDense<6>(seed);
  }
}

TEST(CondensedSolver, BlockLdltRefusesASingularSystem) {
  // Anchor 3 has no edge: its block of the normal matrix stays zero.
  const std::vector<TestEdge> edges = {{0, 1}, {1, 2}};
  const std::vector<bool> fixed = {true, false, false, false};
  int n = 0;
  const std::vector<int> col = orderedColumns(edges, fixed, -1, &n);
  ASSERT_EQ(n, 3);
  NormalMatrix<4> H(edges, col, n);
  for (size_t e = 0; e < edges.size(); ++e) H.add(e, Eigen::Matrix4d::Identity(), Eigen::Matrix4d::Identity());
  BlockLdlt<4> ldlt;
  ldlt.analyze(H);
  EXPECT_FALSE(ldlt.factorize(H));
  // Tied to the rest, it solves.
  const std::vector<TestEdge> tied = {{0, 1}, {1, 2}, {2, 3}};
  NormalMatrix<4> H2(tied, orderedColumns(tied, fixed, -1, &n), n);
  for (size_t e = 0; e < tied.size(); ++e) H2.add(e, -Eigen::Matrix4d::Identity(), Eigen::Matrix4d::Identity());
  ldlt.analyze(H2);
  EXPECT_TRUE(ldlt.factorize(H2));
}

TEST(CondensedSolver, ChordStepsSolveAGraphTornByAFalseLoopAsGaussNewtonDoes) {
  // A 6-DoF ring of 60 anchors (30 m around, climbing 3 m) and a false loop that puts the last
  // anchor 40 m away and turned by 120 degrees: the kind of trial the gate lets through when
  // the prior is weak. Chord steps must not make that solve fail (a failed condensed solve
  // falls back to the full window, hundreds of milliseconds), and where Gauss-Newton converges
  // they converge to the same solution.
  const int n = 60;
  auto pose = [&](int i) {
    const double a = 2.0 * M_PI * i / n;
    core::AnchorPose p;
    p.p = Eigen::Vector3d(4.8 * std::cos(a), 4.8 * std::sin(a), 0.05 * i);
    p.q = Eigen::Quaterniond(Eigen::AngleAxisd(a + M_PI / 2, Eigen::Vector3d::UnitZ()));
    return p;
  };
  auto build = [&]() {
    core::CondensedGraph6 g;
    for (int i = 0; i < n; ++i) g.addAnchor(pose(i), i == 0);
    core::Matrix6d chain = core::Matrix6d::Identity() * 0.01;
    chain.bottomRightCorner<3, 3>() *= 0.01;
    for (int i = 1; i < n; ++i) {
      core::CondensedEdge6 e;
      e.from = i - 1;
      e.to = i;
      e.t = pose(i - 1).q.conjugate() * (pose(i).p - pose(i - 1).p);
      e.q = pose(i - 1).q.conjugate() * pose(i).q;
      e.covariance = chain;
      EXPECT_TRUE(g.addEdge(e));
    }
    core::CondensedEdge6 loop;
    loop.from = 5;
    loop.to = n - 1;
    loop.t = Eigen::Vector3d(40.0, 0.0, 0.0);
    loop.q = Eigen::Quaterniond(Eigen::AngleAxisd(2.0 * M_PI / 3, Eigen::Vector3d(0.3, 0.2, 1.0).normalized()));
    loop.covariance = core::Matrix6d::Identity() * 1e-4;
    EXPECT_TRUE(g.addEdge(loop));
    return g;
  };
  for (double chord : {0.25, 0.5}) {  // 0.5: the trials'
    core::CondensedGraph6 newton = build(), chorded = build();
    bool ok_n = false, ok_c = false, conv_n = false, conv_c = false;
    newton.solve(200, 1e-10, &ok_n, &conv_n, 0.0, 0.0);
    chorded.solve(200, 1e-10, &ok_c, &conv_c, 0.0, chord);
    ASSERT_TRUE(ok_n && conv_n) << "the reference solve";
    EXPECT_TRUE(ok_c && conv_c) << "chord " << chord << " ok " << ok_c << " converged " << conv_c;
    double far = 0.0;
    for (int i = 0; i < n; ++i) far = std::max(far, (newton.state(i).p - chorded.state(i).p).norm());
    EXPECT_LT(far, 1e-6) << "chord " << chord;
    EXPECT_GT((newton.state(n - 1).p - pose(n - 1).p).norm(), 1.0) << "the loop tore the ring";
  }
}

TEST(CondensedSolver, FourDofRingWhoseYawsCrossPiSolvesWithChordStepsAsGaussNewton) {
  // A 4-DoF ring of 60 anchors (yaws a + pi/2 in [-pi, pi], crossing +pi -> -pi; the loop's
  // measured yaw is its true one + 2 pi), tilted by
  // a small pitch and roll, drifted (a yaw error that grows along the ring, and a shift), closed
  // by a true loop with loop_fusion's Huber weighting. The yaw residuals must wrap (the
  // condensed graph skips wrapAngle's trigonometry only for angles already in [-pi, pi]), and
  // the chord steps (the matrix assembled only when a factorisation is needed) must reach
  // Gauss-Newton's solution: the true ring, up to the gauge of anchor 0.
  const int n = 60;
  auto wrap = [](double a) { return std::atan2(std::sin(a), std::cos(a)); };
  auto truth = [&](int i) {
    const double a = 2.0 * M_PI * i / n;
    core::AnchorState s;
    s.p = Eigen::Vector3d(8.0 * std::cos(a), 8.0 * std::sin(a), 0.02 * i);
    s.yaw = wrap(a + M_PI / 2);
    return s;
  };
  const double pitch = 0.03, roll = -0.02;
  auto rotation = [&](double yaw) {
    return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
            Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
        .toRotationMatrix();
  };
  auto edge = [&](int from, int to) {
    core::CondensedEdge e;
    e.from = from;
    e.to = to;
    e.t = rotation(truth(from).yaw).transpose() * (truth(to).p - truth(from).p);
    e.yaw = wrap(truth(to).yaw - truth(from).yaw);
    return e;
  };
  auto build = [&]() {
    core::CondensedGraph g;
    for (int i = 0; i < n; ++i) {
      core::AnchorState s = truth(i);
      s.yaw = wrap(s.yaw + 0.004 * i);  // drift
      s.p += Eigen::Vector3d(0.01 * i, -0.005 * i, 0.0);
      g.addAnchor(s, pitch, roll, i == 0);
    }
    for (int i = 1; i < n; ++i) {
      core::CondensedEdge e = edge(i - 1, i);
      e.covariance = Eigen::Matrix4d::Identity() * 1e-2;
      e.covariance(3, 3) = 1e-4;
      EXPECT_TRUE(g.addEdge(e));
    }
    core::CondensedEdge loop = edge(n - 1, 0);
    loop.yaw = truth(0).yaw - truth(n - 1).yaw + 2.0 * M_PI;  // the same yaw, not wrapped
    loop.covariance = Eigen::Matrix4d::Identity() * 1e-4;
    loop.huber = 0.1;
    EXPECT_TRUE(g.addEdge(loop));
    return g;
  };
  {
    // Drifted, anchor 14's yaw is pi - 0.049 and anchor 15's -pi + 0.060: edge 14 -> 15 measures
    // 0.105, so its yaw residual is -2 pi + 0.004 before wrapping, 0.004 (the drift step) after.
    const core::CondensedGraph g = build();
    ASSERT_GT(g.state(14).yaw, 3.0);
    ASSERT_LT(g.state(15).yaw, -3.0);
    EXPECT_NEAR(g.residual(14)[3], 0.004, 1e-9);
    EXPECT_NEAR(g.residual(n - 1)[3], -0.004 * (n - 1), 1e-9) << "the loop's, measured as its yaw + 2 pi";
  }
  core::CondensedGraph newton = build(), chorded = build();
  bool ok_n = false, ok_c = false, conv_n = false, conv_c = false;
  newton.solve(200, 1e-10, &ok_n, &conv_n, 0.0, 0.0);
  chorded.solve(200, 1e-10, &ok_c, &conv_c, 0.0, 0.5);
  ASSERT_TRUE(ok_n && conv_n) << "the reference solve";
  ASSERT_TRUE(ok_c && conv_c) << "chord steps: ok " << ok_c << " converged " << conv_c;
  double far = 0.0, off_truth = 0.0, yaw_off = 0.0;
  for (int i = 0; i < n; ++i) {
    far = std::max(far, (newton.state(i).p - chorded.state(i).p).norm());
    far = std::max(far, std::abs(wrap(newton.state(i).yaw - chorded.state(i).yaw)));
    off_truth = std::max(off_truth, (chorded.state(i).p - truth(i).p).norm());
    yaw_off = std::max(yaw_off, std::abs(wrap(chorded.state(i).yaw - truth(i).yaw)));
    EXPECT_GE(chorded.state(i).yaw, -M_PI);
    EXPECT_LE(chorded.state(i).yaw, M_PI);
  }
  EXPECT_LT(far, 1e-8);
  EXPECT_LT(off_truth, 1e-6) << "every edge is consistent with the true ring: the solve must find it";
  EXPECT_LT(yaw_off, 1e-8);
  for (size_t e = 0; e < chorded.edgeCount(); ++e) EXPECT_LT(chorded.residual(e).norm(), 1e-6) << "edge " << e;
}
