#include "rover_loop_fusion/core/cost_functions.h"

#include <gtest/gtest.h>

#include <memory>

using namespace rover_loop_fusion::core;

namespace {

constexpr double kDeg = M_PI / 180.0;

/// Evaluates a 4-parameter-block edge cost at (a_rot, a_t, b_rot, b_t).
Eigen::VectorXd residualOf(const ceres::CostFunction& f, double* a_rot, double* a_t, double* b_rot,
                           double* b_t, std::vector<Eigen::MatrixXd>* jac = nullptr) {
  const int n = f.num_residuals();
  Eigen::VectorXd r(n);
  double* params[4] = {a_rot, a_t, b_rot, b_t};
  std::vector<std::vector<double>> storage;
  std::vector<double*> jptr;
  if (jac) {
    for (int k = 0; k < 4; ++k) {
      storage.emplace_back(n * f.parameter_block_sizes()[k]);
      jptr.push_back(storage.back().data());
    }
  }
  EXPECT_TRUE(f.Evaluate(params, r.data(), jac ? jptr.data() : nullptr));
  if (jac) {
    jac->clear();
    for (int k = 0; k < 4; ++k) {
      const int m = f.parameter_block_sizes()[k];
      jac->push_back(Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          storage[k].data(), n, m));
    }
  }
  return r;
}

}  // namespace

TEST(FourDofEdge, MatchesHandComputedResidual) {
  // Keyframe i at (1, 2, 3) facing +y (yaw 90 deg), keyframe j 2 m further along +y and turned
  // 0.1 rad more. In i's frame j is at (2, 0, 0); the edge says (1.5, 0.5, 0) and 0.05 rad.
  double yaw_i = 90 * kDeg, yaw_j = 90 * kDeg + 0.1;
  double t_i[3] = {1, 2, 3}, t_j[3] = {1, 4, 3};
  const Eigen::Vector3d t_ij(1.5, 0.5, 0.0);
  // loop_fusion measures the yaw residual in degrees: 0.05 rad = 2.8648 deg.
  const double yaw_res_deg = 0.05 / kDeg;
  for (bool loop : {false, true}) {
    const double w = loop ? kLoopYawWeight : 1.0;
    std::unique_ptr<ceres::CostFunction> analytic(new FourDofEdgeCost(t_ij, 0.05, 0, 0, w));
    std::unique_ptr<ceres::CostFunction> autodiff(FourDofEdgeError::create(t_ij, 0.05, 0, 0, w));
    for (ceres::CostFunction* f : {analytic.get(), autodiff.get()}) {
      const Eigen::VectorXd r = residualOf(*f, &yaw_i, t_i, &yaw_j, t_j);
      EXPECT_NEAR(r[0], 0.5, 1e-12);
      EXPECT_NEAR(r[1], -0.5, 1e-12);
      EXPECT_NEAR(r[2], 0.0, 1e-12);
      EXPECT_NEAR(r[3], yaw_res_deg * w, 1e-9) << (loop ? "loop" : "odometry");
    }
  }
}

TEST(FourDofEdge, UsesRollAndPitchOfTheEarlierKeyframe) {
  // roll 90 deg: the world y axis is the body's -z axis.
  double yaw_i = 0, yaw_j = 0;
  double t_i[3] = {0, 0, 0}, t_j[3] = {0, 1, 0};
  FourDofEdgeCost f(Eigen::Vector3d::Zero(), 0.0, 0.0, 90 * kDeg, 1.0);
  const Eigen::VectorXd r = residualOf(f, &yaw_i, t_i, &yaw_j, t_j);
  EXPECT_NEAR(r[0], 0.0, 1e-12);
  EXPECT_NEAR(r[1], 0.0, 1e-12);
  EXPECT_NEAR(r[2], -1.0, 1e-12);
}

TEST(FourDofEdge, WrapsTheYawResidual) {
  double yaw_i = 175 * kDeg, yaw_j = -175 * kDeg;  // 10 deg apart across +-180
  double t[3] = {0, 0, 0};
  FourDofEdgeCost f(Eigen::Vector3d::Zero(), 0.0, 0.0, 0.0, 1.0);
  const Eigen::VectorXd r = residualOf(f, &yaw_i, t, &yaw_j, t);
  EXPECT_NEAR(r[3], 10.0, 1e-9);
}

TEST(FourDofEdge, AnalyticJacobiansMatchAutodiff) {
  std::srand(3);
  for (int trial = 0; trial < 20; ++trial) {
    const Eigen::Vector4d rnd = Eigen::Vector4d::Random();
    const Eigen::Vector3d t_ij = Eigen::Vector3d::Random() * 3;
    const double pitch = rnd[0] * 0.3, roll = rnd[1] * 0.3, yaw_ij = rnd[2] * 0.4;
    const double w = trial % 2 ? 1.0 : kLoopYawWeight;
    FourDofEdgeCost analytic(t_ij, yaw_ij, pitch, roll, w);
    std::unique_ptr<ceres::CostFunction> autodiff(FourDofEdgeError::create(t_ij, yaw_ij, pitch, roll, w));
    double yaw_i = rnd[3] * 3, yaw_j = yaw_i + 0.2 * rnd[0];
    Eigen::Vector3d ti = Eigen::Vector3d::Random() * 10, tj = ti + Eigen::Vector3d::Random() * 2;
    std::vector<Eigen::MatrixXd> ja, jb;
    const Eigen::VectorXd ra = residualOf(analytic, &yaw_i, ti.data(), &yaw_j, tj.data(), &ja);
    const Eigen::VectorXd rb = residualOf(*autodiff, &yaw_i, ti.data(), &yaw_j, tj.data(), &jb);
    ASSERT_TRUE(ra.isApprox(rb, 1e-12));
    for (int k = 0; k < 4; ++k) EXPECT_TRUE(ja[k].isApprox(jb[k], 1e-10)) << "block " << k << "\n" << ja[k] << "\n" << jb[k];
  }
}

