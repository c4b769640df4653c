// The condensed 4-DoF pose graph: a few anchor keyframes (the ends of loops, the candidate's
// match and query, sequence ends) joined by edges; a chain of odometry between two anchors is
// one edge with the composed relative pose and the chain's covariance (core/drift.h). For
// the linearised problem this is exact: eliminating the inner keyframes of a chain leaves
// exactly that edge. Everything here costs O(anchors), whatever the run's length.
//
// - marginal(): covariance of one anchor relative to another (held fixed) through every
//   edge, loops included: the uncertainty the gate compares the innovation with.
// - solve(): weighted Gauss-Newton on the anchors (the estimate X of the anchors).
// - the inner keyframes of a chain follow from its ends by the conditional mean of the chain
//   model (ChainMoments::cross), as the full linear solve would place them.
//
// Residual of an edge i -> j (loop_fusion's 4-DoF form, core/cost_functions.h):
//   r_t = R_i^T (p_j - p_i) - t_ij,  r_yaw = wrap(yaw_j - yaw_i - yaw_ij),
// R_i = Rz(yaw_i) Ry(pitch_i) Rx(roll_i), weighted by the edge's square-root information.
// Perturbations: world-frame position and yaw about world z.
#pragma once

#include <Eigen/Core>

#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// Position and yaw of an anchor (pitch and roll stay those of its VIO pose).
struct AnchorState {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  double yaw = 0.0;
};

struct CondensedEdge {
  int from = -1, to = -1;  ///< anchor indices
  Eigen::Vector3d t = Eigen::Vector3d::Zero();  ///< measured position of `to` in `from`'s frame
  double yaw = 0.0;                              ///< measured yaw of `to` minus yaw of `from`
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Identity();
  /// Robust edge (solve() only): Huber loss of this scale on the chi-square of each of the
  /// `count` measurements the edge stands for (loops merged into one edge: covariance / count),
  /// as Ceres' HuberLoss on loop_fusion's loop residuals. 0 = none.
  double huber = 0.0;
  int count = 1;
  /// Scales the edge's information (a graduated non-convexity weight; 0: the edge is left out).
  double weight = 1.0;
};

class CondensedGraph {
 public:
  /// Adds an anchor with its state, the pitch/roll of its VIO pose, and whether it is held fixed.
  int addAnchor(const AnchorState& state, double pitch, double roll, bool fixed);
  /// False (and nothing added) if the covariance is not symmetric positive definite.
  bool addEdge(const CondensedEdge& edge);
  /// The same with the square-root information of its covariance already known
  /// (sqrtInformation() of edge.covariance).
  void addEdge(const CondensedEdge& edge, const Eigen::Matrix4d& sqrt_info);
  /// L^-1 of the covariance's Cholesky factor L (L^-T L^-1 = covariance^-1), of its symmetric
  /// part; false if that is not positive definite or not finite.
  static bool sqrtInformation(const Eigen::Matrix4d& covariance, Eigen::Matrix4d* sqrt_info);
  size_t anchorCount() const { return states_.size(); }
  size_t edgeCount() const { return edges_.size(); }
  const AnchorState& state(int i) const { return states_[i]; }
  void setFixed(int i, bool fixed) { fixed_[i] = fixed; }
  void setWeight(size_t e, double weight) { edges_[e].weight = weight; }
  const CondensedEdge& edge(size_t e) const { return edges_[e]; }

  /// The residual (4) of edge e at the current states; its chi-square via the information
  /// (whatever its weight).
  Eigen::Vector4d residual(size_t e) const;
  double chi2(size_t e) const;

  /// Covariance (4x4) of anchor `query` relative to anchor `gauge` (held fixed, as are the
  /// anchors marked fixed), translation in the frame `frame` (usually R of the gauge). False if
  /// the linear system is singular (query not tied to the gauge).
  bool marginal(int gauge, int query, const Eigen::Matrix3d& frame, Eigen::Matrix4d* cov) const;

  /// Gauss-Newton on the free anchors (robust edges by iteratively reweighted least squares);
  /// returns iterations run. Stops when the largest update
  /// is below `tolerance` or after `max_iterations`. False in *ok if the system was singular or
  /// the solution not finite (states then unchanged since the last good iterate).
  /// Also stops when the cost changed by less than `function_tolerance` of itself in an
  /// iteration (as Ceres; 0: never). *converged (optional): whether it stopped on a tolerance.
  /// `chord` > 0 reuses the last factorisation while the steps shrink by that factor (same
  /// fixed point; core/condensed_solver.h); 0: a factorisation per iteration.
  int solve(int max_iterations, double tolerance, bool* ok, bool* converged = nullptr,
            double function_tolerance = 0.0, double chord = 0.0);

 private:
  struct Linearised {
    Eigen::Vector4d r;
    Eigen::Matrix4d Ja, Jb;  // whitened
  };
  Linearised linearise(size_t e) const;
  /// residual(e) with the rotation of its first anchor given (linearise needs it too).
  Eigen::Vector4d residual(size_t e, const Eigen::Matrix3d& Ra) const;
  Eigen::Matrix3d rotationOf(int anchor) const;

  std::vector<AnchorState> states_;
  // Per anchor: the cosine and sine of its pitch, then of its roll (fixed; rotationOf).
  std::vector<Eigen::Vector4d, Eigen::aligned_allocator<Eigen::Vector4d>> pitch_roll_trig_;
  std::vector<bool> fixed_;
  std::vector<CondensedEdge> edges_;
  std::vector<Eigen::Matrix4d> sqrt_info_;  // upper L with L^T L = covariance^-1
};

}  // namespace core
}  // namespace rover_loop_fusion
