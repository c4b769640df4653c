#include "rover_loop_fusion/core/condensed.h"

#include "rover_loop_fusion/core/condensed_solver.h"
#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>

namespace rover_loop_fusion {
namespace core {

using condensed_detail::orderedColumns;

int CondensedGraph::addAnchor(const AnchorState& state, double pitch, double roll, bool fixed) {
  states_.push_back(state);
  pitch_roll_trig_.emplace_back(std::cos(pitch), std::sin(pitch), std::cos(roll), std::sin(roll));
  fixed_.push_back(fixed);
  return static_cast<int>(states_.size()) - 1;
}

bool CondensedGraph::sqrtInformation(const Eigen::Matrix4d& covariance, Eigen::Matrix4d* sqrt_info) {
  const Eigen::Matrix4d C = 0.5 * (covariance + covariance.transpose());
  if (!C.allFinite()) return false;
  Eigen::LLT<Eigen::Matrix4d> llt(C);
  if (llt.info() != Eigen::Success) return false;
  // information = C^-1 = L^-T L^-1 (C = L L^T): sqrt information = L^-1.
  *sqrt_info = llt.matrixL().solve(Eigen::Matrix4d::Identity());
  return sqrt_info->allFinite();
}

bool CondensedGraph::addEdge(const CondensedEdge& edge) {
  Eigen::Matrix4d Linv;
  if (!sqrtInformation(edge.covariance, &Linv)) return false;
  addEdge(edge, Linv);
  return true;
}

void CondensedGraph::addEdge(const CondensedEdge& edge, const Eigen::Matrix4d& sqrt_info) {
  edges_.push_back(edge);
  sqrt_info_.push_back(sqrt_info);
}

CondensedGraph::Linearised CondensedGraph::linearise(size_t e) const {
  const CondensedEdge& ed = edges_[e];
  const AnchorState& a = states_[ed.from];
  const AnchorState& b = states_[ed.to];
  const Eigen::Matrix3d Ra = rotationOf(ed.from);
  const Eigen::Vector3d d = b.p - a.p;
  Linearised L;
  L.r = residual(e, Ra);
  L.Ja.setZero();
  L.Jb.setZero();
  L.Ja.topLeftCorner<3, 3>() = -Ra.transpose();
  L.Ja.topRightCorner<3, 1>() = -Ra.transpose() * (yawGenerator() * d);
  L.Ja(3, 3) = -1.0;
  L.Jb.topLeftCorner<3, 3>() = Ra.transpose();
  L.Jb(3, 3) = 1.0;
  const Eigen::Matrix4d W = std::sqrt(std::max(0.0, ed.weight)) * sqrt_info_[e];
  L.r = W * L.r;
  L.Ja = W * L.Ja;
  L.Jb = W * L.Jb;
  return L;
}

Eigen::Matrix3d CondensedGraph::rotationOf(int anchor) const {
  const double yaw = states_[anchor].yaw;
  const Eigen::Vector4d& pr = pitch_roll_trig_[anchor];
  return rotationFromCosSin(std::cos(yaw), std::sin(yaw), pr[0], pr[1], pr[2], pr[3]);
}

Eigen::Vector4d CondensedGraph::residual(size_t e) const { return residual(e, rotationOf(edges_[e].from)); }

Eigen::Vector4d CondensedGraph::residual(size_t e, const Eigen::Matrix3d& Ra) const {
  const CondensedEdge& ed = edges_[e];
  const AnchorState& a = states_[ed.from];
  const AnchorState& b = states_[ed.to];
  Eigen::Vector4d r;
  r.head<3>() = Ra.transpose() * (b.p - a.p) - ed.t;
  r[3] = wrapAngleNear(b.yaw - a.yaw - ed.yaw);
  return r;
}

double CondensedGraph::chi2(size_t e) const { return (sqrt_info_[e] * residual(e)).squaredNorm(); }

bool CondensedGraph::marginal(int gauge, int query, const Eigen::Matrix3d& frame,
                              Eigen::Matrix4d* cov) const {
  if (gauge == query) {
    cov->setZero();
    return true;
  }
  int n = 0;
  const std::vector<int> col = orderedColumns(edges_, fixed_, gauge, &n);
  if (col[query] < 0) return false;
  condensed_detail::NormalMatrix<4> H(edges_, col, n);
  for (size_t e = 0; e < edges_.size(); ++e) {
    const Linearised L = linearise(e);
    H.add(e, L.Ja, L.Jb);
  }
  condensed_detail::BlockLdlt<4> ldlt;
  ldlt.analyze(H);
  if (!ldlt.factorize(H)) return false;
  Eigen::Matrix<double, Eigen::Dynamic, 4> X = Eigen::Matrix<double, Eigen::Dynamic, 4>::Zero(4 * n, 4);
  X.block<4, 4>(4 * col[query], 0).setIdentity();
  ldlt.solveInPlace(X);
  if (!X.allFinite()) return false;
  const Eigen::Matrix4d Cw = X.block<4, 4>(4 * col[query], 0);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = frame.transpose();
  *cov = T * (0.5 * (Cw + Cw.transpose())) * T.transpose();
  return cov->allFinite() && (*cov)(3, 3) > 0.0;
}

int CondensedGraph::solve(int max_iterations, double tolerance, bool* ok, bool* converged,
                          double function_tolerance, double chord) {
  return condensed_detail::gaussNewton<4>(
      edges_, fixed_, max_iterations, tolerance, function_tolerance, chord, ok, converged,
      [this](size_t e) { return linearise(e); },
      [this](size_t i, const Eigen::Ref<const Eigen::Vector4d>& dx) {
        states_[i].p += dx.head<3>();
        states_[i].yaw = wrapAngleNear(states_[i].yaw + dx[3]);
      });
}

}  // namespace core
}  // namespace rover_loop_fusion
