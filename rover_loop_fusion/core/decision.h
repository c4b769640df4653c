// The ROVER decision as functions on plain values (no graph access): the innovation gate, the
// score and the thresholds. The verifier gathers the values from its pose graph and the trial
// solve and asks these; an uncertainty-aware test (covariances instead of metres) lives here.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <Eigen/Core>

#include <string>

namespace rover_loop_fusion {
namespace core {

/// Outcome of one test of the decision: passed, or the verdict's reason and why.
struct Check {
  bool passed = true;
  Reason reason = Reason::kAccepted;
  std::string detail;
};

/// The score threshold for a candidate whose match and query are `path_length` apart through
/// the graph [m]: threshold + threshold_per_metre * path_length, capped at max_threshold (> 0).
/// A non-finite path length leaves the fixed threshold.
double scoreThreshold(const VerifierConfig& config, double path_length);

/// The innovation gate, before any solve: passes iff
///   innovation <= max_innovation + max_innovation_per_metre * path_length   [m]
/// or the gate is off (max_innovation <= 0). Fails (kInnovationAboveBound) otherwise, and fails
/// closed (kInvalidInput) when an input or the bound is not finite.
Check innovationGate(const VerifierConfig& config, double innovation, double path_length);

/// The ROVER score s: RMSE of the positions `before` (X) and `after` (X*) of the scored
/// keyframes (3 x N each) after Umeyama alignment (SE(3), or Sim(3) for monocular VO); NaN when
/// it cannot be computed.
double deformationScore(const Eigen::Matrix3Xd& before, const Eigen::Matrix3Xd& after,
                        Alignment alignment);

/// The last test: the trial solve converged to a finite solution within its limits and
/// score <= threshold. `window_size` (scored keyframes) and `time_budget_ms` only go into
/// the detail.
Check scoreTest(const SolveSummary& trial, double score, double threshold, int window_size,
                double time_budget_ms);

// ---- decision: chi2 (in units of drift) ---------------------------------------------------

/// The chi-square quantile: x with P(chi2_dof <= x) = p, for even dof (2, 4, 6), p in (0, 1).
double chiSquareQuantile(double p, int dof);

/// A probability as a verdict's detail prints it: every digit that is set (0.999999, not the
/// 1.000 of the fixed three decimals around it).
std::string probabilityText(double p);

/// d2 = nu^T S^-1 nu; +inf if S is not positive definite.
double mahalanobis(const Eigen::Vector4d& nu, const Eigen::Matrix4d& S);

/// How much better "this is the place" explains the innovation than "this is a look-alike
/// `horizontal` metres away horizontally (any direction) or `vertical` metres away vertically":
///   min over such offsets o of d2(nu - o) - d2(nu)   (o moves the position only).
/// +inf when both distances are 0 (no look-alikes) or S is not positive definite.
double lookalikeMargin(const Eigen::Vector4d& nu, const Eigen::Matrix4d& S, double horizontal,
                       double vertical);

/// The numbers of the chi2 decision, for the verdict.
struct Chi2Numbers {
  double d2 = 0.0;        ///< Mahalanobis distance of the innovation
  double gate = 0.0;      ///< chi-square quantile of gate_probability (4 dof)
  double sigma = 0.0;     ///< largest standard deviation of the relative position [m]
  double margin = 0.0;    ///< lookalikeMargin
};

/// The chi2 decision on an innovation `nu` (candidate minus estimate; translation in the
/// match's frame, yaw) with the covariance `S` of the relative pose through the graph plus the
/// loop's own: passes iff d2 <= gate and the look-alike margin >= lookalike_margin. Fails with
/// kInconsistentWithDrift or kLookalikeCloser. Fills `numbers`.
Check chi2Test(const VerifierConfig& config, const Eigen::Vector4d& nu, const Eigen::Matrix4d& S,
               Chi2Numbers* numbers);

}  // namespace core
}  // namespace rover_loop_fusion
