#include "rover_loop_fusion/core/condensed6.h"

#include "rover_loop_fusion/core/condensed_solver.h"
#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Cholesky>

#include <cmath>

namespace rover_loop_fusion {
namespace core {

int CondensedGraph6::addAnchor(const AnchorPose& pose, bool fixed) {
  AnchorPose s = pose;
  s.q.normalize();
  states_.push_back(s);
  fixed_.push_back(fixed);
  return static_cast<int>(states_.size()) - 1;
}

bool CondensedGraph6::addEdge(const CondensedEdge6& edge) {
  const Matrix6d C = 0.5 * (edge.covariance + edge.covariance.transpose());
  if (!C.allFinite() || !edge.t.allFinite() || !edge.q.coeffs().allFinite() || edge.q.norm() < 0.5) return false;
  Eigen::LLT<Matrix6d> llt(C);
  if (llt.info() != Eigen::Success) return false;
  const Matrix6d Linv = llt.matrixL().solve(Matrix6d::Identity());  // sqrt information (condensed.cpp)
  if (!Linv.allFinite()) return false;
  CondensedEdge6 e = edge;
  e.q.normalize();
  edges_.push_back(e);
  sqrt_info_.push_back(Linv);
  return true;
}

Vector6d CondensedGraph6::residual(size_t e) const {
  const CondensedEdge6& ed = edges_[e];
  const AnchorPose& a = states_[ed.from];
  const AnchorPose& b = states_[ed.to];
  Vector6d r;
  r.head<3>() = a.q.conjugate() * (b.p - a.p) - ed.t;
  r.tail<3>() = 2.0 * (ed.q.conjugate() * a.q.conjugate() * b.q).vec();
  return r;
}

CondensedGraph6::Linearised CondensedGraph6::linearise(size_t e) const {
  const CondensedEdge6& ed = edges_[e];
  const AnchorPose& a = states_[ed.from];
  const AnchorPose& b = states_[ed.to];
  const Eigen::Matrix3d RaT = a.q.conjugate().toRotationMatrix();
  const Eigen::Matrix3d RbT = b.q.conjugate().toRotationMatrix();
  const Eigen::Vector3d d = b.p - a.p;
  const Eigen::Quaterniond err = ed.q.conjugate() * a.q.conjugate() * b.q;
  Linearised L;
  L.r.head<3>() = RaT * d - ed.t;
  L.r.tail<3>() = 2.0 * err.vec();
  // R_a <- Exp(phi) R_a: R_a^T d <- R_a^T (d + [d]x phi). err <- err Exp(+-R_b^T phi) for b / a,
  // and 2 vec(err Exp(delta)) moves by (w I + [vec]x) delta.
  const Eigen::Matrix3d E = err.w() * Eigen::Matrix3d::Identity() + skew(err.vec());
  L.Ja.setZero();
  L.Jb.setZero();
  L.Ja.topLeftCorner<3, 3>() = -RaT;
  L.Ja.topRightCorner<3, 3>() = RaT * skew(d);
  L.Ja.bottomRightCorner<3, 3>() = -E * RbT;
  L.Jb.topLeftCorner<3, 3>() = RaT;
  L.Jb.bottomRightCorner<3, 3>() = E * RbT;
  const Matrix6d& W = sqrt_info_[e];
  L.r = W * L.r;
  L.Ja = W * L.Ja;
  L.Jb = W * L.Jb;
  return L;
}

int CondensedGraph6::solve(int max_iterations, double tolerance, bool* ok, bool* converged,
                           double function_tolerance, double chord) {
  return condensed_detail::gaussNewton<6>(
      edges_, fixed_, max_iterations, tolerance, function_tolerance, chord, ok, converged,
      [this](size_t e) { return linearise(e); },
      [this](size_t i, const Eigen::Ref<const Vector6d>& dx) {
        AnchorPose& s = states_[i];
        s.p += dx.head<3>();
        s.q = (rotationExp(dx.tail<3>()) * s.q).normalized();
      });
}

}  // namespace core
}  // namespace rover_loop_fusion
