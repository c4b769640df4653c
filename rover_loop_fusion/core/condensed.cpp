#include "rover_loop_fusion/core/condensed.h"

#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Cholesky>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>

namespace rover_loop_fusion {
namespace core {

namespace {

/// The edge's blocks J_u^T J_v of the Gauss-Newton Hessian at the columns c[0], c[1] (-1: a
/// state that is not solved for).
void addHessianBlocks(const Eigen::Matrix4d* const J[2], const int c[2], std::vector<Eigen::Triplet<double>>* trip) {
  for (int u = 0; u < 2; ++u) {
    if (c[u] < 0) continue;
    for (int v = 0; v < 2; ++v) {
      if (c[v] < 0) continue;
      const Eigen::Matrix4d B = J[u]->transpose() * (*J[v]);
      for (int r = 0; r < 4; ++r)
        for (int s = 0; s < 4; ++s) trip->emplace_back(4 * c[u] + r, 4 * c[v] + s, B(r, s));
    }
  }
}

}  // namespace

int CondensedGraph::addAnchor(const AnchorState& state, double pitch, double roll, bool fixed) {
  states_.push_back(state);
  pitch_.push_back(pitch);
  roll_.push_back(roll);
  fixed_.push_back(fixed);
  return static_cast<int>(states_.size()) - 1;
}

bool CondensedGraph::addEdge(const CondensedEdge& edge) {
  const Eigen::Matrix4d C = 0.5 * (edge.covariance + edge.covariance.transpose());
  if (!C.allFinite()) return false;
  Eigen::LLT<Eigen::Matrix4d> llt(C);
  if (llt.info() != Eigen::Success) return false;
  // information = C^-1 = L^-T L^-1 (C = L L^T): sqrt information = L^-1.
  const Eigen::Matrix4d Linv = llt.matrixL().solve(Eigen::Matrix4d::Identity());
  if (!Linv.allFinite()) return false;
  edges_.push_back(edge);
  sqrt_info_.push_back(Linv);
  return true;
}

CondensedGraph::Linearised CondensedGraph::linearise(size_t e) const {
  const CondensedEdge& ed = edges_[e];
  const AnchorState& a = states_[ed.from];
  const AnchorState& b = states_[ed.to];
  const Eigen::Matrix3d Ra = yawPitchRollToRotation(a.yaw, pitch_[ed.from], roll_[ed.from]);
  const Eigen::Vector3d d = b.p - a.p;
  Linearised L;
  L.r = residual(e);
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

Eigen::Vector4d CondensedGraph::residual(size_t e) const {
  const CondensedEdge& ed = edges_[e];
  const AnchorState& a = states_[ed.from];
  const AnchorState& b = states_[ed.to];
  const Eigen::Matrix3d Ra = yawPitchRollToRotation(a.yaw, pitch_[ed.from], roll_[ed.from]);
  Eigen::Vector4d r;
  r.head<3>() = Ra.transpose() * (b.p - a.p) - ed.t;
  r[3] = wrapAngle(b.yaw - a.yaw - ed.yaw);
  return r;
}

double CondensedGraph::chi2(size_t e) const { return (sqrt_info_[e] * residual(e)).squaredNorm(); }

namespace {

/// Normal equations over the free anchors (column index per anchor, -1 if fixed).
struct Normal {
  std::vector<int> col;
  int n = 0;
  std::vector<Eigen::Triplet<double>> H;
  Eigen::VectorXd g;
};

}  // namespace

bool CondensedGraph::marginal(int gauge, int query, const Eigen::Matrix3d& frame,
                              Eigen::Matrix4d* cov) const {
  if (gauge == query) {
    cov->setZero();
    return true;
  }
  std::vector<int> col(states_.size(), -1);
  int n = 0;
  for (size_t i = 0; i < states_.size(); ++i)
    if (!fixed_[i] && static_cast<int>(i) != gauge) col[i] = n++;
  if (col[query] < 0) return false;
  std::vector<Eigen::Triplet<double>> trip;
  trip.reserve(edges_.size() * 64);
  for (size_t e = 0; e < edges_.size(); ++e) {
    const Linearised L = linearise(e);
    const int ia = col[edges_[e].from], ib = col[edges_[e].to];
    const Eigen::Matrix4d* J[2] = {&L.Ja, &L.Jb};
    const int c[2] = {ia, ib};
    addHessianBlocks(J, c, &trip);
  }
  Eigen::SparseMatrix<double> H(4 * n, 4 * n);
  H.setFromTriplets(trip.begin(), trip.end());
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(H);
  if (ldlt.info() != Eigen::Success) return false;
  Eigen::MatrixXd rhs = Eigen::MatrixXd::Zero(4 * n, 4);
  rhs.block<4, 4>(4 * col[query], 0).setIdentity();
  const Eigen::MatrixXd X = ldlt.solve(rhs);
  if (ldlt.info() != Eigen::Success || !X.allFinite()) return false;
  const Eigen::Matrix4d Cw = X.block<4, 4>(4 * col[query], 0);
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = frame.transpose();
  *cov = T * (0.5 * (Cw + Cw.transpose())) * T.transpose();
  return cov->allFinite() && (*cov)(3, 3) > 0.0;
}

int CondensedGraph::solve(int max_iterations, double tolerance, bool* ok, bool* converged,
                          double function_tolerance) {
  *ok = true;
  if (converged) *converged = false;
  std::vector<int> col(states_.size(), -1);
  int n = 0;
  for (size_t i = 0; i < states_.size(); ++i)
    if (!fixed_[i]) col[i] = n++;
  if (n == 0) {
    if (converged) *converged = true;
    return 0;
  }
  int it = 0;
  double previous_cost = -1.0;
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt;  // one ordering: the pattern stays
  for (it = 1; it <= max_iterations; ++it) {
    std::vector<Eigen::Triplet<double>> trip;
    trip.reserve(edges_.size() * 64);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(4 * n);
    double cost = 0.0;
    for (size_t e = 0; e < edges_.size(); ++e) {
      Linearised L = linearise(e);
      const CondensedEdge& ed = edges_[e];
      const double chi2 = L.r.squaredNorm();
      cost += chi2;
      if (ed.huber > 0) {  // IRLS: the Huber loss's rho'(s) = delta / sqrt(s) beyond delta^2
        const int count = std::max(1, ed.count);
        const double s = chi2 / count;
        if (s > ed.huber * ed.huber) {
          cost += count * (2.0 * ed.huber * std::sqrt(s) - ed.huber * ed.huber) - chi2;
          const double w = std::sqrt(ed.huber / std::sqrt(s));
          L.r *= w;
          L.Ja *= w;
          L.Jb *= w;
        }
      }
      const Eigen::Matrix4d* J[2] = {&L.Ja, &L.Jb};
      const int c[2] = {col[ed.from], col[ed.to]};
      for (int u = 0; u < 2; ++u)
        if (c[u] >= 0) g.segment<4>(4 * c[u]) += J[u]->transpose() * L.r;
      addHessianBlocks(J, c, &trip);
    }
    if (function_tolerance > 0 && previous_cost >= 0 &&
        std::abs(previous_cost - cost) <= function_tolerance * previous_cost) {
      if (converged) *converged = true;
      return it - 1;  // this iteration's update is not needed
    }
    previous_cost = cost;
    Eigen::SparseMatrix<double> H(4 * n, 4 * n);
    H.setFromTriplets(trip.begin(), trip.end());
    if (it == 1) ldlt.analyzePattern(H);
    ldlt.factorize(H);
    if (ldlt.info() != Eigen::Success) {
      *ok = false;
      return it;
    }
    const Eigen::VectorXd dx = -ldlt.solve(g);
    if (ldlt.info() != Eigen::Success || !dx.allFinite()) {
      *ok = false;
      return it;
    }
    for (size_t i = 0; i < states_.size(); ++i) {
      if (col[i] < 0) continue;
      states_[i].p += dx.segment<3>(4 * col[i]);
      states_[i].yaw = wrapAngle(states_[i].yaw + dx[4 * col[i] + 3]);
    }
    if (dx.cwiseAbs().maxCoeff() < tolerance) {
      if (converged) *converged = true;
      break;
    }
  }
  return std::min(it, max_iterations);
}

}  // namespace core
}  // namespace rover_loop_fusion
