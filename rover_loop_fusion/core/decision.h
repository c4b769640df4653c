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

}  // namespace core
}  // namespace rover_loop_fusion
