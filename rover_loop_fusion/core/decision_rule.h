// How a candidate with a trajectory prior is decided, one strategy object per `decision` mode
// (the verifier orchestrates; the tests themselves are the pure functions of core/decision.h):
//   MetricRule  the paper's deformation score in metres behind the innovation gate (trial solve);
//   Chi2Rule    the innovation in units of drift: the covariance through the condensed graph,
//               the chi-square gate and the look-alike test (no trial solve);
//   RevisitRule both per candidate (the fast path); what neither accepts nor rules out is held
//               as a member of a revisit hypothesis, which judge() tests as a whole.
// A rule decides (decide), re-decides a held candidate against the graph as it is now
// (recheck), and keeps the estimate X in step with the graph after loops were added or
// removed (adoptDecided, updateEstimate). It never adds or removes loops itself.
#pragma once

#include "rover_loop_fusion/core/decision.h"
#include "rover_loop_fusion/core/held_candidates.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/types.h"

#include <Eigen/Core>

#include <chrono>
#include <limits>
#include <memory>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// What a rule worked out for a candidate it accepted, kept until commit() (or a release) adds
/// the very loop, so that nothing is solved twice.
struct Decided {
  TrialSolution solution;                                     ///< metric: the trial's X*
  Eigen::Vector4d innovation = Eigen::Vector4d::Zero();       ///< chi2: for the calibration
  Eigen::Matrix4d chain_covariance = Eigen::Matrix4d::Zero(); ///< chi2, at variance scale 1
  /// Its innovation teaches the drift calibration when the loop is committed (learn()): set by
  /// Verifier::verify, false for a loop the prior did not confirm (a revisit extension).
  bool calibrates = true;
};

/// The outcome of decide(): the test (passed, or the reason and why), and whether a candidate
/// that passed should be held rather than accepted, and as what (chi2's hold_sigma: the prior
/// alone too weak; revisit: a member of a revisit hypothesis).
struct RuleOutcome {
  Check check;
  bool hold = false;
  HoldKind kind = HoldKind::kWeakPrior;
  double d2 = 0.0;  ///< the innovation's Mahalanobis distance, where the rule computed it
};

class DecisionRule {
 public:
  using Clock = std::chrono::steady_clock;
  virtual ~DecisionRule() = default;

  /// Decides a candidate whose query and match the graph ties together (a trajectory prior),
  /// against the graph and X as they are. Fills the measured numbers of the verdict (`measured`:
  /// innovation, score, threshold, ...) and, when it passes, *decided. `t0`: when the
  /// verification started (the time budget counts from there).
  virtual RuleOutcome decide(const LoopCandidate& c, size_t query_pos, size_t match_pos, Clock::time_point t0,
                             Verdict* measured, Decided* decided) = 0;
  /// Decides a held candidate again, against the graph as it is now; when it passes, *decided
  /// holds what adoptDecided() needs once the loop is in the graph.
  virtual bool recheck(const LoopCandidate& c, size_t query_pos, size_t match_pos, Decided* decided) = 0;
  /// decision revisit: a member of a revisit hypothesis that is being dropped, tested alone again
  /// with the per-candidate (metric) test against the graph as it is now (other loops of its
  /// revisit may have closed the drift since it was held). Other rules: false.
  virtual bool retestAlone(const LoopCandidate& c, size_t query_pos, size_t match_pos, std::string* why) {
    (void)c, (void)query_pos, (void)match_pos, (void)why;
    return false;
  }
  /// A loop that decide() or recheck() passed has been added to the graph: X takes what was
  /// worked out for it (metric: the trial's X*; chi2: the condensed solve, unless
  /// `update_estimate` is false and the caller updates X once for a group: updateEstimate).
  /// An error says why X could not be updated (X unchanged).
  virtual Status adoptDecided(const Decided& decided, size_t query_pos, bool update_estimate) = 0;
  /// A loop accepted by its own decide() has been committed: what it says about the drift
  /// (chi2: a calibration sample for calibrate_drift).
  virtual void learn(const Decided&) {}
  /// X after loops between [first, newest] were added (or removed) without a decided solution.
  /// `time_budget_ms` > 0 bounds a metric solve (a loop without a prior, in the host's
  /// loop-closure path). An error (X unchanged) or a warning (stopped by the budget, X moved
  /// part of the way) carries the solver's message.
  virtual Status updateEstimate(size_t first, size_t newest, double time_budget_ms) = 0;
  /// The variance scale of the drift model (chi2 with calibrate_drift fits it; 1 otherwise).
  virtual double driftScale() const { return 1.0; }
  /// decision revisit: the median Mahalanobis distance of a hypothesis' members (held members
  /// of one revisit) against the graph and X as they are now (+inf: no member has a prior).
  virtual double misfit(const HeldGroup& group) {
    (void)group;
    return std::numeric_limits<double>::infinity();
  }
  /// decision revisit: whether a hypothesis passes its joint test against the graph and X as
  /// they are now (the median member within the gate, the trial's deformation within its
  /// bound); why (not) in *why. Other rules hold no hypotheses: false.
  virtual bool judge(const HeldGroup& group, std::string* why) {
    *why = "no revisit hypotheses under this decision rule";
    (void)group;
    return false;
  }
};

/// The rule of config.decision, deciding on `graph` (which it must outlive).
std::unique_ptr<DecisionRule> makeDecisionRule(const VerifierConfig& config, KeyframeGraph& graph);

/// decision metric from the innovation gate on, as a function (the rule, and the diagnostics of
/// Verifier::compareTrials): fills the numbers and the trial (trials over more than
/// `condense_min_window` keyframes condensed; -1: the config's).
Check metricDecision(const VerifierConfig& config, KeyframeGraph& graph, const LoopCandidate& c, size_t query_pos,
                     size_t match_pos, int condense_min_window, std::chrono::steady_clock::time_point t0,
                     Verdict* measured, TrialSolution* trial);

/// The trial of metricDecision alone (no gate, no score test): solves it within what is left of
/// time_budget_ms since t0 and fills the trial's numbers (iterations, solve time, convergence,
/// window, score).
void runTrial(const VerifierConfig& config, KeyframeGraph& graph, const LoopCandidate& c, size_t query_pos,
              size_t match_pos, int condense_min_window, std::chrono::steady_clock::time_point t0, Verdict* measured,
              TrialSolution* trial);

}  // namespace core
}  // namespace rover_loop_fusion
