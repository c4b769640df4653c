// What the condensed graphs share (core/condensed.h: 4-DoF anchors, 4 unknowns each;
// core/condensed6.h: 6-DoF anchors, 6 each): the sparse normal equations over the free anchors
// in blocks of B unknowns, their fill-reducing order, their factorisation on those blocks, and
// weighted Gauss-Newton with Huber edges by iteratively reweighted least squares. Internal to
// the core.
#pragma once

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Sparse>  // AMDOrdering

#include <algorithm>
#include <cmath>
#include <limits>
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

template <int B>
using Blocks = std::vector<Eigen::Matrix<double, B, B>, Eigen::aligned_allocator<Eigen::Matrix<double, B, B>>>;

/// The upper triangle of the Gauss-Newton Hessian over the free anchors in B x B blocks (anchor
/// i's unknowns are block col[i]), block-compressed by columns, its structure built once: where
/// each edge's blocks J_u^T J_v go, so that an iteration adds them in place.
template <int B>
class NormalMatrix {
 public:
  using Block = Eigen::Matrix<double, B, B>;

  template <class Edge>
  NormalMatrix(const std::vector<Edge>& edges, const std::vector<int>& col, int n) : n_(n) {
    // Per block column its block rows (upper: row <= column), the diagonal included: counted,
    // placed in one array, then sorted and made unique per column (no vector per column).
    std::vector<int> first(n + 1, 0);
    for (int j = 0; j < n; ++j) ++first[j + 1];
    for (const Edge& e : edges) forUpperBlocks(col[e.from], col[e.to], [&](int, int, int, int cv) { ++first[cv + 1]; });
    for (int j = 0; j < n; ++j) first[j + 1] += first[j];
    std::vector<int> all(first[n]), fill(first.begin(), first.end() - 1);
    for (int j = 0; j < n; ++j) all[fill[j]++] = j;
    for (const Edge& e : edges)
      forUpperBlocks(col[e.from], col[e.to], [&](int, int, int cu, int cv) { all[fill[cv]++] = cu; });
    start_.assign(n + 1, 0);
    row_.reserve(all.size());
    for (int j = 0; j < n; ++j) {
      int* begin = all.data() + first[j];
      int* end = all.data() + first[j + 1];
      std::sort(begin, end);
      end = std::unique(begin, end);
      row_.insert(row_.end(), begin, end);
      start_[j + 1] = static_cast<int>(row_.size());
    }
    values_.assign(row_.size(), Block::Zero());
    offsets_.assign(edges.size() * 4, -1);  // per edge and block (u, v): its value index
    for (size_t k = 0; k < edges.size(); ++k)
      forUpperBlocks(col[edges[k].from], col[edges[k].to], [&](int u, int v, int cu, int cv) {
        const int* begin = row_.data() + start_[cv];
        const int* end = row_.data() + start_[cv + 1];
        offsets_[4 * k + 2 * u + v] = static_cast<int>(std::lower_bound(begin, end, cu) - row_.data());
      });
  }
  void setZero() { std::fill(values_.begin(), values_.end(), Block::Zero()); }
  /// Adds edge k's blocks (its whitened Jacobians at its two ends).
  void add(size_t k, const Block& Ja, const Block& Jb) {
    const Block* J[2] = {&Ja, &Jb};
    for (int u = 0; u < 2; ++u)
      for (int v = 0; v < 2; ++v) {
        const int at = offsets_[4 * k + 2 * u + v];
        if (at >= 0) values_[at].noalias() += J[u]->transpose() * (*J[v]);
      }
  }
  int blocks() const { return n_; }
  /// Block column j: rows row(p) and values value(p) for p in [begin(j), end(j)), rows increasing
  /// (the last is j, the diagonal block, whole).
  int begin(int j) const { return start_[j]; }
  int end(int j) const { return start_[j + 1]; }
  int row(int p) const { return row_[p]; }
  const Block& value(int p) const { return values_[p]; }

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

  int n_;
  std::vector<int> start_, row_;
  Blocks<B> values_;
  std::vector<int> offsets_;
};

/// A = L D L^T of a NormalMatrix in its own (already fill-reducing) order, on B x B blocks: L unit
/// lower block-triangular, D block-diagonal. T. Davis' up-looking LDL (the algorithm of Eigen's
/// SimplicialLDLT) with each scalar a fixed-size block: the elimination tree and the columns'
/// lengths once (analyze), the values per iteration (factorize).
template <int B>
class BlockLdlt {
 public:
  using Block = Eigen::Matrix<double, B, B>;