TEST(SixDofEdge, MatchesHandComputedResidual) {
  const double theta = 0.2;
  const Eigen::Quaterniond qj(Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()));
  double q_i[4] = {1, 0, 0, 0}, t_i[3] = {0, 0, 0};
  double q_j[4] = {qj.w(), qj.x(), qj.y(), qj.z()}, t_j[3] = {1.0, 0.3, 0};
  std::unique_ptr<ceres::CostFunction> f(
      SixDofEdgeError::create(Eigen::Vector3d(1, 0, 0), Eigen::Quaterniond::Identity()));
  const Eigen::VectorXd r = residualOf(*f, q_i, t_i, q_j, t_j);
  EXPECT_NEAR(r[0], 0.0, 1e-12);
  EXPECT_NEAR(r[1], 0.3 / kSixDofTranslationSigma, 1e-12);
  EXPECT_NEAR(r[2], 0.0, 1e-12);
  EXPECT_NEAR(r[3], 0.0, 1e-12);
  EXPECT_NEAR(r[4], 0.0, 1e-12);
  EXPECT_NEAR(r[5], 2 * std::sin(theta / 2) / kSixDofRotationSigma, 1e-9);
}

TEST(YawPitchRoll, RoundTrip) {
  std::srand(5);
  for (int k = 0; k < 50; ++k) {
    const Eigen::Vector3d a = Eigen::Vector3d::Random().cwiseProduct(Eigen::Vector3d(3.1, 1.5, 3.1));
    const Eigen::Matrix3d R = yawPitchRollToRotation(a[0], a[1], a[2]);
    const Eigen::Matrix3d expected = (Eigen::AngleAxisd(a[0], Eigen::Vector3d::UnitZ()) *
                                      Eigen::AngleAxisd(a[1], Eigen::Vector3d::UnitY()) *
                                      Eigen::AngleAxisd(a[2], Eigen::Vector3d::UnitX()))
                                         .toRotationMatrix();
    ASSERT_TRUE(R.isApprox(expected, 1e-12));
    EXPECT_TRUE(rotationToYawPitchRoll(R).isApprox(a, 1e-9));
  }
}

TEST(EdgeInformation, WeightsTheResidualAndItsJacobians) {
  // The residual handed to Ceres is L r with L^T L = information; unit information is
  // loop_fusion's weighting and leaves r untouched.
  Eigen::Matrix4d information = Eigen::Matrix4d::Zero();
  information.diagonal() << 4.0, 9.0, 1.0, 0.25;
  information(0, 1) = information(1, 0) = 1.0;
  Eigen::Matrix4d L;
  ASSERT_TRUE(sqrtInformation<4>(information, &L));
  EXPECT_TRUE((L.transpose() * L).isApprox(information, 1e-12));
  const Eigen::Vector3d t_ij(1.0, -0.5, 0.2);
  FourDofEdgeCost unit(t_ij, 0.1, 0.05, -0.02, 1.0);
  FourDofEdgeCost weighted(t_ij, 0.1, 0.05, -0.02, 1.0, &L);
  const Eigen::Matrix4d I = Eigen::Matrix4d::Identity();
  FourDofEdgeCost explicit_unit(t_ij, 0.1, 0.05, -0.02, 1.0, &I);
  double yaw_i = 0.3, yaw_j = 0.5, t_i[3] = {1, 2, 3}, t_j[3] = {2, 1.5, 3.1};
  std::vector<Eigen::MatrixXd> ju, jw, je;
  const Eigen::VectorXd ru = residualOf(unit, &yaw_i, t_i, &yaw_j, t_j, &ju);
  const Eigen::VectorXd rw = residualOf(weighted, &yaw_i, t_i, &yaw_j, t_j, &jw);
  const Eigen::VectorXd re = residualOf(explicit_unit, &yaw_i, t_i, &yaw_j, t_j, &je);
  EXPECT_TRUE(rw.isApprox(L * ru, 1e-12));
  for (int k = 0; k < 4; ++k) EXPECT_TRUE(jw[k].isApprox(L * ju[k], 1e-12)) << "block " << k;
  EXPECT_EQ(re, ru);
  for (int k = 0; k < 4; ++k) EXPECT_EQ(je[k], ju[k]);

  Matrix6d info6 = Matrix6d::Identity();
  info6.diagonal() << 1, 4, 9, 16, 25, 36;
  Matrix6d L6;
  ASSERT_TRUE(sqrtInformation<6>(info6, &L6));
  std::unique_ptr<ceres::CostFunction> six(SixDofEdgeError::create(t_ij, Eigen::Quaterniond::Identity()));
  std::unique_ptr<ceres::CostFunction> six_w(SixDofEdgeError::create(
      t_ij, Eigen::Quaterniond::Identity(), kSixDofTranslationSigma, kSixDofRotationSigma, &L6));
  double q_i[4] = {1, 0, 0, 0}, q_j[4] = {std::cos(0.1), 0, 0, std::sin(0.1)};
  const Eigen::VectorXd r6 = residualOf(*six, q_i, t_i, q_j, t_j);
  EXPECT_TRUE(residualOf(*six_w, q_i, t_i, q_j, t_j).isApprox(L6 * r6, 1e-12));

  Eigen::Matrix4d bad = information;
  bad(3, 3) = -1.0;
  EXPECT_FALSE(sqrtInformation<4>(bad, &L)) << "not positive definite";
  bad = information;
  bad(0, 2) = 5.0;
  EXPECT_FALSE(sqrtInformation<4>(bad, &L)) << "not symmetric";
}
