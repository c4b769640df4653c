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
#pragma once

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>

namespace rover_loop_fusion {
namespace core {

constexpr double kYawResidualScale = 180.0 / M_PI;
/// loop_fusion's loop edges divide the yaw residual by 10.
constexpr double kLoopYawWeight = 0.1;
/// loop_fusion's 6-DoF edges (odometry and loop) use t_var = 0.1, q_var = 0.01.
constexpr double kSixDofTranslationSigma = 0.1;
constexpr double kSixDofRotationSigma = 0.01;

/// Wraps an angle difference to [-pi, pi] (one turn, as the differences here are small).
template <typename T>
T wrapAngleDiff(const T& a) {
  if (a > T(M_PI)) return a - T(2.0 * M_PI);
  if (a < T(-M_PI)) return a + T(2.0 * M_PI);
  return a;
}

/// R = Rz(yaw) * Ry(pitch) * Rx(roll), row-major, radians (the Z-Y-X convention of
/// loop_fusion's Utility::ypr2R).
template <typename T>
void yawPitchRollToRotation(const T& yaw, const T& pitch, const T& roll, T R[9]) {
  using std::cos;
  using std::sin;
  const T cy = cos(yaw), sy = sin(yaw), cp = cos(pitch), sp = sin(pitch), cr = cos(roll),
          sr = sin(roll);
  R[0] = cy * cp;
  R[1] = -sy * cr + cy * sp * sr;
  R[2] = sy * sr + cy * sp * cr;
  R[3] = sy * cp;
  R[4] = cy * cr + sy * sp * sr;
  R[5] = -cy * sr + sy * sp * cr;
  R[6] = -sp;
  R[7] = cp * sr;
  R[8] = cp * cr;
}

/// Yaw, pitch, roll (radians, Z-Y-X) of a rotation matrix.
inline Eigen::Vector3d rotationToYawPitchRoll(const Eigen::Matrix3d& R) {
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  return Eigen::Vector3d(yaw, pitch, roll);
}

inline Eigen::Matrix3d yawPitchRollToRotation(double yaw, double pitch, double roll) {
  double R[9];
  yawPitchRollToRotation(yaw, pitch, roll, R);
  Eigen::Matrix3d M;
  M << R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8];
  return M;
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
  FourDofEdgeCost(const Eigen::Vector3d& t_ij, double yaw_ij, double pitch_i, double roll_i,
                  double yaw_weight)
      : t_ij_(t_ij), yaw_ij_(yaw_ij), yaw_scale_(kYawResidualScale * yaw_weight) {
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
    return true;
  }

 private:
  Eigen::Vector3d t_ij_;
  double yaw_ij_, yaw_scale_;
  Eigen::Matrix3d RprT_;
};

class SixDofEdgeError {
 public:
  /// q_ij as [w, x, y, z].
  SixDofEdgeError(const Eigen::Vector3d& t_ij, const Eigen::Quaterniond& q_ij, double t_sigma,
                  double q_sigma)
      : t_ij_(t_ij), t_sigma_(t_sigma), q_sigma_(q_sigma) {
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
    return true;
  }

  static ceres::CostFunction* create(const Eigen::Vector3d& t_ij, const Eigen::Quaterniond& q_ij,
                                     double t_sigma = kSixDofTranslationSigma,
                                     double q_sigma = kSixDofRotationSigma) {
    return new ceres::AutoDiffCostFunction<SixDofEdgeError, 6, 4, 3, 4, 3>(
        new SixDofEdgeError(t_ij, q_ij, t_sigma, q_sigma));
  }

 private:
  Eigen::Vector3d t_ij_;
  double q_ij_inv_[4];
  double t_sigma_, q_sigma_;
};

}  // namespace core
}  // namespace rover_loop_fusion
