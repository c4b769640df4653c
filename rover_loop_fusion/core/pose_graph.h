// The pose graph of the ROVER core: keyframes (VIO poses), odometry edges to the previous
// `odometry_neighbours` keyframes of the same sequence (as loop_fusion), loop edges, sequences
// (union-find; loop_fusion's first-loop anchoring shift), the current estimate X of every
// keyframe, trial problems over a window, and loop_fusion's own batch solve.
//
// Used by the verifier (core/verifier.h, which adds the decision and the pending state), and
// on its own as loop_fusion's stand-in: the graph that rover_verifier_node and rover_replay
// solve like loop_fusion for any plugin, including accept-all.
//
// Edges carry an information matrix of their residual (core/cost_functions.h); today every
// edge has unit information, loop_fusion's weighting.
//
// Not thread-safe: one thread at a time (core::Verifier holds a mutex around its graph).
// Never throws for bad input: refusals come back as a Status or an error text, and leave the
// graph unchanged.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <Eigen/Core>

#include <chrono>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// Keyframe positions beyond this distance from the origin along any axis [m] are not VIO
/// poses (and their squares would overflow path lengths): refused.
constexpr double kMaxCoordinate = 1e8;

/// The parameters of one keyframe in an optimisation. 4-DoF: yaw + t (roll and pitch stay
/// those of the VIO pose); 6-DoF: q [w, x, y, z] + t.
struct KeyframeState {
  double t[3] = {0, 0, 0};
  double yaw = 0;
  double q[4] = {1, 0, 0, 0};
};

/// The solution of a trial problem: what verify() scores and commit() may adopt.
struct TrialSolution {
  std::vector<size_t> positions;      ///< optimised keyframes (positions in the graph), increasing
  std::vector<KeyframeState> states;  ///< their solution, in the same order
  SolveSummary summary;
  /// A condensed trial (condense_min_window): positions/states hold its anchors only; the other
  /// keyframes of the window [first, newest] of segment root `component` follow from them
  /// (scoredPositions(), adopt()).
  bool condensed = false;
  size_t first = 0;
  int component = 0;
};

/// A condensed trial scores at most this many keyframes of its window (evenly spaced): the
/// RMSE of a smooth deformation, at a cost that does not grow with the window.
constexpr size_t kCondensedScoredKeyframes = 2000;

/// Result of solveLikeLoopFusion(): the trajectory loop_fusion's own optimisation would give.
struct BatchSolveResult {
  bool ok = false;
  std::string message;
  int iterations = 0;
  double solve_ms = 0.0;
  int free_keyframes = 0;
  std::vector<Pose> poses;  ///< one per keyframe, in trajectory() order
};

/// What the global pass (KeyframeGraph::globalConsistency) found for one candidate loop.
struct GlobalLoop {
  /// Weight above 0.5 at the end of the robust solve and its residual within the inlier quantile.
  bool inlier = false;
  /// An inlier whose cycle (the odometry between its ends) the robust solution bends beyond the
  /// tear quantile: it is part of a solution that tears the trajectory (not tested further).
  bool torn = false;
  /// Its residual's chi-square in the robust solution (NaN: not solved: no prior, a failed solve).
  double chi2 = std::numeric_limits<double>::quiet_NaN();
  /// Inliers, not torn: tested against the graph without them (leave one out): d2 and sigma set.
  bool pinned = false;
  /// Mahalanobis distance of the candidate from the relative pose the graph without it gives
  /// its ends (that pose's covariance plus the loop's).
  double d2 = std::numeric_limits<double>::quiet_NaN();
  /// The largest standard deviation of that relative position [m]: how tightly the other loops
  /// pin the candidate down.
  double sigma = std::numeric_limits<double>::quiet_NaN();
};

class KeyframeGraph {
 public:
  /// Reads mode, odometry_neighbours, loop_huber, function_tolerance, quaternion_tolerance,
  /// window_margin, max_relative_translation, max_relative_yaw, anchor_incoming_keyframes,
  /// max_keyframe_jump, max_stamp_jump and jump_confirmations. The config is used as given
  /// (validate it first).
  explicit KeyframeGraph(const VerifierConfig& config = VerifierConfig());
  ~KeyframeGraph();
  KeyframeGraph(const KeyframeGraph&) = delete;
  KeyframeGraph& operator=(const KeyframeGraph&) = delete;

  const VerifierConfig& config() const { return config_; }