  void analyze(const NormalMatrix<B>& A) {
    const int n = A.blocks();
    parent_.assign(n, -1);
    count_.assign(n, 0);
    std::vector<int> flag(n);
    for (int k = 0; k < n; ++k) {
      flag[k] = k;
      for (int p = A.begin(k); p < A.end(k); ++p)
        for (int i = A.row(p); i < k && flag[i] != k; i = parent_[i]) {
          if (parent_[i] == -1) parent_[i] = k;
          ++count_[i];
          flag[i] = k;
        }
    }
    start_.assign(n + 1, 0);
    for (int k = 0; k < n; ++k) start_[k + 1] = start_[k] + count_[k];
    row_.assign(start_[n], 0);
    L_.assign(start_[n], Block::Zero());
    D_inv_.assign(n, Block::Zero());
  }

  /// False if a pivot block is not positive definite (the system is singular there).
  bool factorize(const NormalMatrix<B>& A) {
    const int n = A.blocks();
    Blocks<B> y(n, Block::Zero());
    std::vector<int> pattern(n), flag(n), filled(n, 0);
    for (int k = 0; k < n; ++k) {
      Block d = Block::Zero();
      int top = n;
      flag[k] = k;
      for (int p = A.begin(k); p < A.end(k); ++p) {
        int i = A.row(p);
        if (i == k) {
          d = A.value(p);
          continue;
        }
        y[i] = A.value(p);
        int len = 0;
        for (; flag[i] != k; i = parent_[i]) {
          pattern[len++] = i;
          flag[i] = k;
        }
        while (len > 0) pattern[--top] = pattern[--len];
      }
      for (; top < n; ++top) {
        const int i = pattern[top];
        const Block yi = y[i];
        y[i].setZero();
        const int stop = start_[i] + filled[i];
        for (int p = start_[i]; p < stop; ++p) y[row_[p]].noalias() -= L_[p] * yi;
        const Block l = yi.transpose() * D_inv_[i];
        d.noalias() -= l * yi;
        row_[stop] = k;
        L_[stop] = l;
        ++filled[i];
      }
      const Block sym = 0.5 * (d + d.transpose());
      Eigen::LLT<Block> llt(sym);
      if (llt.info() != Eigen::Success) return false;
      D_inv_[k] = llt.solve(Block::Identity());
      if (!D_inv_[k].allFinite()) return false;
    }
    return true;
  }

  /// x := A^-1 x (x: B rows per block, any number of columns).
  template <class Matrix>
  void solveInPlace(Matrix& x) const {
    const int n = static_cast<int>(D_inv_.size());
    for (int j = 0; j < n; ++j)
      for (int p = start_[j]; p < start_[j + 1]; ++p)
        x.template middleRows<B>(B * row_[p]).noalias() -= L_[p] * x.template middleRows<B>(B * j);
    for (int j = 0; j < n; ++j) x.template middleRows<B>(B * j) = (D_inv_[j] * x.template middleRows<B>(B * j)).eval();
    for (int j = n - 1; j >= 0; --j)
      for (int p = start_[j]; p < start_[j + 1]; ++p)
        x.template middleRows<B>(B * j).noalias() -= L_[p].transpose() * x.template middleRows<B>(B * row_[p]);
  }

 private:
  std::vector<int> parent_, count_, start_, row_;
  Blocks<B> L_;      // L's blocks below the diagonal, by column (rows row_)
  Blocks<B> D_inv_;  // D's blocks, inverted
};

/// Edge ed's linearisation *L reweighted by its Huber loss (IRLS); its cost (the Huber loss's
/// where it applies) added to *cost.
template <class Edge, class Linearisation>
void huberReweight(const Edge& ed, Linearisation* L, double* cost) {
  const double chi2 = L->r.squaredNorm();
  *cost += chi2;
  if (ed.huber <= 0) return;
  // the Huber loss's rho'(s) = delta / sqrt(s) beyond delta^2
  const int count = std::max(1, ed.count);
  const double s = chi2 / count;
  if (s > ed.huber * ed.huber) {
    *cost += count * (2.0 * ed.huber * std::sqrt(s) - ed.huber * ed.huber) - chi2;
    const double w = std::sqrt(ed.huber / std::sqrt(s));
    L->r *= w;
    L->Ja *= w;
    L->Jb *= w;
  }
}

