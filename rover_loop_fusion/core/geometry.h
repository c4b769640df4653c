// Angles and yaw-pitch-roll: the one copy, Eigen only (no Ceres), used by the cost functions,
// the pose graph, the simulator and the tools.
//
// Convention: R = Rz(yaw) * Ry(pitch) * Rx(roll), radians (the Z-Y-X convention of
// loop_fusion's Utility::ypr2R / R2ypr, which work in degrees).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>

namespace rover_loop_fusion {
namespace core {

/// An angle wrapped to (-pi, pi], any number of turns.
inline double wrapAngle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

/// wrapAngle for an angle that is nearly always in [-pi, pi] already (a condensed solve's yaw
/// residuals and updates): returned as it is then, without sine, cosine and arctangent
/// (wrapAngle would give it back to within a rounding); wrapAngle otherwise.
inline double wrapAngleNear(double a) { return a >= -M_PI && a <= M_PI ? a : wrapAngle(a); }

/// Wraps an angle difference to [-pi, pi] by one turn (the differences here are small).
/// A template so that Ceres' autodiff (Jet) can use it.
template <typename T>
T wrapAngleDiff(const T& a) {
  if (a > T(M_PI)) return a - T(2.0 * M_PI);
  if (a < T(-M_PI)) return a + T(2.0 * M_PI);
  return a;
}

/// R = Rz(yaw) * Ry(pitch) * Rx(roll), row-major, from the cosines and sines of the three
/// angles (what yawPitchRollToRotation computes them into; the condensed graphs keep pitch's and
/// roll's, which do not change, and compute only yaw's per linearisation).
template <typename T>
void rotationFromCosSin(const T& cy, const T& sy, const T& cp, const T& sp, const T& cr, const T& sr, T R[9]) {
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

/// R = Rz(yaw) * Ry(pitch) * Rx(roll), row-major, radians. A template for autodiff.
template <typename T>
void yawPitchRollToRotation(const T& yaw, const T& pitch, const T& roll, T R[9]) {
  using std::cos;
  using std::sin;
  rotationFromCosSin(T(cos(yaw)), T(sin(yaw)), T(cos(pitch)), T(sin(pitch)), T(cos(roll)), T(sin(roll)), R);
}

/// rotationFromCosSin as a matrix.
inline Eigen::Matrix3d rotationFromCosSin(double cy, double sy, double cp, double sp, double cr, double sr) {
  double R[9];
  rotationFromCosSin(cy, sy, cp, sp, cr, sr, R);
  Eigen::Matrix3d M;
  M << R[0], R[1], R[2], R[3], R[4], R[5], R[6], R[7], R[8];
  return M;
}

inline Eigen::Matrix3d yawPitchRollToRotation(double yaw, double pitch, double roll) {
  return rotationFromCosSin(std::cos(yaw), std::sin(yaw), std::cos(pitch), std::sin(pitch), std::cos(roll),
                            std::sin(roll));
}

/// Yaw, pitch, roll (radians, Z-Y-X) of a rotation matrix.
inline Eigen::Vector3d rotationToYawPitchRoll(const Eigen::Matrix3d& R) {
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const double pitch = std::atan2(-R(2, 0), std::hypot(R(0, 0), R(1, 0)));
  const double roll = std::atan2(R(2, 1), R(2, 2));
  return Eigen::Vector3d(yaw, pitch, roll);
}

/// Yaw (radians, Z-Y-X) of a rotation.
inline double yawOf(const Eigen::Quaterniond& q) { return rotationToYawPitchRoll(q.toRotationMatrix())[0]; }

/// E = [e_z]x: d(Rz(yaw) x)/d yaw at yaw = 0 is E x.
inline Eigen::Matrix3d yawGenerator() {
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  E(0, 1) = -1.0;
  E(1, 0) = 1.0;
  return E;
}

/// [v]x: the cross product with v as a matrix ([v]x w = v x w).
inline Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d S;
  S << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return S;
}

/// The rotation exp([phi]x) (angle |phi| about phi).
inline Eigen::Quaterniond rotationExp(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  return angle > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi / angle)) : Eigen::Quaterniond::Identity();
}

/// A rotation about the z axis.
inline Eigen::Quaterniond yawRotation(double yaw) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
}

}  // namespace core
}  // namespace rover_loop_fusion
