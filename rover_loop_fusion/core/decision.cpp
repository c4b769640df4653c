#include "rover_loop_fusion/core/decision.h"

#include "rover_loop_fusion/core/alignment.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

Check fail(Reason reason, std::string detail) {
  Check c;
  c.passed = false;
  c.reason = reason;
  c.detail = std::move(detail);
  return c;
}

}  // namespace

double scoreThreshold(const VerifierConfig& config, double path_length) {
  double threshold = config.threshold;
  if (config.threshold_per_metre > 0 && std::isfinite(path_length)) {
    threshold += config.threshold_per_metre * path_length;
    if (config.max_threshold > 0) threshold = std::min(threshold, config.max_threshold);
  }
  return threshold;
}

Check innovationGate(const VerifierConfig& config, double innovation, double path_length) {
  if (!(config.max_innovation > 0)) return Check();
  const double bound = config.max_innovation + config.max_innovation_per_metre * path_length;
  std::ostringstream s;
  s.precision(3);
  if (!std::isfinite(innovation) || !std::isfinite(path_length) || !std::isfinite(bound)) {
    s << "innovation gate cannot decide: innovation " << innovation << " m, path length " << path_length
      << " m (not finite): rejected";
    return fail(Reason::kInvalidInput, s.str());
  }
  if (innovation <= bound) return Check();
  s << std::fixed << "innovation " << innovation << " m > " << bound << " m (" << config.max_innovation
    << " m + " << config.max_innovation_per_metre << " x " << path_length
    << " m of path): more than drift can explain";
  return fail(Reason::kInnovationAboveBound, s.str());
}

double deformationScore(const Eigen::Matrix3Xd& before, const Eigen::Matrix3Xd& after,
                        Alignment alignment) {
  const AlignmentResult al = alignPositions(before, after, alignment == Alignment::kSim3);
  return al.ok ? al.rmse : std::numeric_limits<double>::quiet_NaN();
}

Check scoreTest(const SolveSummary& trial, double score, double threshold, int window_size,
                double time_budget_ms) {
  if (trial.timed_out)
    return fail(Reason::kTimeBudgetExceeded, "trial optimisation ran past time_budget_ms=" +
                                                 std::to_string(time_budget_ms) + ": " + trial.message);
  std::ostringstream s;
  s.precision(3);
  if (!trial.converged || !trial.finite || !std::isfinite(score)) {
    s << "trial optimisation did not converge after " << trial.iterations << " iterations ("
      << (trial.finite ? trial.message : "non-finite solution") << ")";
    return fail(Reason::kNotConverged, s.str());
  }
  const bool above = score > threshold;
  s << "score " << std::fixed << score << (above ? " m > threshold " : " m <= threshold ") << threshold
    << " m over " << window_size << " keyframes";
  if (above) return fail(Reason::kScoreAboveThreshold, s.str());
  Check passed;
  passed.detail = s.str();
  return passed;
}

}  // namespace core
}  // namespace rover_loop_fusion
