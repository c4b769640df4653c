#include "rover_loop_fusion/core/decision_rule.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

/// The paper's rule: innovation gate, trial solve, deformation score against a threshold [m].
class MetricRule : public DecisionRule {
 public:
  MetricRule(const VerifierConfig& config, KeyframeGraph& graph) : config_(config), graph_(graph) {}

  RuleOutcome decide(const LoopCandidate& c, size_t qpos, size_t mpos, Clock::time_point t0, Verdict* measured,
                     Decided* decided) override {
    RuleOutcome out;
    out.check = metricDecision(config_, graph_, c, qpos, mpos, -1, t0, measured, &decided->solution);
    return out;
  }

  bool recheck(const LoopCandidate& c, size_t qpos, size_t mpos, Decided* decided) override {
    Verdict measured;
    return metricDecision(config_, graph_, c, qpos, mpos, -1, Clock::now(), &measured, &decided->solution).passed;
  }

  Status adoptDecided(const Decided& decided, size_t, bool) override {
    graph_.adopt(decided.solution);
    return Status::Ok();
  }

  Status updateEstimate(size_t first, size_t newest, double time_budget_ms) override {
    if (graph_.sequenceAt(first) == 0 && graph_.sequenceAt(newest) == 0) return Status::Ok();  // both fixed
    const TrialSolution s =
        graph_.solveWindow(first, newest, nullptr, false, config_.max_iterations, time_budget_ms);
    if (!s.summary.finite) return Status::Error(s.summary.message);  // X keeps its old values
    graph_.adopt(s);  // a solve stopped by the budget still moved X towards the loops
    if (s.summary.timed_out) return Status::Warning(s.summary.message);
    return Status::Ok();
  }

 private:
  const VerifierConfig& config_;
  KeyframeGraph& graph_;
};

/// In units of drift: the covariance of the relative pose through the condensed graph, the
/// chi-square gate and the look-alike test; X updated by the condensed least-squares solve.
class Chi2Rule : public DecisionRule {
 public:
  Chi2Rule(const VerifierConfig& config, KeyframeGraph& graph) : config_(config), graph_(graph) {}

  RuleOutcome decide(const LoopCandidate& c, size_t qpos, size_t mpos, Clock::time_point, Verdict* measured,
                     Decided* decided) override {
    RuleOutcome out;
    measured->innovation = graph_.innovation(c, qpos, mpos);
    // (No path length: its Dijkstra over every loop end would be the one cost that grows with
    // the run; the chi2 decision does not use it.)
    Eigen::Matrix4d C;
    int anchors = 0;
    if (!graph_.relativeCovariance(mpos, qpos, drift_scale_, &C, &anchors)) {
      out.check.passed = false;
      out.check.reason = Reason::kInvalidInput;
      out.check.detail = "no covariance of the relative pose (the condensed graph is singular)";
      return out;
    }
    const Eigen::Vector4d nu = graph_.innovationVector(c, qpos, mpos);
    Chi2Numbers n;
    out.check = chi2Test(config_, nu, C + graph_.loopCovariance(), &n);
    measured->score = n.d2;
    measured->threshold = n.gate;
    measured->window_size = anchors;
    measured->converged = true;
    if (!out.check.passed) return out;
    if (config_.hold_sigma > 0 && n.sigma > config_.hold_sigma) {
      std::ostringstream s;
      s.precision(3);
      s << std::fixed << out.check.detail << "; held: the prior alone is too weak (std " << n.sigma
        << " m > hold_sigma " << config_.hold_sigma << " m) until " << config_.confirm_count
        << " candidates of this revisit agree";
      out.check.detail = s.str();
      out.hold = true;
      return out;
    }
    decided->innovation = nu;
    decided->chain_covariance = C / drift_scale_;
    return out;
  }

  bool recheck(const LoopCandidate& c, size_t qpos, size_t mpos, Decided*) override {
    Eigen::Matrix4d C;
    Chi2Numbers n;
    return graph_.relativeCovariance(mpos, qpos, drift_scale_, &C) &&
           chi2Test(config_, graph_.innovationVector(c, qpos, mpos), C + graph_.loopCovariance(), &n).passed;
  }

  void learn(const Decided& decided) override {
    // What each loop accepted by its verify() said about the drift.
    calibration_.push_back({decided.innovation, decided.chain_covariance});
    if (config_.calibrate_drift) recalibrate();
  }

