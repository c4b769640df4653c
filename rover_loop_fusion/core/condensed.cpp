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

/// The upper triangle of the Gauss-Newton Hessian over the free anchors (4 columns each, at
/// col[i]; -1: a state that is not solved for) in compressed form, its structure built once:
/// where each edge's blocks J_u^T J_v go, so that an iteration adds them in place instead of
/// sorting every edge's triplets again.
class NormalMatrix {
 public:
  NormalMatrix(const std::vector<CondensedEdge>& edges, const std::vector<int>& col, int n) : H_(4 * n, 4 * n) {
    std::vector<Eigen::Triplet<double>> structure;
    structure.reserve(edges.size() * 64);
    for (const CondensedEdge& e : edges) {
      const int c[2] = {col[e.from], col[e.to]};
      for (int u = 0; u < 2; ++u)
        for (int v = 0; v < 2; ++v)
          if (c[u] >= 0 && c[v] >= 0 && c[u] <= c[v])  // the upper triangle's blocks
            for (int r = 0; r < 4; ++r)
              for (int s = 0; s < 4; ++s) structure.emplace_back(4 * c[u] + r, 4 * c[v] + s, 0.0);
    }
    H_.setFromTriplets(structure.begin(), structure.end());
    // Per edge and block (u, v): the value index of the block's first row in each of its 4
    // columns (a block's rows are contiguous: all 16 of its entries are in the structure).
    offsets_.assign(edges.size() * 16, -1);
    for (size_t k = 0; k < edges.size(); ++k) {
      const int c[2] = {col[edges[k].from], col[edges[k].to]};
      for (int u = 0; u < 2; ++u)
        for (int v = 0; v < 2; ++v) {
          if (c[u] < 0 || c[v] < 0 || c[u] > c[v]) continue;
          for (int s = 0; s < 4; ++s) {
            const int j = 4 * c[v] + s;
            const int* begin = H_.innerIndexPtr() + H_.outerIndexPtr()[j];
            const int* end = H_.innerIndexPtr() + H_.outerIndexPtr()[j + 1];
            offsets_[16 * k + 8 * u + 4 * v + s] =
                static_cast<int>(std::lower_bound(begin, end, 4 * c[u]) - H_.innerIndexPtr());
          }
        }
    }
  }
  void setZero() { std::fill(H_.valuePtr(), H_.valuePtr() + H_.nonZeros(), 0.0); }
  /// Adds edge k's blocks (its whitened Jacobians at its two ends).
  void add(size_t k, const Eigen::Matrix4d& Ja, const Eigen::Matrix4d& Jb) {
    const Eigen::Matrix4d* J[2] = {&Ja, &Jb};
    double* values = H_.valuePtr();
    for (int u = 0; u < 2; ++u)
      for (int v = 0; v < 2; ++v) {
        const int* at = &offsets_[16 * k + 8 * u + 4 * v];
        if (at[0] < 0) continue;
        const Eigen::Matrix4d B = J[u]->transpose() * (*J[v]);
        for (int s = 0; s < 4; ++s)
          for (int r = 0; r < 4; ++r) values[at[s] + r] += B(r, s);
      }
  }
  const Eigen::SparseMatrix<double>& matrix() const { return H_; }

 private:
  Eigen::SparseMatrix<double> H_;
  std::vector<int> offsets_;
};

/// The column (4 unknowns) of each free anchor (-1: held fixed, or the gauge) in an approximate
/// minimum degree order of the anchors' graph: the factorisation's fill-reducing ordering,
/// found on a quarter of the nodes and a sixteenth of the entries that the scalars have, and
/// the matrix assembled in that order, so that the factorisation reads it without a permuted
/// copy. *n: the number of free anchors.
std::vector<int> orderedColumns(const std::vector<CondensedEdge>& edges, const std::vector<bool>& fixed, int gauge,
                                int* n) {
  std::vector<int> col(fixed.size(), -1);
  int m = 0;
  for (size_t i = 0; i < fixed.size(); ++i)
    if (!fixed[i] && static_cast<int>(i) != gauge) col[i] = m++;
  *n = m;
  if (m == 0) return col;
  std::vector<Eigen::Triplet<double>> pattern;
  pattern.reserve(m + 2 * edges.size());
  for (int i = 0; i < m; ++i) pattern.emplace_back(i, i, 1.0);
  for (const CondensedEdge& e : edges) {
    const int a = col[e.from], b = col[e.to];
    if (a < 0 || b < 0) continue;
    pattern.emplace_back(a, b, 1.0);
    pattern.emplace_back(b, a, 1.0);
  }
  Eigen::SparseMatrix<double, Eigen::ColMajor, int> graph(m, m);
  graph.setFromTriplets(pattern.begin(), pattern.end());
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> order;  // order[k]: the k-th eliminated
  Eigen::AMDOrdering<int>()(graph, order);
  std::vector<int> position(m);
  for (int k = 0; k < m; ++k) position[order.indices()[k]] = k;
  for (int& c : col)
    if (c >= 0) c = position[c];
  return col;
}

/// The factorisation of the normal equations: their upper triangle, already in the order of
/// orderedColumns().
using NormalLdlt = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Upper, Eigen::NaturalOrdering<int>>;

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

bool CondensedGraph::marginal(int gauge, int query, const Eigen::Matrix3d& frame,
                              Eigen::Matrix4d* cov) const {
  if (gauge == query) {
    cov->setZero();
    return true;
  }
  int n = 0;
  const std::vector<int> col = orderedColumns(edges_, fixed_, gauge, &n);
  if (col[query] < 0) return false;
  NormalMatrix H(edges_, col, n);
  for (size_t e = 0; e < edges_.size(); ++e) {
    const Linearised L = linearise(e);
    H.add(e, L.Ja, L.Jb);
  }
  NormalLdlt ldlt(H.matrix());
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
  int n = 0;
  const std::vector<int> col = orderedColumns(edges_, fixed_, -1, &n);
  if (n == 0) {
    if (converged) *converged = true;
    return 0;
  }
  int it = 0;
  double previous_cost = -1.0;
  NormalLdlt ldlt;  // one symbolic analysis: the pattern stays
  NormalMatrix H(edges_, col, n);
  for (it = 1; it <= max_iterations; ++it) {
    H.setZero();
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
      H.add(e, L.Ja, L.Jb);
    }
    if (function_tolerance > 0 && previous_cost >= 0 &&
        std::abs(previous_cost - cost) <= function_tolerance * previous_cost) {
      if (converged) *converged = true;
      return it - 1;  // this iteration's update is not needed
    }
    previous_cost = cost;
    if (it == 1) ldlt.analyzePattern(H.matrix());
    ldlt.factorize(H.matrix());
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