  // ---- keyframes ----------------------------------------------------------------------------
  /// Registers a keyframe. Indices must be strictly increasing (loop_fusion's global index),
  /// sequences non-decreasing; the pose must be finite (within kMaxCoordinate) with a unit
  /// quaternion. Within a live sequence a keyframe must follow the previous one plausibly
  /// (max_keyframe_jump, stamp after it by at most max_stamp_jump); an implausible one is
  /// refused unless it ends a run of jump_confirmations consistent keyframes (accepted with a
  /// warning: a relocation starts a new segment, or a new clock). Sequence 0 (a loaded map,
  /// held fixed) may come out of time order: kept, with one warning. Refused input leaves the
  /// graph unchanged; ok with a message is a warning.
  /// `step_covariance` (optional): the covariance of the odometry step from the previous
  /// keyframe of its sequence to this one (x, y, z, yaw in this keyframe's frame), where the
  /// data carries it (g2o files); the uncertainty (decision chi2, revisit) uses it instead of the
  /// drift model's for that step. One that is not finite or not positive definite is ignored
  /// with a warning.
  Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                     const Eigen::Quaterniond& q, const Eigen::Matrix4d* step_covariance = nullptr);
  size_t keyframeCount() const;
  bool hasKeyframe(int64_t index) const;
  /// Position (0 = oldest) of the keyframe with this index; false if unknown.
  bool find(int64_t index, size_t* position) const;
  int sequenceAt(size_t position) const;
  /// The segment of a keyframe (odometry joins only keyframes of one segment).
  int segmentAt(size_t position) const;

  // ---- loops --------------------------------------------------------------------------------
  /// Empty if the candidate can be used as a loop edge (known keyframes, match older than
  /// query, finite and plausible relative pose); otherwise why not. Fills the positions.
  std::string checkLoop(const LoopCandidate& c, size_t* query_pos, size_t* match_pos) const;
  /// Adds the loop edge (no solve; X unchanged). A first loop between two sequences anchors
  /// the query's sequence to the match's frame exactly as loop_fusion shifts it
  /// (w_r_vio / w_t_vio). Refuses what checkLoop() refuses and a loop already in the graph.
  Status addLoop(const LoopCandidate& c);
  /// Whether the loop query -> match (keyframe indices) is in the graph.
  bool hasLoop(int64_t query_index, int64_t match_index) const;
  size_t loopCount() const;
  /// Whether the two keyframes' sequences are tied together by loops (a trajectory prior).
  bool connected(size_t a, size_t b) const;
  /// Changes with every loop added: a trial solution of an older revision is stale.
  uint64_t revision() const;

  // ---- the estimate X -------------------------------------------------------------------------
  bool estimate(int64_t index, Pose* pose) const;
  /// X of the keyframe at `position`; false if there is none.
  bool estimateAt(size_t position, Pose* pose) const;
  /// The VIO pose of the keyframe at `position` (after any sequence anchoring shift); false if
  /// there is none.
  bool vioAt(size_t position, Pose* pose) const;
  std::vector<TrajectoryPoint> trajectory() const;
  /// |t_meas - t_X|: where the candidate puts the query in the match's frame vs where X has it [m].
  double innovation(const LoopCandidate& c, size_t query_pos, size_t match_pos) const;
  /// Shortest odometry path [m] between two keyframes through the graph: along a sequence by
  /// arc length, across accepted loops for free. Infinite if nothing connects them.
  double pathLength(size_t from, size_t to) const;
  /// Keep what pathLength searches (the places that loops tie together) up to date as loops
  /// are added from now on. Without it, it is built on the first pathLength, which then pays
  /// for every loop before it at once (a removed loop makes the next one rebuild it too).
  void keepPathLengths();

  // ---- optimisation ---------------------------------------------------------------------------
  /// Solves the window [match - window_margin, newest] of the query's connected sequences,
  /// warm-started from X, with `candidate` as an extra loop edge (nullptr: none; robust: with
  /// the committed loops' Huber loss). The window's first keyframe and sequence 0 are held
  /// fixed, older keyframes too. Does not change the graph. Windows of more than
  /// condense_min_window keyframes are solved on the condensed graph (bounded cost; the full
  /// window if that fails). time_budget_ms <= 0: no limit;
  /// otherwise the call returns by it: a trial that cannot finish building and one iteration
  /// within it (at the cost per keyframe measured on this graph's solves so far) is not
  /// started, and the solve stops before an iteration that would end past it (both:
  /// summary.timed_out, with why in summary.message; a stopped solve keeps its last iterate).
  /// `condense_min_window` >= 0 overrides the config's (diagnostics: Verifier::compareTrials).
  TrialSolution solveWindow(size_t match_pos, size_t query_pos, const LoopCandidate* candidate,
                            bool robust_candidate, int max_iterations, double time_budget_ms,
                            int condense_min_window = -1);
  /// A trial with several candidate loops at once (decision revisit: a hypothesis' members),
  /// as above: the window from the earliest match on, the component of the last candidate's
  /// query. Candidates with unknown keyframes are left out (none left: a failed solution).
  TrialSolution solveWindow(const std::vector<LoopCandidate>& candidates, bool robust_candidate, int max_iterations,
                            double time_budget_ms);
  /// Positions of the keyframes of a solution that may move (not sequence 0), in X (`before`)
  /// and in the solution (`after`), 3 x N each (a condensed trial: at most
  /// kCondensedScoredKeyframes of them, evenly spaced). Returns N.
  int scoredPositions(const TrialSolution& solution, Eigen::Matrix3Xd* before,
                      Eigen::Matrix3Xd* after) const;
  /// X := the solution; keyframes added after the solution was computed follow the
  /// correction of the newest solved keyframe.
  void adopt(const TrialSolution& solution);
  /// Solves the whole graph as loop_fusion's optimize4DoF/optimize6DoF does: keyframes from
  /// the earliest loop's match on, initialised from the VIO poses, that keyframe and sequence
  /// 0 held fixed, committed loops with Huber loss, `max_iterations` (loop_fusion: 5).
  /// Does not change the graph.
  BatchSolveResult solveLikeLoopFusion(int max_iterations = 5) const;
  /// Ceres solves run so far (diagnostics for tests and benchmarks).
  size_t solveCount() const;

  // ---- uncertainty (decision chi2; core/drift.h, core/condensed.h) ---------------------------
  // In x, y, z, yaw; a 6-DoF graph too (its states' yaw follows their q; an update changes
  // x, y, z and yaw, turning q about the world z axis).
  // Odometry steps carry the drift model's covariance (config drift_*), accepted loops
  // loop_sigma / loop_sigma_yaw. Everything below works on the condensed graph: the loop ends
  // (merged and capped by max_loop_anchors) and the keyframes asked about, joined by chains
  // whose covariance comes from prefix moments: O(anchors), whatever the run's length.

  /// Covariance (x, y, z, yaw; translation in the match's frame) of the query's pose relative
  /// to the match's through the graph, drift variances times `variance_scale`; the number of
  /// anchors used in *anchors. False if the two are not tied together.
  bool relativeCovariance(size_t match_pos, size_t query_pos, double variance_scale,
                          Eigen::Matrix4d* covariance, int* anchors = nullptr) const;
  /// Covariance of the pose of keyframe `to` relative to `from` (from < to, one segment) along
  /// the odometry alone (no loops), translation in `from`'s frame; false otherwise.
  bool chainCovariance(size_t from, size_t to, double variance_scale, Eigen::Matrix4d* covariance) const;
  /// Covariance of a loop's relative pose (loop_sigma, loop_sigma_yaw).
  Eigen::Matrix4d loopCovariance() const;
  /// Keep the prefix moments up to date on keyframe arrival from now on: the drift-weighted
  /// ones (everything above) and/or the unit-weight ones (condensed trials). Without it each
  /// kind is built on its first use, which then pays for every keyframe before it at once.
  void keepMoments(bool drift_weighted, bool unit_weight);
  /// The candidate's relative pose minus what X predicts: translation in the match's frame, yaw.
  Eigen::Vector4d innovationVector(const LoopCandidate& c, size_t query_pos, size_t match_pos) const;
  /// X := the weighted least-squares estimate of the component of `position` with its accepted
  /// loops (Gauss-Newton on the condensed graph; the chains between anchors follow as the
  /// linear solve places them). Error (X unchanged) if the solve failed.
  Status updateEstimate(size_t position, double variance_scale);
  /// Removes an accepted loop (a revocation); X is not updated (updateEstimate, solveWindow).
  /// The sequences stay connected.
  Status removeLoop(int64_t query_index, int64_t match_index);
  /// The accepted loops whose query keyframe lies at positions [first, last] (a revisit's
  /// stretch), in the order they were added. O(loops).
  std::vector<LoopCandidate> loopsWithQueryIn(size_t first, size_t last) const;
  /// Decision revisit's global pass (core/global_pass.cpp): the `candidates` as robust loop
  /// edges (graduated non-convexity, truncated quadratic loss at `inlier_chi2`) on the condensed
  /// graph of their component with its accepted loops, drift variances times `variance_scale`.
  /// An inlier whose odometry between its ends the solution bends beyond `tear_chi2` (a chain
  /// edge's chi-square) is torn; the other inliers are tested against the graph without them
  /// (leave one out; only those marked in `test_alone`, if it is not empty: one solve each).
  /// One GlobalLoop per candidate, in order. Changes nothing. False if a
  /// component's condensed graph could not be built or solved (its candidates stay without a
  /// result: chi2 NaN), or if `deadline` passed (checked after every solve; *timed_out set, the
  /// results incomplete: not to be acted on).
  bool globalConsistency(const std::vector<LoopCandidate>& candidates, double inlier_chi2, double tear_chi2,
                         double variance_scale, const std::vector<bool>& test_alone,
                         std::vector<GlobalLoop>* out,
                         std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max(),
                         bool* timed_out = nullptr) const;
  /// X of every keyframe, and X := such a copy again (a revocation that did not go through puts
  /// the estimate back; false, X unchanged, if the keyframe count differs).
  std::vector<KeyframeState> estimates() const;
  bool restoreEstimates(const std::vector<KeyframeState>& states);

 private:
  struct Impl;
  VerifierConfig config_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace core
}  // namespace rover_loop_fusion
