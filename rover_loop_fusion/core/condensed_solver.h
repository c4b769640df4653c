// What the condensed graphs share (core/condensed.h: 4-DoF anchors, 4 unknowns each;
// core/condensed6.h: 6-DoF anchors, 6 each): the sparse normal equations over the free anchors
// in blocks of B unknowns, their fill-reducing order, and weighted Gauss-Newton with Huber edges
// by iteratively reweighted least squares. Internal to the core.
#pragma once

#include <Eigen/Core>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <vector>

namespace rover_loop_fusion {
namespace core {
namespace condensed_detail {

/// The column block of each free anchor (-1: held fixed, or the gauge) in an approximate
/// minimum degree order of the anchors' graph: the factorisation's fill-reducing ordering,
/// found on one node per anchor instead of per unknown, and the matrix assembled in that order,
/// so that the factorisation reads it without a permuted copy. *n: the number of free anchors.
/// `Edge`: anything with anchor indices `from` and `to`.
template <class Edge>
std::vector<int> orderedColumns(const std::vector<Edge>& edges, const std::vector<bool>& fixed, int gauge, int* n) {
  std::vector<int> col(fixed.size(), -1);
  int m = 0;
  for (size_t i = 0; i < fixed.size(); ++i)
    if (!fixed[i] && static_cast<int>(i) != gauge) col[i] = m++;
  *n = m;
  if (m == 0) return col;
  std::vector<Eigen::Triplet<double>> pattern;
  pattern.reserve(m + 2 * edges.size());
  for (int i = 0; i < m; ++i) pattern.emplace_back(i, i, 1.0);
  for (const Edge& e : edges) {
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

/// The upper triangle of the Gauss-Newton Hessian over the free anchors (B columns each, at
/// B * col[i]) in compressed form, its structure built once: where each edge's blocks
/// J_u^T J_v go, so that an iteration adds them in place instead of sorting every edge's
/// triplets again.
template <int B>
class NormalMatrix {
 public:
  using Block = Eigen::Matrix<double, B, B>;

  template <class Edge>
  NormalMatrix(const std::vector<Edge>& edges, const std::vector<int>& col, int n) : H_(B * n, B * n) {
    std::vector<Eigen::Triplet<double>> structure;
    structure.reserve(edges.size() * 4 * B * B);
    for (const Edge& e : edges)
      forUpperBlocks(col[e.from], col[e.to], [&](int, int, int cu, int cv) {
        for (int r = 0; r < B; ++r)
          for (int s = 0; s < B; ++s) structure.emplace_back(B * cu + r, B * cv + s, 0.0);
      });
    H_.setFromTriplets(structure.begin(), structure.end());
    // Per edge and block (u, v): the value index of the block's first row in each of its B
    // columns (a block's rows are contiguous: all B * B of its entries are in the structure).
    offsets_.assign(edges.size() * 4 * B, -1);
    for (size_t k = 0; k < edges.size(); ++k)
      forUpperBlocks(col[edges[k].from], col[edges[k].to], [&](int u, int v, int cu, int cv) {
        for (int s = 0; s < B; ++s) {
          const int j = B * cv + s;
          const int* begin = H_.innerIndexPtr() + H_.outerIndexPtr()[j];
          const int* end = H_.innerIndexPtr() + H_.outerIndexPtr()[j + 1];
          offsets_[4 * B * k + 2 * B * u + B * v + s] =
              static_cast<int>(std::lower_bound(begin, end, B * cu) - H_.innerIndexPtr());
        }
      });
  }
  void setZero() { std::fill(H_.valuePtr(), H_.valuePtr() + H_.nonZeros(), 0.0); }
  /// Adds edge k's blocks (its whitened Jacobians at its two ends).
  void add(size_t k, const Block& Ja, const Block& Jb) {
    const Block* J[2] = {&Ja, &Jb};
    double* values = H_.valuePtr();
    for (int u = 0; u < 2; ++u)
      for (int v = 0; v < 2; ++v) {
        const int* at = &offsets_[4 * B * k + 2 * B * u + B * v];
        if (at[0] < 0) continue;
        const Block M = J[u]->transpose() * (*J[v]);
        for (int s = 0; s < B; ++s)
          for (int r = 0; r < B; ++r) values[at[s] + r] += M(r, s);
      }
  }
  const Eigen::SparseMatrix<double>& matrix() const { return H_; }

 private:
  /// f(u, v, col_u, col_v) for each block (u, v) of an edge with ends in columns c0, c1 that
  /// lies in the upper triangle (both ends free).
  template <class F>
  static void forUpperBlocks(int c0, int c1, F f) {
    const int c[2] = {c0, c1};
    for (int u = 0; u < 2; ++u)
      for (int v = 0; v < 2; ++v)
        if (c[u] >= 0 && c[v] >= 0 && c[u] <= c[v]) f(u, v, c[u], c[v]);
  }

  Eigen::SparseMatrix<double> H_;
  std::vector<int> offsets_;
};

/// The factorisation of the normal equations: their upper triangle, already in the order of
/// orderedColumns().
using NormalLdlt = Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Upper, Eigen::NaturalOrdering<int>>;

/// Gauss-Newton on the free anchors (`fixed`: held), robust edges (`huber` > 0: Ceres' HuberLoss
/// of that scale on the chi-square of each of the edge's `count` measurements) by iteratively
/// reweighted least squares. `linearise(e)` gives edge e's residual `r` and Jacobians `Ja`, `Jb`
/// at its two ends (whitened and weighted, fixed-size B); `step(i, dx)` moves
/// anchor i by its update. Stops when the largest update is below `tolerance`, when the cost
/// changed by less than `function_tolerance` of itself (0: never), or after `max_iterations`;
/// returns the iterations run. *ok false: singular or not finite (states as after the last
/// good update).
template <int B, class Edge, class Linearise, class Step>
int gaussNewton(const std::vector<Edge>& edges, const std::vector<bool>& fixed, int max_iterations, double tolerance,
                double function_tolerance, bool* ok, bool* converged, Linearise linearise, Step step) {
  *ok = true;
  if (converged) *converged = false;
  int n = 0;
  const std::vector<int> col = orderedColumns(edges, fixed, -1, &n);
  if (n == 0) {
    if (converged) *converged = true;
    return 0;
  }
  int it = 0;
  double previous_cost = -1.0;
  NormalLdlt ldlt;  // one symbolic analysis: the pattern stays
  NormalMatrix<B> H(edges, col, n);
  for (it = 1; it <= max_iterations; ++it) {
    H.setZero();
    Eigen::VectorXd g = Eigen::VectorXd::Zero(B * n);
    double cost = 0.0;
    for (size_t e = 0; e < edges.size(); ++e) {
      auto L = linearise(e);  // r, Ja, Jb: Eigen fixed-size (B) vector and matrices
      const Edge& ed = edges[e];
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
      const Eigen::Matrix<double, B, B>* J[2] = {&L.Ja, &L.Jb};
      const int c[2] = {col[ed.from], col[ed.to]};
      for (int u = 0; u < 2; ++u)
        if (c[u] >= 0) g.template segment<B>(B * c[u]) += J[u]->transpose() * L.r;
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
    for (size_t i = 0; i < fixed.size(); ++i)
      if (col[i] >= 0) step(i, dx.template segment<B>(B * col[i]));
    if (dx.cwiseAbs().maxCoeff() < tolerance) {
      if (converged) *converged = true;
      break;
    }
  }
  return std::min(it, max_iterations);
}

}  // namespace condensed_detail
}  // namespace core
}  // namespace rover_loop_fusion
