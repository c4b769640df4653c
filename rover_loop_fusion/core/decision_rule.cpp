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
        graph_.solveWindow(first, newest, nullptr, false, config_.trial.max_iterations, time_budget_ms);
    if (!s.summary.finite) return Status::Error(s.summary.message);  // X keeps its old values
    graph_.adopt(s);  // a solve stopped by the budget still moved X towards the loops
    if (s.summary.timed_out) return Status::Warning(s.summary.message);
    return Status::Ok();
  }

 private:
  const VerifierConfig& config_;
  KeyframeGraph& graph_;
};

/// A variance scale of the drift model fitted to what accepted loops said about the drift:
/// robust maximum likelihood over a log grid. calibrate_drift applies it to the model
/// (scale()); the revisit judge reads it for its bound (observed(), revisit_observed_drift).
class DriftCalibration {
 public:
  DriftCalibration(const VerifierConfig& config, const KeyframeGraph& graph, double initial)
      : config_(config), graph_(graph), scale_(initial) {}
  double scale() const { return scale_; }

  void add(const Eigen::Vector4d& innovation, const Eigen::Matrix4d& chain_covariance) {
    samples_.push_back({innovation, chain_covariance});
    if (config_.drift.calibrate_drift) scale_ = fit(scale_);
  }

  /// The scale the accepted loops' innovations ask for relative to the one in use (1 with
  /// calibrate_drift off); fitted when asked, once per new sample; 1 before kMinLoops loops.
  double observed() {
    if (observed_samples_ != samples_.size()) {
      observed_ = fit(scale_) / scale_;
      observed_samples_ = samples_.size();
    }
    return observed_;
  }

 private:
  struct Sample {
    Eigen::Vector4d innovation;
    Eigen::Matrix4d chain_covariance;
  };

  double fit(double start) const {
    // Robust maximum likelihood of one variance scale s of the drift model: each accepted loop's
    // innovation nu ~ N(0, s C + L) (C: its chain covariance at scale 1, L: the loop's), Huber
    // on sqrt(d2) (an accepted look-alike cannot drag s far), over a log grid of s.
    const size_t kMinLoops = 5, kWindow = 200;
    if (samples_.size() < kMinLoops) return start;
    const size_t first = samples_.size() > kWindow ? samples_.size() - kWindow : 0;
    const Eigen::Matrix4d L = graph_.loopCovariance();
    double best = start, best_nll = std::numeric_limits<double>::infinity();
    for (int k = 0; k <= 80; ++k) {
      const double s = std::exp(std::log(0.01) + k * (std::log(100.0) - std::log(0.01)) / 80.0);
      double nll = 0.0;
      for (size_t i = first; i < samples_.size(); ++i) {
        const Eigen::Matrix4d S = s * samples_[i].chain_covariance + L;
        const Eigen::LLT<Eigen::Matrix4d> llt(S);
        if (llt.info() != Eigen::Success) continue;
        const double d2 = samples_[i].innovation.dot(llt.solve(samples_[i].innovation));
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
    return best;
  }

  const VerifierConfig& config_;
  const KeyframeGraph& graph_;
  double scale_;
  std::vector<Sample> samples_;
  double observed_ = 1.0;
  size_t observed_samples_ = 0;
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
    // (No path length: the chi2 decision does not use it, and its verifier keeps no places
    // for it.)
    Eigen::Matrix4d C;
    if (!graph_.relativeCovariance(mpos, qpos, calibration_.scale(), &C)) {
      out.check.passed = false;
      out.check.reason = Reason::kInvalidInput;
      out.check.detail = "no covariance of the relative pose (the condensed graph is singular)";
      return out;
    }
    const Eigen::Vector4d nu = graph_.innovationVector(c, qpos, mpos);
    Chi2Numbers n;
    out.check = chi2Test(config_, nu, C + graph_.loopCovariance(), &n);
    // No trial: the test is d2 against the gate (score and threshold are metres and stay NaN).
    measured->d2 = n.d2;
    measured->gate = n.gate;
    measured->threshold = std::numeric_limits<double>::quiet_NaN();
    measured->converged = true;
    if (!out.check.passed) return out;
    if (config_.chi2.hold_sigma > 0 && n.sigma > config_.chi2.hold_sigma) {
      std::ostringstream s;
      s.precision(3);
      s << std::fixed << out.check.detail << "; held: the prior alone is too weak (std " << n.sigma
        << " m > hold_sigma " << config_.chi2.hold_sigma << " m) until " << config_.hold.confirm_count
        << " candidates of this revisit agree";
      out.check.detail = s.str();
      out.hold = true;
      return out;
    }
    decided->innovation = nu;
    decided->chain_covariance = C / calibration_.scale();
    return out;
  }

  bool recheck(const LoopCandidate& c, size_t qpos, size_t mpos, Decided*) override {
    Eigen::Matrix4d C;
    Chi2Numbers n;
    return graph_.relativeCovariance(mpos, qpos, calibration_.scale(), &C) &&
           chi2Test(config_, graph_.innovationVector(c, qpos, mpos), C + graph_.loopCovariance(), &n).passed;
  }

  void learn(const Decided& decided) override {
    // What each loop accepted by its verify() said about the drift.
    calibration_.add(decided.innovation, decided.chain_covariance);
  }

  Status adoptDecided(const Decided&, size_t qpos, bool update_estimate) override {
    if (!update_estimate) return Status::Ok();
    return graph_.updateEstimate(qpos, calibration_.scale());
  }

  Status updateEstimate(size_t, size_t newest, double) override {
    return graph_.updateEstimate(newest, calibration_.scale());
  }

  double driftScale() const override { return calibration_.scale(); }

 private:
  const VerifierConfig& config_;
  KeyframeGraph& graph_;
  DriftCalibration calibration_{config_, graph_, 1.0};
};

/// The revisit as the unit of decision: the metric and the chi2 tests per candidate (the fast
/// path: both pass), a prompt rejection where no drift explains the innovation, and what is
/// left held as a member of a revisit hypothesis that judge() tests as a whole. X follows the
/// trial solves, as for metric.
class RevisitRule : public MetricRule {
 public:
  RevisitRule(const VerifierConfig& config, KeyframeGraph& graph) : MetricRule(config, graph), cfg_(config), g_(graph) {}