/// The gradient of the weighted edges at the current states (and, with H, the normal matrix
/// added edge by edge); their cost added to *cost. `weighted(e, cost)`: edge e's linearisation.
template <int B, class Edge, class Weighted>
Eigen::VectorXd gradientPass(const std::vector<Edge>& edges, const std::vector<int>& col, int n, Weighted& weighted,
                             NormalMatrix<B>* H, double* cost) {
  Eigen::VectorXd g = Eigen::VectorXd::Zero(B * n);
  for (size_t e = 0; e < edges.size(); ++e) {
    const auto L = weighted(e, cost);
    const Edge& ed = edges[e];
    const Eigen::Matrix<double, B, B>* J[2] = {&L.Ja, &L.Jb};
    const int c[2] = {col[ed.from], col[ed.to]};
    for (int u = 0; u < 2; ++u)
      if (c[u] >= 0) g.template segment<B>(B * c[u]) += J[u]->transpose() * L.r;
    if (H) H->add(e, L.Ja, L.Jb);
  }
  return g;
}

/// Gauss-Newton on the free anchors (`fixed`: held), robust edges (`huber` > 0: Ceres' HuberLoss
/// of that scale on the chi-square of each of the edge's `count` measurements) by iteratively
/// reweighted least squares. `linearise(e)` gives edge e's residual `r` and Jacobians `Ja`, `Jb`
/// at its two ends (whitened and weighted, fixed-size B); `step(i, dx)` moves
/// anchor i by its update. Stops when the largest update is below `tolerance`, when the cost
/// changed by less than `function_tolerance` of itself (0: never), or after `max_iterations`;
/// returns the iterations run. *ok false: singular or not finite (states as after the last
/// good update). `chord` > 0: after a step at most `chord` times the one before, the next
/// iteration tries the last factorisation again (a chord step: the gradient is always the
/// current one, so the fixed point is Gauss-Newton's); a chord step larger than the step
/// before is not taken (the iteration factorises its own matrix and takes Gauss-Newton's
/// step instead), and a step that shrank by less than `chord` has the next iteration
/// factorise. 0: every iteration factorises.
template <int B, class Edge, class Linearise, class Step>
int gaussNewton(const std::vector<Edge>& edges, const std::vector<bool>& fixed, int max_iterations, double tolerance,
                double function_tolerance, double chord, bool* ok, bool* converged, Linearise linearise, Step step) {
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
  BlockLdlt<B> ldlt;  // one symbolic analysis: the pattern stays
  NormalMatrix<B> H(edges, col, n);
  bool refactor = true;
  double previous_step = std::numeric_limits<double>::infinity();
  // Edge e linearised at the current states and reweighted by its Huber loss; its cost (the
  // Huber loss's where it applies) added to *cost.
  auto weighted = [&](size_t e, double* cost) {
    auto L = linearise(e);  // r, Ja, Jb: Eigen fixed-size (B) vector and matrices
    huberReweight(edges[e], &L, cost);
    return L;
  };
  // The matrix at the current states, when a chord step was tried and not taken: the same
  // blocks the gradient pass computed, added in the same order.
  auto assemble = [&] {
    H.setZero();
    double unused = 0.0;
    for (size_t e = 0; e < edges.size(); ++e) {
      const auto L = weighted(e, &unused);
      H.add(e, L.Ja, L.Jb);
    }
  };
  for (it = 1; it <= max_iterations; ++it) {
    // An iteration that tries the last factorisation first (a chord step) assembles the
    // gradient alone; the matrix only if the chord step is not taken (assemble()).
    const bool assembled = refactor;
    if (assembled) H.setZero();
    double cost = 0.0;
    const Eigen::VectorXd g = gradientPass<B>(edges, col, n, weighted, assembled ? &H : nullptr, &cost);
    if (function_tolerance > 0 && previous_cost >= 0 &&
        std::abs(previous_cost - cost) <= function_tolerance * previous_cost) {
      if (converged) *converged = true;
      return it - 1;  // this iteration's update is not needed
    }
    previous_cost = cost;
    if (it == 1) ldlt.analyze(H);
    Eigen::VectorXd dx = -g;
    bool taken = false;
    if (!refactor) {  // the chord step, unless it grows
      ldlt.solveInPlace(dx);
      taken = dx.allFinite() && dx.cwiseAbs().maxCoeff() <= previous_step;
      if (!taken) dx = -g;
    }
    if (!taken) {  // Gauss-Newton's step
      if (!assembled) assemble();
      if (!ldlt.factorize(H)) {
        *ok = false;
        return it;
      }
      ldlt.solveInPlace(dx);
      *ok = dx.allFinite();
      if (!*ok) return it;
    }
    for (size_t i = 0; i < fixed.size(); ++i)
      if (col[i] >= 0) step(i, dx.template segment<B>(B * col[i]));
    const double largest = dx.cwiseAbs().maxCoeff();
    refactor = chord <= 0 || largest > chord * previous_step;
    previous_step = largest;
    if (largest < tolerance) {
      if (converged) *converged = true;
      break;
    }
  }
  return std::min(it, max_iterations);
}

}  // namespace condensed_detail
}  // namespace core
}  // namespace rover_loop_fusion
