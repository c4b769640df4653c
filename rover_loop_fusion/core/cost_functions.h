// Ceres cost functors of the pose graph, written to have the same residual form as
// VINS-Fusion loop_fusion's pose graph (so that our trial optimisation predicts what
// loop_fusion will do with a loop), in our own code and units:
//
//   4-DoF edge i -> j (odometry and loop), parameters yaw_i, t_i, yaw_j, t_j:
//     r[0:3] = w * (R(yaw_i, pitch_i, roll_i)^T (t_j - t_i) - t_ij)
//     r[3]   = w * wrap(yaw_j - yaw_i - yaw_ij) * kYawResidualScale * yaw_weight
//   with w = 1; yaw_weight = 1 for odometry, 1/10 for loops (loop_fusion's
//   FourDOFWeightError). Angles are radians; loop_fusion's yaw residual is in degrees, so
//   kYawResidualScale = 180/pi keeps its relative weighting of yaw against translation.
//
//   6-DoF edge i -> j, parameters q_i [w,x,y,z], t_i, q_j, t_j (loop_fusion's RelativeRTError):
//     r[0:3] = (R_i^T (t_j - t_i) - t_ij) / t_var
//     r[3:6] = 2 vec(q_ij^-1 * (q_i^-1 q_j)) / q_var
//
// Every edge can carry an information matrix Lambda of its residual r (as defined above, 4x4 or
// 6x6); the residual handed to Ceres is then L r with L^T L = Lambda, so that the cost is
// r^T Lambda r / 2. Unit information (loop_fusion's weighting, the default) leaves r exactly
// as above and costs nothing.
#pragma once

#include "rover_loop_fusion/core/geometry.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <memory>

namespace rover_loop_fusion {
namespace core {

constexpr double kYawResidualScale = 180.0 / M_PI;
/// loop_fusion's loop edges divide the yaw residual by 10.
constexpr double kLoopYawWeight = 0.1;
/// loop_fusion's 6-DoF edges (odometry and loop) use t_var = 0.1, q_var = 0.01.
constexpr double kSixDofTranslationSigma = 0.1;
constexpr double kSixDofRotationSigma = 0.01;

using Matrix6d = Eigen::Matrix<double, 6, 6>;

/// L (upper triangular) with L^T L = information; false if it is not symmetric positive
/// definite and finite. Unit information gives L = I exactly.
template <int N>
bool sqrtInformation(const Eigen::Matrix<double, N, N>& information, Eigen::Matrix<double, N, N>* L) {
  if (!information.allFinite() || !information.isApprox(information.transpose())) return false;
  const Eigen::LLT<Eigen::Matrix<double, N, N>> llt(information);
  if (llt.info() != Eigen::Success) return false;
  *L = llt.matrixU();
  return true;
}

class FourDofEdgeError {
 public:
  FourDofEdgeError(const Eigen::Vector3d& t_ij, double yaw_ij, double pitch_i, double roll_i,
                   double yaw_weight)
      : t_ij_(t_ij), yaw_ij_(yaw_ij), pitch_i_(pitch_i), roll_i_(roll_i),
        yaw_weight_(yaw_weight) {}

  template <typename T>
  bool operator()(const T* const yaw_i, const T* const t_i, const T* const yaw_j,
                  const T* const t_j, T* residuals) const {
    const T d[3] = {t_j[0] - t_i[0], t_j[1] - t_i[1], t_j[2] - t_i[2]};
    T R[9];
    yawPitchRollToRotation(yaw_i[0], T(pitch_i_), T(roll_i_), R);
    // R^T * d
    residuals[0] = R[0] * d[0] + R[3] * d[1] + R[6] * d[2] - T(t_ij_.x());
    residuals[1] = R[1] * d[0] + R[4] * d[1] + R[7] * d[2] - T(t_ij_.y());
    residuals[2] = R[2] * d[0] + R[5] * d[1] + R[8] * d[2] - T(t_ij_.z());
    residuals[3] = wrapAngleDiff(yaw_j[0] - yaw_i[0] - T(yaw_ij_)) *
                   T(kYawResidualScale * yaw_weight_);
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector3d& t_ij, double yaw_ij,
                                     double pitch_i, double roll_i, double yaw_weight) {
    return new ceres::AutoDiffCostFunction<FourDofEdgeError, 4, 1, 3, 1, 3>(
        new FourDofEdgeError(t_ij, yaw_ij, pitch_i, roll_i, yaw_weight));
  }

