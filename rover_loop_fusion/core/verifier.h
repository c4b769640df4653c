// The ROVER loop verifier: ROS-free, one instance per loop_fusion process.
//
// It keeps its own pose graph (core/pose_graph.h: keyframe VIO poses, odometry edges to the
// previous `odometry_neighbours` keyframes of the same sequence, accepted loop edges) and its
// own current estimate X of every keyframe. For a candidate it asks the innovation gate, solves
// the graph plus the candidate, warm-started from X, over the window [match - window_margin,
// newest keyframe] (everything older held fixed, as loop_fusion holds the keyframes before its
// earliest loop) and scores the deformation: s = RMSE of the positions of X and X* after
// Umeyama alignment (the tests themselves: core/decision.h). verify() never changes the graph;
// commit() adds the loop and keeps the X* of the verify() that accepted it (no second solve).
//
// decision chi2 (core/decision.h) decides in units of drift instead: the innovation against the
// covariance of the relative pose through the condensed graph, no trial solve.
//
// Held candidates and later decisions (the protocol a host follows):
//   verdict = verify(c)
//     accepted  -> use the loop, then commit(c)                    (as always)
//     deferred  -> do not use the loop yet (reason kDeferred)       (confirm_without_prior,
//                                                                    hold_sigma, decision
//                                                                    revisit, global_check)
//     otherwise -> rejected
//   after every addKeyframe() and verify(): for (d : takeDecisions())
//     kRelease  -> the held candidate d.candidate is accepted now and ALREADY COMMITTED by the
//                  verifier: apply it to its query keyframe (loop_fusion: has_loop, loop_index,
//                  loop_info; optimize_buf), do not call commit()
//     kDrop     -> the held candidate is rejected for good (reason kUnconfirmed)
//     kRevoke   -> a loop accepted earlier (committed or released) is removed from the
//                  verifier's graph: remove it from the host's (loop_fusion: clear has_loop and
//                  loop_index of the query keyframe and queue an optimisation, which restarts
//                  from the VIO poses with the loops that remain)
// Revocation (revoke_group > 0): a candidate that contradicts an accepted loop of its own
// stretch is held as a rival; a confirmed group of rivals that outnumbers those loops and
// passes against the graph without them revokes them and is released (types.h).
// Decisions come in the order they were made; each held candidate gets exactly one kRelease or
// kDrop; a revoked loop is never released or accepted again.
// Copies (the same query -> match proposed again: loop_fusion re-detects a pair, a bag is
// replayed twice, a driver retransmits) are one piece of evidence, counted once:
//   a copy of a held candidate is deferred, never held itself (it counts toward no
//     confirm_count, revisit_support or group), and gets the held candidate's later decision
//     right after it (the same kind, about the same loop: a host applies or removes the loop
//     once; a released copy is revoked with its loop);
//   a copy of a candidate rejected or dropped earlier gets that rejection's reason;
//   a copy of a loop in the graph is refused: invalid_input, "already in the graph".
// Each gets the numbers (score, d2, ...) of the first candidate's verdict.
//
// Every public method is safe to call from any thread (one internal mutex), never throws for
// bad input and never leaves the graph half-changed: bad input comes back as a Status or as a
// Verdict with reason kInvalidInput.
#pragma once

#include "rover_loop_fusion/core/accepted_loops.h"
#include "rover_loop_fusion/core/copies.h"
#include "rover_loop_fusion/core/decision_rule.h"
#include "rover_loop_fusion/core/held_candidates.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/stage.h"
#include "rover_loop_fusion/core/stage_decide.h"
#include "rover_loop_fusion/core/stage_hold.h"
#include "rover_loop_fusion/core/stage_input.h"
#include "rover_loop_fusion/core/stage_prior.h"
#include "rover_loop_fusion/core/types.h"
#include "rover_loop_fusion/core/verdict_emitter.h"

#include <Eigen/Geometry>

#include <chrono>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

class Verifier {
 public:
  /// An invalid config is replaced by the defaults; configError() says why.
  explicit Verifier(const VerifierConfig& config = VerifierConfig());
  ~Verifier();
  Verifier(const Verifier&) = delete;
  Verifier& operator=(const Verifier&) = delete;

