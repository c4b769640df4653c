// The condensed 6-DoF pose graph of a condensed trial (mode 6dof; the 4-DoF one:
// core/condensed.h): anchor keyframes with full poses, joined by edges; a chain of odometry
// between two anchors is one edge with the composed relative pose and the chain's covariance
// (KeyframeGraph's chain model: condensed_trial.cpp). Gauss-Newton on the anchors, O(anchors).
//
// Residual of an edge i -> j (core/cost_functions.h's SixDofEdgeError before its sigmas):
//   r_t = R_i^T (p_j - p_i) - t_ij,  r_q = 2 vec(q_ij^-1 q_i^-1 q_j),
// weighted by the edge's square-root information. Perturbations: world-frame position, and a
// rotation about world axes (R <- Exp(phi) R).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <vector>

namespace rover_loop_fusion {
namespace core {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;

struct AnchorPose {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
};

struct CondensedEdge6 {
  int from = -1, to = -1;  ///< anchor indices
  Eigen::Vector3d t = Eigen::Vector3d::Zero();           ///< measured position of `to` in `from`'s frame
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();  ///< measured rotation of `to` in `from`'s frame
  Matrix6d covariance = Matrix6d::Identity();             ///< of the residual (r_t, r_q)
  /// Huber loss of this scale on the chi-square of each of the `count` measurements the edge
  /// stands for (as CondensedEdge). 0 = none.
  double huber = 0.0;
  int count = 1;
};

class CondensedGraph6 {
 public:
  int addAnchor(const AnchorPose& pose, bool fixed);
  /// False (and nothing added) if the covariance is not symmetric positive definite or the
  /// measurement is not finite.
  bool addEdge(const CondensedEdge6& edge);
  size_t anchorCount() const { return states_.size(); }
  size_t edgeCount() const { return edges_.size(); }
  const AnchorPose& state(int i) const { return states_[i]; }
  /// The residual (6) of edge e at the current states (not whitened).
  Vector6d residual(size_t e) const;
  /// As CondensedGraph::solve.
  int solve(int max_iterations, double tolerance, bool* ok, bool* converged = nullptr,
            double function_tolerance = 0.0, double chord = 0.0);

 private:
  struct Linearised {
    Vector6d r;
    Matrix6d Ja, Jb;  // whitened
  };
  Linearised linearise(size_t e) const;

  std::vector<AnchorPose> states_;
  std::vector<bool> fixed_;
  std::vector<CondensedEdge6> edges_;
  std::vector<Matrix6d> sqrt_info_;
};

}  // namespace core
}  // namespace rover_loop_fusion