  Status adoptDecided(const Decided&, size_t qpos, bool update_estimate) override {
    if (!update_estimate) return Status::Ok();
    return graph_.updateEstimate(qpos, drift_scale_);
  }

  Status updateEstimate(size_t, size_t newest, double) override { return graph_.updateEstimate(newest, drift_scale_); }

  double driftScale() const override { return drift_scale_; }

 private:
  struct CalibrationSample {
    Eigen::Vector4d innovation;
    Eigen::Matrix4d chain_covariance;
  };

  void recalibrate() {
    // Robust maximum likelihood of one variance scale s of the drift model: each accepted loop's
    // innovation nu ~ N(0, s C + L) (C: its chain covariance at scale 1, L: the loop's), Huber
    // on sqrt(d2) (an accepted look-alike cannot drag s far), over a log grid of s.
    const size_t kMinLoops = 5, kWindow = 200;
    if (calibration_.size() < kMinLoops) return;
    const size_t first = calibration_.size() > kWindow ? calibration_.size() - kWindow : 0;
    const Eigen::Matrix4d L = graph_.loopCovariance();
    double best = drift_scale_, best_nll = std::numeric_limits<double>::infinity();
    for (int k = 0; k <= 80; ++k) {
      const double s = std::exp(std::log(0.01) + k * (std::log(100.0) - std::log(0.01)) / 80.0);
      double nll = 0.0;
      for (size_t i = first; i < calibration_.size(); ++i) {
        const Eigen::Matrix4d S = s * calibration_[i].chain_covariance + L;
        const Eigen::LLT<Eigen::Matrix4d> llt(S);
        if (llt.info() != Eigen::Success) continue;
        const double d2 = calibration_[i].innovation.dot(llt.solve(calibration_[i].innovation));
        const double r = std::sqrt(std::max(0.0, d2));
        const double rho = r < 3.0 ? d2 : 6.0 * r - 9.0;
        const Eigen::Matrix4d Lc = llt.matrixL();
        nll += 0.5 * rho + Lc.diagonal().array().log().sum();
      }
      if (nll < best_nll) {
        best_nll = nll;
        best = s;
      }
    }
    drift_scale_ = best;
  }

  const VerifierConfig& config_;
  KeyframeGraph& graph_;
  double drift_scale_ = 1.0;
  std::vector<CalibrationSample> calibration_;
};

}  // namespace

Check metricDecision(const VerifierConfig& config, KeyframeGraph& graph, const LoopCandidate& c, size_t qpos,
                     size_t mpos, int condense_min_window, std::chrono::steady_clock::time_point t0,
                     Verdict* measured, TrialSolution* trial) {
  measured->innovation = graph.innovation(c, qpos, mpos);
  measured->path_length = graph.pathLength(mpos, qpos);
  measured->threshold = scoreThreshold(config, measured->path_length);
  const Check gate = innovationGate(config, measured->innovation, measured->path_length);
  if (!gate.passed) return gate;

  // The budget counts from the call: what the checks above took is spent.
  const double budget_left =
      config.time_budget_ms > 0 ? std::max(1e-3, config.time_budget_ms - msSince(t0)) : 0.0;
  *trial = graph.solveWindow(mpos, qpos, &c, config.robust_candidate, config.max_iterations, budget_left,
                             condense_min_window);
  const SolveSummary& o = trial->summary;
  measured->iterations = o.iterations;
  measured->solve_ms = o.solve_ms;
  measured->converged = o.converged && o.finite;
  // Scored: the keyframes that may move (sequence 0 is a fixed prior map).
  Eigen::Matrix3Xd before, after;
  measured->window_size = graph.scoredPositions(*trial, &before, &after);
  if (o.finite) measured->score = deformationScore(before, after, config.alignment);

  Check score = scoreTest(o, measured->score, measured->threshold, measured->window_size, config.time_budget_ms);
  if (trial->condensed) score.detail += " (" + o.message + ")";
  return score;
}

std::unique_ptr<DecisionRule> makeDecisionRule(const VerifierConfig& config, KeyframeGraph& graph) {
  if (config.decision == Decision::kChi2) return std::unique_ptr<DecisionRule>(new Chi2Rule(config, graph));
  return std::unique_ptr<DecisionRule>(new MetricRule(config, graph));
}

}  // namespace core
}  // namespace rover_loop_fusion
