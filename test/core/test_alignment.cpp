#include "rover_loop_fusion/core/alignment.h"

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using rover_loop_fusion::core::AlignmentResult;
using rover_loop_fusion::core::alignPositions;

namespace {

Eigen::Matrix3Xd randomPoints(int n, unsigned seed) {
  std::srand(seed);
  return Eigen::Matrix3Xd::Random(3, n) * 10.0;
}

Eigen::Matrix3d someRotation() {
  return (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(-0.3, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

}  // namespace

TEST(Alignment, RecoversKnownSE3) {
  const Eigen::Matrix3Xd P = randomPoints(50, 1);
  const Eigen::Matrix3d R = someRotation();
  const Eigen::Vector3d t(1.0, -2.0, 3.5);
  // P = R * Pstar + t  <=>  Pstar = R^T (P - t)
  const Eigen::Matrix3Xd Pstar = R.transpose() * (P.colwise() - t);
  const AlignmentResult a = alignPositions(P, Pstar, false);
  ASSERT_TRUE(a.ok);
  EXPECT_NEAR(a.rmse, 0.0, 1e-9);
  EXPECT_NEAR(a.scale, 1.0, 1e-12);
  EXPECT_TRUE(a.rotation.isApprox(R, 1e-9));
  EXPECT_TRUE(a.translation.isApprox(t, 1e-9));
}

TEST(Alignment, RecoversKnownSim3) {
  const Eigen::Matrix3Xd P = randomPoints(40, 2);
  const Eigen::Matrix3d R = someRotation();
  const Eigen::Vector3d t(-4.0, 0.5, 2.0);
  const double scale = 1.7;
  const Eigen::Matrix3Xd Pstar = R.transpose() * (P.colwise() - t) / scale;
  const AlignmentResult sim3 = alignPositions(P, Pstar, true);
  ASSERT_TRUE(sim3.ok);
  EXPECT_NEAR(sim3.rmse, 0.0, 1e-9);
  EXPECT_NEAR(sim3.scale, scale, 1e-9);
  EXPECT_TRUE(sim3.rotation.isApprox(R, 1e-9));
  // SE(3) cannot explain the scale change: the score must show it.
  const AlignmentResult se3 = alignPositions(P, Pstar, false);
  ASSERT_TRUE(se3.ok);
  EXPECT_GT(se3.rmse, 1.0);
}

TEST(Alignment, RmseIsTheScoreOfTheDeformation) {
  // Moving one of four points by d after a rigid motion: the optimal alignment leaves a
  // residual, and it is never more than the unaligned RMSE d / 2.
  Eigen::Matrix3Xd P(3, 4);
  P << 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1;
  Eigen::Matrix3Xd Pstar = P;
  Pstar(0, 3) += 2.0;
  const AlignmentResult a = alignPositions(P, Pstar, false);
  ASSERT_TRUE(a.ok);
  EXPECT_GT(a.rmse, 0.1);
  EXPECT_LE(a.rmse, 1.0 + 1e-12);
}

TEST(Alignment, DegenerateInputs) {
  Eigen::Matrix3Xd one(3, 1);
  one << 1, 2, 3;
  Eigen::Matrix3Xd other(3, 1);
  other << -1, 0, 5;
  const AlignmentResult single = alignPositions(one, other, true);
  ASSERT_TRUE(single.ok);
  EXPECT_DOUBLE_EQ(single.rmse, 0.0);

  EXPECT_FALSE(alignPositions(Eigen::Matrix3Xd(3, 0), Eigen::Matrix3Xd(3, 0), false).ok);
  EXPECT_FALSE(alignPositions(randomPoints(5, 3), randomPoints(4, 3), false).ok);
  Eigen::Matrix3Xd nan = randomPoints(5, 4);
  nan(1, 2) = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(alignPositions(nan, randomPoints(5, 5), false).ok);

  // All of P* in one point: Sim(3) falls back to SE(3) instead of dividing by zero.
  const Eigen::Matrix3Xd same = Eigen::Matrix3Xd::Ones(3, 6);
  const AlignmentResult collapsed = alignPositions(randomPoints(6, 6), same, true);
  ASSERT_TRUE(collapsed.ok);
  EXPECT_TRUE(std::isfinite(collapsed.rmse));
  EXPECT_DOUBLE_EQ(collapsed.scale, 1.0);
}