  RuleOutcome decide(const LoopCandidate& c, size_t qpos, size_t mpos, Clock::time_point t0, Verdict* measured,
                     Decided* decided) override {
    RuleOutcome out;
    // The fast path: the paper's test, as decision metric.
    out.check = metricDecision(cfg_, g_, c, qpos, mpos, -1, t0, measured, &decided->solution);
    // Held: only a candidate whose trial bent the trajectory too far for the metric threshold.
    // The innovation gate stays a hard filter (holding what it rejects let rows of near
    // look-alikes in on the pose graphs' tuning cases: docs/design-notes.md), and a trial that
    // gave no answer is no evidence either way: fail closed. Those need no prior (an extension
    // of accepted loops does not teach the calibration, the one use of it past this point).
    if (!out.check.passed && out.check.reason != Reason::kScoreAboveThreshold) return out;
    Eigen::Vector4d nu;
    Eigen::Matrix4d C;
    const bool prior = drift(c, qpos, mpos, &nu, &C);
    if (prior) {  // what an accepted loop teaches the calibration when it is committed (learn())
      decided->innovation = nu;
      decided->chain_covariance = C / calibration_.scale();
    }
    if (out.check.passed) return out;
    if (!prior) {
      out.check.detail += "; no covariance of the relative pose (the condensed graph is singular)";
      return out;
    }
    Chi2Numbers n;
    chi2Test(cfg_, nu, C + g_.loopCovariance(), &n);
    out.d2 = n.d2;
    const double reject = chiSquareQuantile(cfg_.revisit.revisit_reject_probability, 4);
    measured->d2 = n.d2;
    measured->gate = reject;
    std::ostringstream s;
    s.precision(3);
    s << std::fixed << out.check.detail << "; Mahalanobis d2 " << n.d2 << (n.d2 <= reject ? " <= " : " > ") << reject
      << " (chi2 " << probabilityText(cfg_.revisit.revisit_reject_probability) << ", drift scale " << calibration_.scale()
      << "; relative position std up to " << n.sigma << " m)";
    if (!(n.d2 <= reject)) {
      out.check.detail = s.str() + ": no drift explains it";
      return out;
    }
    out.check = Check();
    out.hold = true;
    out.kind = HoldKind::kRevisit;
    out.check.detail = s.str() + ": held as a member of a revisit hypothesis";
    return out;
  }

