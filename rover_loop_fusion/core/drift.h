// The odometry drift model and the covariance of a chain of odometry in O(1).
//
// Odometry noise of the step from keyframe j-1 to keyframe j (length l_j = |p_j - p_{j-1}|),
// in the frame of keyframe j (as gtsam's BetweenFactor: right perturbation):
//   translation x, y: sigma_xy^2 * l'   z: sigma_z^2 * l'   yaw: sigma_yaw^2 * l'
// with l' = max(l_j, min_step) (a rotation in place still drifts). 4-DoF: the error of the
// step is u_j = (R_j v_j, w_j) in the world frame (position, yaw about world z).
//
// The error of keyframe k relative to keyframe a (a held fixed), world frame:
//   e_p = sum_{j in (a,k]} R_j v_j + E (p_k - p_j) w_j,   e_yaw = sum_{j in (a,k]} w_j,
// E = [e_z]x: the yaw error of step j turns everything after keyframe j about p_j. Its
// covariance is sum_j H(p_k - p_j) W_j H(p_k - p_j)^T with H(d) = [[I, E d], [0, 1]], a
// quadratic in p_k whose coefficients are sums over j of W_j, W_j p_j^T and W_j p_j p_j^T:
// prefix sums give it for any pair (a, k) in O(1) (ChainMoments). The same sums give the
// cross-covariance of the errors at two keyframes k <= b, which is what carries a correction
// of a chain's ends to its inner keyframes (core/condensed.h).
//
// Checked against step-by-step sums and gtsam's marginals (docs/method.md).
#pragma once

#include <Eigen/Core>

#include <vector>

namespace rover_loop_fusion {
namespace core {

/// Drift rates of the odometry: standard deviations per square root of a metre travelled.
struct DriftModel {
  double sigma_xy = 0.05;    ///< m / sqrt(m), horizontal translation
  double sigma_z = 0.025;    ///< m / sqrt(m), vertical translation
  double sigma_yaw = 0.0035; ///< rad / sqrt(m)
  double min_step = 0.05;    ///< m: every step counts as at least this long

  /// Covariance (x, y, z, yaw; frame of the keyframe the step ends at) of a step of length l.
  Eigen::Matrix4d stepCovariance(double length) const;
};

/// Keyframe j (0, 1, ...) of a chain: its position, its rotation (full, world frame) and the
/// covariance of the step that ends at it (j >= 1). What ChainMoments sums; its owner keeps
/// them (the pose graph's keyframes), so that the moments hold only their checkpoints.
class ChainSteps {
 public:
  virtual ~ChainSteps() = default;
  virtual Eigen::Vector3d position(size_t j) const = 0;
  virtual Eigen::Matrix3d rotation(size_t j) const = 0;
  virtual Eigen::Matrix4d stepCovariance(size_t j) const = 0;
};

/// Prefix sums of the step moments of one chain of keyframes (ChainSteps), indexed 0..size()-1
/// within the chain; step j (j >= 1) goes from j-1 to j. Holds a checkpoint of the sums every
/// kStride keyframes (68 bytes per keyframe); the steps since the last one are summed on each
/// query, from the same ChainSteps (unchanged since they were added).
class ChainMoments {
 public:
  /// Extends the sums to the first n keyframes of `steps` (n >= size()).
  void extend(const ChainSteps& steps, size_t n);
  size_t size() const { return n_; }
  void clear();

  /// Cov(e_k, e_b) of the chain errors relative to keyframe a (a <= k <= b), world frame
  /// (x, y, z, yaw about world z). k == b gives the covariance of keyframe b relative to a.
  Eigen::Matrix4d cross(const ChainSteps& steps, size_t a, size_t k, size_t b) const;
  /// Covariance of the pose of b relative to a (a < b, a fixed), translation expressed in
  /// the frame `Ra` (normally a's rotation: the 4-DoF residual's R_a^T), yaw.
  Eigen::Matrix4d relative(const ChainSteps& steps, size_t a, size_t b, const Eigen::Matrix3d& Ra) const;

  /// The six sums over steps (0, k]: A = sum W_tt, b = sum W_ty, Bp = sum W_ty p^T,
  /// c = sum W_yy, cp = sum W_yy p, Cpp = sum W_yy p p^T.
  struct Sums {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    Eigen::Matrix3d Bp = Eigen::Matrix3d::Zero();
    double c = 0.0;
    Eigen::Vector3d cp = Eigen::Vector3d::Zero();
    Eigen::Matrix3d Cpp = Eigen::Matrix3d::Zero();
    void add(const Sums& o, double sign);
  };
  /// Sums over (0, k]: a stored checkpoint every kStride keyframes plus the steps after it.
  Sums prefix(const ChainSteps& steps, size_t k) const;
  /// cross(a, k, b) from prefix(a), which a caller asking for many k with the same a keeps:
  /// the same arithmetic without summing a's steps again.
  Eigen::Matrix4d cross(const ChainSteps& steps, const Sums& prefix_a, size_t a, size_t k, size_t b) const;

 private:
  /// Adds the moments of step j (j >= 1; nothing for 0) to *s.
  static void addStep(const ChainSteps& steps, size_t j, Sums* s);

  /// 4, not 8: a whole-run trial's scoring steps half as far from a checkpoint (3-9 % of its
  /// verify time at 20k-100k keyframes) for 34 more bytes per keyframe.
  static constexpr size_t kStride = 4;
  size_t n_ = 0;
  std::vector<Sums> checkpoints_;  ///< prefix(kStride * i)
};

/// Steps kept in vectors, with their moments: a chain built step by step (tests, one step).
class StoredChainMoments : public ChainSteps {
 public:
  /// Appends keyframe j with its position, rotation and the covariance of the step that ends
  /// at it (ignored for the first keyframe).
  void append(const Eigen::Vector3d& p, const Eigen::Matrix3d& R, const Eigen::Matrix4d& step_cov);
  size_t size() const { return p_.size(); }
  Eigen::Matrix4d cross(size_t a, size_t k, size_t b) const { return moments_.cross(*this, a, k, b); }
  Eigen::Matrix4d relative(size_t a, size_t b, const Eigen::Matrix3d& Ra) const {
    return moments_.relative(*this, a, b, Ra);
  }
  Eigen::Vector3d position(size_t j) const override { return p_[j]; }
  Eigen::Matrix3d rotation(size_t j) const override { return R_[j]; }
  Eigen::Matrix4d stepCovariance(size_t j) const override { return cov_[j]; }

 private:
  std::vector<Eigen::Vector3d> p_;
  std::vector<Eigen::Matrix3d> R_;
  std::vector<Eigen::Matrix4d> cov_;
  ChainMoments moments_;
};

}  // namespace core
}  // namespace rover_loop_fusion
