#include "rover_loop_fusion/core/types.h"

#include <cmath>

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
    case Reason::kInconsistentWithDrift: return "inconsistent_with_drift";
    case Reason::kLookalikeCloser: return "lookalike_closer";
    case Reason::kDeferred: return "deferred";
    case Reason::kUnconfirmed: return "unconfirmed";
    case Reason::kRevoked: return "revoked";
  }
  return "invalid_input";
}

const char* toString(Mode mode) { return mode == Mode::kFourDof ? "4dof" : "6dof"; }

const char* toString(Alignment alignment) {
  return alignment == Alignment::kSE3 ? "se3" : "sim3";
}

const char* toString(Decision decision) {
  switch (decision) {
    case Decision::kChi2: return "chi2";
    case Decision::kRevisit: return "revisit";
    case Decision::kMetric: break;
  }
  return "metric";
}

bool parseDecision(const std::string& s, Decision* decision) {
  if (s == "chi2") *decision = Decision::kChi2;
  else if (s == "revisit") *decision = Decision::kRevisit;
  else if (s == "metric") *decision = Decision::kMetric;
  else return false;
  return true;
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

Verdict Verdict::Defer(const LoopCandidate& c, std::string detail) {
  Verdict v;
  v.query_index = c.query_index;
  v.match_index = c.match_index;
  v.accepted = false;
  v.deferred = true;
  v.reason = Reason::kDeferred;
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

void rejectRefusedCommit(Verdict* v, const Status& commit) {
  if (commit.ok) return;
  v->accepted = false;
  v->reason = Reason::kInvalidInput;
  v->detail += "; but the verifier refused to commit it: " + commit.message;
}

}  // namespace core
}  // namespace rover_loop_fusion
