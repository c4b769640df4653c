#include "rover_loop_fusion/core/verifier.h"

#include "rover_loop_fusion/core/decision.h"

#include <chrono>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// `decided` with the numbers measured on the way to it (`measured`) and the time taken.
Verdict withNumbers(Verdict decided, const Verdict& measured, Clock::time_point t0) {
  decided.score = measured.score;
  decided.threshold = measured.threshold;
  decided.converged = measured.converged;
  decided.iterations = measured.iterations;
  decided.window_size = measured.window_size;
  decided.innovation = measured.innovation;
  decided.path_length = measured.path_length;
  decided.solve_ms = measured.solve_ms;
  decided.elapsed_ms = msSince(t0);
  return decided;
}

}  // namespace

Verifier::Verifier(const VerifierConfig& config)
    : config_error_(config.validate()),
      config_(config_error_.empty() ? config : VerifierConfig()),
      graph_(config_) {}

Verifier::~Verifier() = default;

Status Verifier::addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                             const Eigen::Quaterniond& q) {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.addKeyframe(index, stamp, sequence, t, q);
}

Verdict Verifier::verify(const LoopCandidate& c) {
  const auto t0 = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  Verdict measured;  // the numbers gathered on the way to the decision
  measured.threshold = config_.threshold;
  auto reject = [&](Reason reason, std::string detail) {
    return withNumbers(Verdict::Reject(reason, c, std::move(detail)), measured, t0);
  };

  size_t qpos = 0, mpos = 0;
  const std::string bad = graph_.checkLoop(c, &qpos, &mpos);
  if (!bad.empty()) return reject(Reason::kInvalidInput, bad);
  const int qseq = graph_.sequenceAt(qpos), mseq = graph_.sequenceAt(mpos);
  if (!graph_.connected(qpos, mpos)) {
    std::ostringstream s;
    if (qseq == mseq)
      s << "keyframes " << c.match_index << " and " << c.query_index << " of sequence " << qseq
        << " lie on either side of a keyframe jump accepted as a relocation, which no loop ties yet: "
           "no trajectory prior; ";
    else
      s << "sequences " << mseq << " and " << qseq << " are not connected: no trajectory prior; ";
    s << (config_.accept_without_prior ? "accepted by policy (accept_without_prior)"
                                       : "rejected by policy (accept_without_prior=false)");
    if (config_.accept_without_prior)
      return withNumbers(Verdict::Accept(c, s.str(), Reason::kNoTrajectoryPrior), measured, t0);
    return reject(Reason::kNoTrajectoryPrior, s.str());
  }
  if (qseq == 0 && mseq == 0)
    return reject(Reason::kInvalidInput,
                  "both keyframes are in sequence 0 (a loaded map, held fixed): nothing to verify");

  measured.innovation = graph_.innovation(c, qpos, mpos);
  measured.path_length = graph_.pathLength(mpos, qpos);
  measured.threshold = scoreThreshold(config_, measured.path_length);
  const Check gate = innovationGate(config_, measured.innovation, measured.path_length);
  if (!gate.passed) return reject(gate.reason, gate.detail);

  TrialSolution trial = graph_.solveWindow(mpos, qpos, &c, config_.robust_candidate,
                                           config_.max_iterations, config_.time_budget_ms);
  const SolveSummary& o = trial.summary;
  measured.iterations = o.iterations;
  measured.solve_ms = o.solve_ms;
  measured.converged = o.converged && o.finite;
  // Scored: the keyframes that may move (sequence 0 is a fixed prior map).
  Eigen::Matrix3Xd before, after;
  measured.window_size = graph_.scoredPositions(trial, &before, &after);
  if (o.finite) measured.score = deformationScore(before, after, config_.alignment);

  const Check score = scoreTest(o, measured.score, measured.threshold, measured.window_size,
                                config_.time_budget_ms);
  if (!score.passed) return reject(score.reason, score.detail);
  pending_.valid = true;
  pending_.candidate = c;
  pending_.revision = graph_.revision();
  pending_.solution = std::move(trial);
  return withNumbers(Verdict::Accept(c, score.detail), measured, t0);
}

Status Verifier::commit(const LoopCandidate& c) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Pending& p = pending_;
  const bool reuse = p.valid && p.revision == graph_.revision() &&
                     p.candidate.query_index == c.query_index &&
                     p.candidate.match_index == c.match_index &&
                     p.candidate.relative_t == c.relative_t &&
                     p.candidate.relative_q.coeffs() == c.relative_q.coeffs() &&
                     p.candidate.relative_yaw == c.relative_yaw;
  const Status added = graph_.addLoop(c);
  if (!added) return Status::Error("commit refused: " + added.message);
  pending_.valid = false;
  if (reuse) {
    graph_.adopt(p.solution);
    return Status::Ok();
  }
  size_t qpos = 0, mpos = 0;
  graph_.find(c.query_index, &qpos);
  graph_.find(c.match_index, &mpos);
  if (graph_.sequenceAt(qpos) == 0 && graph_.sequenceAt(mpos) == 0) return Status::Ok();  // both fixed
  const TrialSolution s = graph_.solveWindow(mpos, qpos, nullptr, false, config_.max_iterations, 0.0);
  if (!s.summary.finite)  // the loop is in the graph (the host uses it); X keeps its old values
    return Status::Warning("loop committed but the update of the estimate failed (" + s.summary.message + ")");
  graph_.adopt(s);
  return Status::Ok();
}

size_t Verifier::keyframeCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.keyframeCount();
}

size_t Verifier::solveCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.solveCount();
}

size_t Verifier::loopCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.loopCount();
}

bool Verifier::hasKeyframe(int64_t index) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.hasKeyframe(index);
}

bool Verifier::estimate(int64_t index, Pose* pose) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.estimate(index, pose);
}

std::vector<TrajectoryPoint> Verifier::trajectory() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.trajectory();
}

BatchSolveResult Verifier::solveLikeLoopFusion(int max_iterations) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.solveLikeLoopFusion(max_iterations);
}

}  // namespace core
}  // namespace rover_loop_fusion