 private:
  Eigen::Vector3d t_ij_;
  double yaw_ij_, pitch_i_, roll_i_, yaw_weight_;
};

/// FourDofEdgeError with analytic Jacobians: the same residual, several times cheaper to
/// evaluate than the autodiff version (the trial optimisation evaluates thousands of them).
/// test_cost_functions checks it against the autodiff functor.
class FourDofEdgeCost : public ceres::SizedCostFunction<4, 1, 3, 1, 3> {
 public:
  /// `sqrt_information`: L of the residual's information (see the top of this file); none or
  /// the identity is loop_fusion's weighting.
  FourDofEdgeCost(const Eigen::Vector3d& t_ij, double yaw_ij, double pitch_i, double roll_i,
                  double yaw_weight, const Eigen::Matrix4d* sqrt_information = nullptr)
      : t_ij_(t_ij), yaw_ij_(yaw_ij), yaw_scale_(kYawResidualScale * yaw_weight) {
    if (sqrt_information && !sqrt_information->isIdentity(0.0)) L_.reset(new Eigen::Matrix4d(*sqrt_information));
    // R(yaw, pitch, roll)^T = (Ry(pitch) Rx(roll))^T Rz(yaw)^T; the first factor is fixed.
    const Eigen::Matrix3d Rpr = yawPitchRollToRotation(0.0, pitch_i, roll_i);
    RprT_ = Rpr.transpose();
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double yaw_i = parameters[0][0], yaw_j = parameters[2][0];
    const Eigen::Map<const Eigen::Vector3d> t_i(parameters[1]), t_j(parameters[3]);
    const Eigen::Vector3d d = t_j - t_i;
    const double c = std::cos(yaw_i), s = std::sin(yaw_i);
    Eigen::Matrix3d RzT;
    RzT << c, s, 0, -s, c, 0, 0, 0, 1;
    const Eigen::Matrix3d RT = RprT_ * RzT;
    Eigen::Map<Eigen::Vector4d> r(residuals);
    r.head<3>() = RT * d - t_ij_;
    r[3] = wrapAngleDiff(yaw_j - yaw_i - yaw_ij_) * yaw_scale_;
    if (L_) r = *L_ * r.eval();
    if (!jacobians) return true;
    if (jacobians[0]) {  // d r / d yaw_i
      Eigen::Matrix3d dRzT;
      dRzT << -s, c, 0, -c, -s, 0, 0, 0, 0;
      Eigen::Map<Eigen::Vector4d> J(jacobians[0]);
      J.head<3>() = RprT_ * dRzT * d;
      J[3] = -yaw_scale_;
    }
    if (jacobians[1]) {  // d r / d t_i
      Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> J(jacobians[1]);
      J.topRows<3>() = -RT;
      J.row(3).setZero();
    }
    if (jacobians[2]) {  // d r / d yaw_j
      Eigen::Map<Eigen::Vector4d> J(jacobians[2]);
      J.head<3>().setZero();
      J[3] = yaw_scale_;
    }
    if (jacobians[3]) {  // d r / d t_j
      Eigen::Map<Eigen::Matrix<double, 4, 3, Eigen::RowMajor>> J(jacobians[3]);
      J.topRows<3>() = RT;
      J.row(3).setZero();
    }
    if (L_) {
      for (int k = 0; k < 4; ++k) {
        if (!jacobians[k]) continue;
        const int n = k % 2 ? 3 : 1;
        Eigen::Map<Eigen::Matrix<double, 4, Eigen::Dynamic, Eigen::RowMajor>> J(jacobians[k], 4, n);
        J = *L_ * J.eval();
      }
    }
    return true;
  }