  bool recheck(const LoopCandidate& c, size_t qpos, size_t mpos, Decided* decided) override {
    Eigen::Matrix4d C;
    if (!drift(c, qpos, mpos, &decided->innovation, &C)) return false;
    decided->chain_covariance = C / calibration_.scale();
    return true;
  }

  void learn(const Decided& decided) override { calibration_.add(decided.innovation, decided.chain_covariance); }

  bool retestAlone(const LoopCandidate& c, size_t qpos, size_t mpos, std::string* why) override {
    Verdict measured;
    TrialSolution solution;
    const Check check = metricDecision(cfg_, g_, c, qpos, mpos, -1, Clock::now(), &measured, &solution);
    *why = check.detail;
    return check.passed;
  }

  double driftScale() const override { return calibration_.scale(); }

  double misfit(const HeldGroup& group) override {
    Members m = members(group);
    if (m.d2.empty()) return std::numeric_limits<double>::infinity();
    return median(&m.d2).first;
  }

  bool judge(const HeldGroup& group, std::string* why) override {
    // Each member against the prior as it is now; the hypothesis' fit is the median member's.
    Members m = members(group);
    const double sigma = m.sigma;
    std::ostringstream s;
    s.precision(3);
    s << std::fixed << "revisit hypothesis of " << group.size() << " (loops " << group.front().candidate.query_index
      << "->" << group.front().candidate.match_index << " .. " << group.back().candidate.query_index << "->"
      << group.back().candidate.match_index << "): ";
    if (m.d2.size() < static_cast<size_t>(cfg_.revisit.revisit_support)) {
      s << "fewer than revisit_support members have a prior now";
      *why = s.str();
      return false;
    }
    if (cfg_.revisit.revisit_max_sigma > 0 && sigma > cfg_.revisit.revisit_max_sigma) {
      s << "the prior is too weak to tell a revisit from a look-alike row (relative position std up to " << sigma
        << " m > revisit_max_sigma " << cfg_.revisit.revisit_max_sigma << " m)";
      *why = s.str();
      return false;
    }
    const double median_d2 = median(&m.d2).first;
    const double gate = chiSquareQuantile(cfg_.revisit.revisit_gate_probability, 4);
    if (!(median_d2 <= gate)) {
      s << "median Mahalanobis d2 " << median_d2 << " > " << gate << " (chi2 " << probabilityText(cfg_.revisit.revisit_gate_probability)
        << "): more than drift explains";
      *why = s.str();
      return false;
    }
    // The trial with all its loops: how far the trajectory has to bend for this revisit.
    std::vector<LoopCandidate> loops;
    for (const auto& d : m.d2) loops.push_back(d.second->candidate);
    const TrialSolution trial = g_.solveWindow(loops, cfg_.trial.robust_candidate, cfg_.trial.max_iterations, 0.0);
    Eigen::Matrix3Xd before, after;
    const int n = g_.scoredPositions(trial, &before, &after);
    const double score = trial.summary.finite ? deformationScore(before, after, cfg_.alignment)
                                              : std::numeric_limits<double>::quiet_NaN();
    double bound = std::max(cfg_.metric.threshold, cfg_.revisit.revisit_score_sigmas * sigma);
    s << "median d2 " << median_d2 << " <= " << gate << "; trial with its " << loops.size() << " loops: score "
      << score << " m over " << n << " keyframes, bound ";
    std::ostringstream b;
    b.precision(3);
    b << std::fixed << "(max of threshold and " << cfg_.revisit.revisit_score_sigmas << " x std " << sigma << " m";
    if (!(score <= bound) && cfg_.revisit.revisit_observed_drift) {
      // The drift model's std may be the VIO's or not; the accepted loops tell (a recorded run's third
      // lap: 0.226 m against 0.65 x 0.138 m, docs/vins-fusion.md). Only where the prior tells
      // the place from a look-alike a known spacing away: a row of look-alikes fits as well as
      // a third lap by score and d2 (warehouse_s0.1: 0.24 m, d2 7-11; docs/design-notes.md).
      const double observed = calibration_.observed();
      const double lookalike = median(&m.margin).first;
      if (observed > 1.0 && std::isfinite(lookalike) && lookalike >= cfg_.chi2.lookalike_margin) {
        bound = std::max(cfg_.metric.threshold, cfg_.revisit.revisit_score_sigmas * sigma * std::sqrt(observed));
        b << " x sqrt(" << observed << "), the drift scale the accepted loops show)";
      } else {
        b << "; the accepted loops show drift scale " << observed;
        if (observed > 1.0 && !std::isfinite(lookalike))
          b << ", not applied: no look-alike spacing is set (lookalike_distance, lookalike_distance_vertical 0), so "
               "nothing tells the place from a row of look-alikes";
        else if (observed > 1.0)
          b << ", not applied: a look-alike explains the median member as well (margin " << lookalike << " < "
            << cfg_.chi2.lookalike_margin << ")";
        b << ")";
      }
    } else {
      b << ")";
    }
    s << bound << " m " << b.str();
    *why = s.str();
    return trial.summary.converged && trial.summary.finite && score <= bound;
  }

