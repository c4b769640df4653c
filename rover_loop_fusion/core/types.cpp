#include "rover_loop_fusion/core/types.h"

#include <cmath>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

const char* toString(Reason reason) {
  switch (reason) {
    case Reason::kAccepted: return "accepted";
    case Reason::kScoreAboveThreshold: return "score_above_threshold";
    case Reason::kNotConverged: return "not_converged";
    case Reason::kNoTrajectoryPrior: return "no_trajectory_prior";
    case Reason::kInvalidInput: return "invalid_input";
    case Reason::kTimeBudgetExceeded: return "time_budget_exceeded";
    case Reason::kInnovationAboveBound: return "innovation_above_bound";
  }
  return "invalid_input";
}

const char* toString(Mode mode) { return mode == Mode::kFourDof ? "4dof" : "6dof"; }

const char* toString(Alignment alignment) {
  return alignment == Alignment::kSE3 ? "se3" : "sim3";
}

bool parseMode(const std::string& s, Mode* mode) {
  if (s == "4dof") *mode = Mode::kFourDof;
  else if (s == "6dof") *mode = Mode::kSixDof;
  else return false;
  return true;
}

bool parseAlignment(const std::string& s, Alignment* alignment) {
  if (s == "se3") *alignment = Alignment::kSE3;
  else if (s == "sim3") *alignment = Alignment::kSim3;
  else return false;
  return true;
}

LoopCandidate candidateFromLoopInfo(int64_t query_index, int64_t match_index,
                                    const double loop_info[8], int inliers) {
  LoopCandidate c;
  c.query_index = query_index;
  c.match_index = match_index;
  c.relative_t = Eigen::Vector3d(loop_info[0], loop_info[1], loop_info[2]);
  c.relative_q = Eigen::Quaterniond(loop_info[3], loop_info[4], loop_info[5], loop_info[6]);
  c.relative_yaw = loop_info[7] * M_PI / 180.0;
  c.inliers = inliers;
  return c;
}

Verdict Verdict::Accept(const LoopCandidate& c, std::string detail, Reason reason) {
  Verdict v;
  v.query_index = c.query_index;
  v.match_index = c.match_index;
  v.accepted = true;
  v.reason = reason;
  v.detail = std::move(detail);
  return v;
}

Verdict Verdict::Reject(Reason reason, const LoopCandidate& c, std::string detail) {
  Verdict v;
  v.query_index = c.query_index;
  v.match_index = c.match_index;
  v.accepted = false;
  v.reason = reason == Reason::kAccepted ? Reason::kInvalidInput : reason;  // never "rejected: accepted"
  v.detail = std::move(detail);
  return v;
}

std::string VerifierConfig::validate() const {
  std::ostringstream e;
  auto positive = [&](const char* name, double v) {
    if (!(std::isfinite(v) && v > 0)) e << name << " must be a positive number (got " << v << "); ";
  };
  positive("threshold", threshold);
  positive("loop_huber", loop_huber);
  positive("max_relative_translation", max_relative_translation);
  positive("max_relative_yaw", max_relative_yaw);
  positive("quaternion_tolerance", quaternion_tolerance);
  positive("function_tolerance", function_tolerance);
  if (!(std::isfinite(threshold_per_metre) && threshold_per_metre >= 0))
    e << "threshold_per_metre must be >= 0 (got " << threshold_per_metre << "); ";
  if (!std::isfinite(max_threshold)) e << "max_threshold must be finite; ";
  if (!std::isfinite(max_innovation)) e << "max_innovation must be finite; ";
  if (!(std::isfinite(max_innovation_per_metre) && max_innovation_per_metre >= 0))
    e << "max_innovation_per_metre must be >= 0 (got " << max_innovation_per_metre << "); ";
  if (max_iterations < 1) e << "max_iterations must be >= 1 (got " << max_iterations << "); ";
  if (!std::isfinite(time_budget_ms)) e << "time_budget_ms must be finite; ";
  if (odometry_neighbours < 1)
    e << "odometry_neighbours must be >= 1 (got " << odometry_neighbours << "); ";
  if (window_margin < 0) e << "window_margin must be >= 0 (got " << window_margin << "); ";
  std::string s = e.str();
  if (s.size() >= 2) s.resize(s.size() - 2);
  return s;
}

}  // namespace core
}  // namespace rover_loop_fusion