  const VerifierConfig& config() const { return config_; }
  const std::string& configError() const { return config_error_; }

  /// Registers a keyframe (KeyframeGraph::addKeyframe: the rules, the plausibility limits and the
  /// recovery from a jump). Refused input leaves the graph unchanged; ok with a message is a
  /// warning for the host's log.
  Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                     const Eigen::Quaterniond& q, const Eigen::Matrix4d* step_covariance = nullptr);

  /// Scores a candidate against the trajectory prior. Does not change the graph; a deferred
  /// verdict holds the candidate (see the protocol above).
  Verdict verify(const LoopCandidate& candidate);

  /// The decisions made since the last call, oldest first (see the protocol above). Cheap when
  /// there are none.
  std::vector<LoopDecision> takeDecisions();
  /// Candidates held now (deferred, neither released nor dropped yet).
  size_t heldCount() const;

  /// Adds a loop edge that the host is going to use and updates X. If the last verify()
  /// accepted this very candidate, its X* is kept (no second solve); otherwise (stored loops
  /// of a loaded map, loops accepted without a prior, an override) the graph is solved once:
  /// for a loop without a prior within time_budget_ms (a Warning says when the budget stopped
  /// that update of X), otherwise to convergence.
  /// A first loop between two sequences anchors the query's sequence to the match's frame
  /// exactly as loop_fusion shifts it (w_r_vio / w_t_vio). (A graph that only collects loops,
  /// solved once at the end: KeyframeGraph::addLoop.)
  Status commit(const LoopCandidate& candidate);

  size_t keyframeCount() const;
  size_t loopCount() const;
  bool hasKeyframe(int64_t index) const;
  /// The current estimate X of a keyframe; false if unknown.
  bool estimate(int64_t index, Pose* pose) const;
  std::vector<TrajectoryPoint> trajectory() const;
  /// Ceres solves run so far (verify, commit, solveLikeLoopFusion); diagnostics that let
  /// tests and benchmarks see that a verify()+commit() pair costs one solve.
  size_t solveCount() const;

  /// Solves the whole graph as loop_fusion's optimize4DoF/optimize6DoF does: keyframes from
  /// the earliest loop's match on, initialised from the VIO poses, that keyframe and sequence
  /// 0 held fixed, committed loops with Huber loss, `max_iterations` (loop_fusion: 5).
  /// For benchmarks and evaluation; does not change the verifier.
  BatchSolveResult solveLikeLoopFusion(int max_iterations = 5) const;

  /// decision chi2: the variance scale of the drift model (1 unless calibrate_drift fitted it).
  double driftScale() const;

  /// Diagnostics (the agreement benchmark, rover_replay --compare-trials): the verdicts that
  /// decision metric gives `c` against the graph and X as they are now with the full-window
  /// trial (first) and with trials over more than `condense_min_window` keyframes condensed
  /// (second). Changes nothing (no pending commit, nothing held); a candidate with no trial
  /// (invalid, no prior, decision chi2) gets the same invalid_input verdict in both.
  std::pair<Verdict, Verdict> compareTrials(const LoopCandidate& candidate, int condense_min_window);

 private:
  /// What verify()'s last stage said, acted on: a candidate to hold is held (the global pool for
  /// kGlobal: the rule's rejection `failed` stands if it does not qualify), an accepted one's
  /// decided work kept for commit().
  StageOutcome act(Passage* p, StageOutcome out, const StageOutcome& failed);
  /// Holds a candidate (a deferred verdict) and settles what is due.
  void hold(const LoopCandidate& c, size_t query_pos, size_t match_pos, HoldKind kind, double d2 = 0.0);
  Status commitLocked(const LoopCandidate& c, bool update_estimate);
  /// A confirmed group of rivals that outnumbers the `loops` it contradicts: revoke them and
  /// release the rivals that pass against the graph without them, or put everything back and
  /// drop the group.
  void settleRivals(const HeldGroup& group, const std::vector<LoopCandidate>& loops);
  /// global_check: a candidate (held for the pool, or a member of a dropped revisit hypothesis)
  /// joins the global pool (the oldest is dropped when it is full); false if it does not qualify
  /// (then it is rejected or dropped).
  bool addToGlobalPool(const HeldCandidate& h);
  /// global_check: the global pass over the pool (every global_period keyframes): releases the
  /// inliers the other loops pin down, drops what waited longer than global_window. A warning
  /// if it stopped at global_budget_ms (nothing released; the next pass tries again).
  Status globalPass();
  /// Acts on what the store of held candidates says is due: releases groups that are confirmed,
  /// drops those that expired; the revisit hypotheses too if `revisit` (on keyframe arrival
  /// only: their joint trials).
  void settle(bool revisit);
  /// Commits a confirmed group and emits its releases (`judged`: what a revisit hypothesis'
  /// joint test found).
  void release(const HeldGroup& group, const std::string& judged = std::string());
  /// Drops a group's members, each tested alone first where loops were committed since it was
  /// held; a revisit member whose hypothesis failed before any such commit waits (HeldCandidates::wait()).
  void drop(const HeldGroup& group, const std::string& why, bool contradicted);
  void dropMember(const HeldCandidate& h, const std::string& why, bool contradicted);
  /// Whether a dropped revisit member is tested alone now (else it waits for the next
  /// keyframe): while revisit_retest_budget_ms, counted from the keyframe's arrival, is not
  /// spent (at least one re-test per keyframe). Revisit members are dropped on keyframe arrival only.
  bool retestNow() const;
  /// A keyframe's budget for work on its arrival (revisit_retest_budget_ms, global_budget_ms):
  /// `ms`, or 0 (no bound) when time_budget_ms 0 lifts every budget (verdicts independent of the
  /// machine's load: the benchmarks).
  double arrivalBudgetMs(double ms) const { return config_.trial.time_budget_ms > 0 ? ms : 0.0; }
  /// What the last verify() that accepted worked out, for commit() to keep.
  struct Pending {
    bool valid = false;
    LoopCandidate candidate;
    uint64_t revision = 0;  ///< the graph's revision it was decided on
    Decided decided;
  };
  std::string config_error_;  // before config_: the constructor validates first
  VerifierConfig config_;
  mutable std::mutex mutex_;
  KeyframeGraph graph_;
  std::unique_ptr<DecisionRule> rule_;
  Pending pending_;
  AcceptedLoops loops_;  ///< the tests of held candidates against the accepted loops
  HeldCandidates held_;  ///< every held candidate, whatever it waits for
  /// The re-tests of the addKeyframe() running (retestNow()).
  struct RetestBudget {
    std::chrono::steady_clock::time_point started;
    size_t count = 0;  ///< re-tests run on this keyframe
  };
  RetestBudget retest_;
  size_t last_global_pass_ = 0;  ///< global_check: keyframes at the last global pass
  /// What the last global pass was given: one over the same loops, estimate, drift scale and
  /// pool decides the same, and is skipped unless a candidate's global_window ends.
  struct GlobalInputs {
    uint64_t graph_revision = ~uint64_t(0);
    uint64_t pool_revision = ~uint64_t(0);
    double drift_scale = 0.0;
    bool operator==(const GlobalInputs& o) const {
      return graph_revision == o.graph_revision && pool_revision == o.pool_revision && drift_scale == o.drift_scale;
    }
  };
  GlobalInputs last_global_inputs_;
  /// What the copies of a candidate get (also verify()'s copies stage).
  Copies copies_;
  /// Every verdict and decision leaves through it; it keeps the queue of decisions.
  VerdictEmitter emit_{copies_};
  /// verify()'s stages, in the order they run (Copies between input and prior).
  InputStage input_{graph_};
  PriorStage prior_{config_.host, config_.hold, graph_};
  DecideStage decide_{config_, graph_, *rule_, loops_};
  HoldStage hold_stage_{config_.hold, config_.global, config_.decision, loops_};
};

}  // namespace core
}  // namespace rover_loop_fusion