 private:
  /// The members with a prior now: their d2 (and the member), look-alike margins, the largest
  /// position std.
  struct Members {
    std::vector<std::pair<double, const HeldCandidate*>> d2;
    std::vector<std::pair<double, const HeldCandidate*>> margin;
    double sigma = 0.0;
  };
  Members members(const HeldGroup& group) const {
    Members m;
    for (const HeldCandidate& h : group) {
      Eigen::Vector4d nu;
      Eigen::Matrix4d C;
      if (!g_.connected(h.query_pos, h.match_pos) || !drift(h.candidate, h.query_pos, h.match_pos, &nu, &C)) continue;
      Chi2Numbers n;
      chi2Test(cfg_, nu, C + g_.loopCovariance(), &n);
      m.d2.push_back({n.d2, &h});
      m.margin.push_back({n.margin, &h});
      m.sigma = std::max(m.sigma, n.sigma);
    }
    return m;
  }
  /// The median (upper, for an even count) by value; v not empty, reordered.
  static std::pair<double, const HeldCandidate*> median(std::vector<std::pair<double, const HeldCandidate*>>* v) {
    std::nth_element(v->begin(), v->begin() + v->size() / 2, v->end());
    return (*v)[v->size() / 2];
  }

  bool drift(const LoopCandidate& c, size_t qpos, size_t mpos, Eigen::Vector4d* nu, Eigen::Matrix4d* C) const {
    if (!g_.relativeCovariance(mpos, qpos, calibration_.scale(), C)) return false;
    *nu = g_.innovationVector(c, qpos, mpos);
    return true;
  }

  const VerifierConfig& cfg_;
  KeyframeGraph& g_;
  DriftCalibration calibration_{cfg_, g_, 1.0};
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

  runTrial(config, graph, c, qpos, mpos, condense_min_window, t0, measured, trial);
  const SolveSummary& o = trial->summary;
  Check score = scoreTest(o, measured->score, measured->threshold, measured->window_size, config.trial.time_budget_ms);
  if (trial->condensed) score.detail += " (" + o.message + ")";
  return score;
}

void runTrial(const VerifierConfig& config, KeyframeGraph& graph, const LoopCandidate& c, size_t qpos, size_t mpos,
              int condense_min_window, std::chrono::steady_clock::time_point t0, Verdict* measured,
              TrialSolution* trial) {
  // The budget counts from the call: what the checks before it took is spent.
  const double budget_left =
      config.trial.time_budget_ms > 0 ? std::max(1e-3, config.trial.time_budget_ms - msSince(t0)) : 0.0;
  *trial = graph.solveWindow(mpos, qpos, &c, config.trial.robust_candidate, config.trial.max_iterations, budget_left,
                             condense_min_window);
  const SolveSummary& o = trial->summary;
  measured->iterations = o.iterations;
  measured->solve_ms = o.solve_ms;
  measured->converged = o.converged && o.finite;
  // Scored: the keyframes that may move (sequence 0 is a fixed prior map).
  Eigen::Matrix3Xd before, after;
  measured->window_size = graph.scoredPositions(*trial, &before, &after);
  if (o.finite) measured->score = deformationScore(before, after, config.alignment);
}

std::unique_ptr<DecisionRule> makeDecisionRule(const VerifierConfig& config, KeyframeGraph& graph) {
  if (config.decision == Decision::kChi2) return std::unique_ptr<DecisionRule>(new Chi2Rule(config, graph));
  if (config.decision == Decision::kRevisit) return std::unique_ptr<DecisionRule>(new RevisitRule(config, graph));
  return std::unique_ptr<DecisionRule>(new MetricRule(config, graph));
}

}  // namespace core
}  // namespace rover_loop_fusion