 private:
  Eigen::Vector3d t_ij_;
  double yaw_ij_, yaw_scale_;
  Eigen::Matrix3d RprT_;
  std::unique_ptr<Eigen::Matrix4d> L_;  // null: unit information
};

class SixDofEdgeError {
 public:
  /// q_ij as [w, x, y, z].
  /// `sqrt_information`: as for FourDofEdgeCost (none or the identity: loop_fusion's weighting).
  SixDofEdgeError(const Eigen::Vector3d& t_ij, const Eigen::Quaterniond& q_ij, double t_sigma,
                  double q_sigma, const Matrix6d* sqrt_information = nullptr)
      : t_ij_(t_ij), t_sigma_(t_sigma), q_sigma_(q_sigma) {
    if (sqrt_information && !sqrt_information->isIdentity(0.0)) L_.reset(new Matrix6d(*sqrt_information));
    q_ij_inv_[0] = q_ij.w();
    q_ij_inv_[1] = -q_ij.x();
    q_ij_inv_[2] = -q_ij.y();
    q_ij_inv_[3] = -q_ij.z();
  }

  template <typename T>
  bool operator()(const T* const q_i, const T* const t_i, const T* const q_j,
                  const T* const t_j, T* residuals) const {
    const T d[3] = {t_j[0] - t_i[0], t_j[1] - t_i[1], t_j[2] - t_i[2]};
    const T q_i_inv[4] = {q_i[0], -q_i[1], -q_i[2], -q_i[3]};
    T t_i_ij[3];
    ceres::QuaternionRotatePoint(q_i_inv, d, t_i_ij);
    residuals[0] = (t_i_ij[0] - T(t_ij_.x())) / T(t_sigma_);
    residuals[1] = (t_i_ij[1] - T(t_ij_.y())) / T(t_sigma_);
    residuals[2] = (t_i_ij[2] - T(t_ij_.z())) / T(t_sigma_);
    T q_rel[4];
    ceres::QuaternionProduct(q_i_inv, q_j, q_rel);
    const T q_meas_inv[4] = {T(q_ij_inv_[0]), T(q_ij_inv_[1]), T(q_ij_inv_[2]), T(q_ij_inv_[3])};
    T q_err[4];
    ceres::QuaternionProduct(q_meas_inv, q_rel, q_err);
    residuals[3] = T(2.0) * q_err[1] / T(q_sigma_);
    residuals[4] = T(2.0) * q_err[2] / T(q_sigma_);
    residuals[5] = T(2.0) * q_err[3] / T(q_sigma_);
    if (L_) {
      T r[6];
      for (int i = 0; i < 6; ++i) r[i] = residuals[i];
      for (int i = 0; i < 6; ++i) {
        residuals[i] = T(0.0);
        for (int j = 0; j < 6; ++j) residuals[i] += T((*L_)(i, j)) * r[j];
      }
    }
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector3d& t_ij, const Eigen::Quaterniond& q_ij,
                                     double t_sigma = kSixDofTranslationSigma,
                                     double q_sigma = kSixDofRotationSigma,
                                     const Matrix6d* sqrt_information = nullptr) {
    return new ceres::AutoDiffCostFunction<SixDofEdgeError, 6, 4, 3, 4, 3>(
        new SixDofEdgeError(t_ij, q_ij, t_sigma, q_sigma, sqrt_information));
  }

 private:
  Eigen::Vector3d t_ij_;
  double q_ij_inv_[4];
  double t_sigma_, q_sigma_;
  std::unique_ptr<Matrix6d> L_;  // null: unit information
};

}  // namespace core
}  // namespace rover_loop_fusion
