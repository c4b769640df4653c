// The one place that knows which Ceres we build against.
//
// Ceres >= 2.1 (Debian 12) has ceres::Manifold and deprecates LocalParameterization;
// Ceres 1.14 (Ubuntu 20.04 / ROS Noetic) only has LocalParameterization. Everything else in
// the core uses the names below and never spells either API directly.
#pragma once

#include "rover_loop_fusion/core/geometry.h"

#include <ceres/ceres.h>
#include <ceres/version.h>

#if (CERES_VERSION_MAJOR > 2) || (CERES_VERSION_MAJOR == 2 && CERES_VERSION_MINOR >= 1)
#define ROVER_CERES_HAS_MANIFOLD 1
#else
#define ROVER_CERES_HAS_MANIFOLD 0
#endif

namespace rover_loop_fusion {
namespace core {
namespace compat {

#if ROVER_CERES_HAS_MANIFOLD
using ParameterManifold = ceres::Manifold;

/// A yaw angle in radians, kept in (-pi, pi].
class AngleManifold : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 1; }
  int TangentSize() const override { return 1; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    *x_plus_delta = wrapAngle(*x + *delta);
    return true;
  }
  bool PlusJacobian(const double*, double* jacobian) const override {
    *jacobian = 1.0;
    return true;
  }
  bool Minus(const double* y, const double* x, double* y_minus_x) const override {
    *y_minus_x = wrapAngle(*y - *x);
    return true;
  }
  bool MinusJacobian(const double*, double* jacobian) const override {
    *jacobian = 1.0;
    return true;
  }
};

/// Unit quaternion stored [w, x, y, z] (Ceres' own order, as loop_fusion's 6-DoF graph).
inline ParameterManifold* newQuaternionManifold() { return new ceres::QuaternionManifold(); }

inline void setManifold(ceres::Problem& problem, double* block, ParameterManifold* manifold) {
  problem.SetManifold(block, manifold);
}
/// The core owns every cost function, loss and manifold it hands to a Problem.
inline ceres::Problem::Options problemOptionsNotOwning() {
  ceres::Problem::Options o;
  o.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  return o;
}
#else
using ParameterManifold = ceres::LocalParameterization;

class AngleManifold : public ceres::LocalParameterization {
 public:
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override {
    *x_plus_delta = wrapAngle(*x + *delta);
    return true;
  }
  bool ComputeJacobian(const double*, double* jacobian) const override {
    *jacobian = 1.0;
    return true;
  }
  int GlobalSize() const override { return 1; }
  int LocalSize() const override { return 1; }
};

inline ParameterManifold* newQuaternionManifold() { return new ceres::QuaternionParameterization(); }

inline void setManifold(ceres::Problem& problem, double* block, ParameterManifold* manifold) {
  problem.SetParameterization(block, manifold);
}
inline ceres::Problem::Options problemOptionsNotOwning() {
  ceres::Problem::Options o;
  o.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.local_parameterization_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  return o;
}
#endif

}  // namespace compat
}  // namespace core
}  // namespace rover_loop_fusion
