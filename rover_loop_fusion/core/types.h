// Plain value types of the ROS-free ROVER core.
//
// Units: metres and radians everywhere inside the core. loop_fusion hands relative yaw in
// degrees (its loop_info[7]); candidateFromLoopInfo() converts at the boundary.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cstdint>
#include <limits>
#include <string>

namespace rover_loop_fusion {
namespace core {

/// Degrees of freedom of the pose graph.
/// kFourDof: x, y, z, yaw (roll and pitch fixed from the VIO pose) — loop_fusion with IMU.
/// kSixDof: full SE(3) — loop_fusion without IMU (visual odometry).
enum class Mode { kFourDof, kSixDof };

/// How the positions before and after the trial optimisation are aligned before scoring.
/// kSE3 when scale is observable (VIO, stereo); kSim3 for monocular VO.
enum class Alignment { kSE3, kSim3 };

/// How a candidate is decided (docs/method.md).
/// kMetric: the paper's deformation score against a threshold in metres, behind an innovation
///   gate in metres that grows with the path (rover_paper.yaml: threshold only).
/// kChi2: in units of drift: the innovation's Mahalanobis distance under the uncertainty of the
///   relative pose through the graph (drift model + accepted loops) against a chi-square
///   quantile, and the look-alike test (no look-alike place explains the candidate better).
///   6-DoF (VO): the same test on x, y, z and yaw of the 6-DoF poses (the drift model has no
///   roll and pitch: their effect on the position belongs in drift_xy / drift_z), and the
///   estimate is updated in those four (roll and pitch stay the VO's).
/// kRevisit: the revisit as the unit of decision (docs/method.md). A candidate that passes the
///   metric test is accepted at once (the fast path, where the prior is tight); one that fails
///   it but that the drift model does not rule out (revisit_reject_probability) is held as a
///   member of a revisit hypothesis (mutually consistent candidates of one stretch), which is
///   released as a group once it has revisit_support members, does not contradict the accepted
///   loops of its stretch, lies within the prior (revisit_gate_probability), bends the
///   trajectory with all its loops by at most max(threshold, revisit_score_sigmas x std) and
///   fits better than every rival hypothesis of its revisit (revisit_member_weight,
///   revisit_margin); dropped if that does not happen within revisit_window keyframes.
enum class Decision { kMetric, kChi2, kRevisit };

/// Why a verdict came out the way it did. Exactly one per verdict.
enum class Reason {
  kAccepted,             ///< solve converged and score <= threshold
  kScoreAboveThreshold,  ///< solve converged but the trajectory deformed too much
  kNotConverged,         ///< the solver stopped without converging (or failed)
  kNoTrajectoryPrior,    ///< query and match are in sequences nothing connects yet
  kInvalidInput,         ///< the candidate or the graph state is not usable
  kTimeBudgetExceeded,   ///< the solve ran past config.trial.time_budget_ms
  kInconsistentWithDrift, ///< chi2: the innovation's Mahalanobis distance exceeds the gate
  kLookalikeCloser,      ///< chi2: a look-alike place at lookalike_distance explains it better
  kDeferred,             ///< held: neither accepted nor rejected yet; a LoopDecision follows
  kUnconfirmed,          ///< a held candidate that was not confirmed (in time, or a rival won)
  kRevoked,              ///< an accepted loop that a larger consistent group contradicted
  kInnovationAboveBound, ///< the candidate disagrees with the estimate by more than the drift
                         ///< over the path between the two keyframes can explain (no solve)
};

/// snake_case name used in messages, logs and CSV ("score_above_threshold", ...).
const char* toString(Reason reason);
const char* toString(Mode mode);
const char* toString(Alignment alignment);
const char* toString(Decision decision);
bool parseDecision(const std::string& s, Decision* decision);
bool parseMode(const std::string& s, Mode* mode);
bool parseAlignment(const std::string& s, Alignment* alignment);

struct Pose {
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Pose() = default;
  Pose(const Eigen::Vector3d& t_, const Eigen::Quaterniond& q_) : t(t_), q(q_) {}
};

/// A loop candidate that passed geometric verification (PnP/RANSAC in loop_fusion).
/// The relative pose is the query keyframe expressed in the match keyframe's frame, exactly
/// what loop_fusion stores in KeyFrame::loop_info.
struct LoopCandidate {
  int64_t query_index = -1;  ///< the newer keyframe (loop_fusion: cur_kf->index)
  int64_t match_index = -1;  ///< the older keyframe (loop_fusion: old_kf->index / loop_index)
  Eigen::Vector3d relative_t = Eigen::Vector3d::Zero();
  Eigen::Quaterniond relative_q = Eigen::Quaterniond::Identity();
  double relative_yaw = 0.0;  ///< radians; used by the 4-DoF graph
  int inliers = -1;           ///< feature inliers of the geometric check, -1 if unknown
};

/// Builds a candidate from loop_fusion's loop_info layout
/// [t_x, t_y, t_z, q_w, q_x, q_y, q_z, relative_yaw_degrees].
LoopCandidate candidateFromLoopInfo(int64_t query_index, int64_t match_index,
                                    const double loop_info[8], int inliers = -1);

struct Verdict {
  int64_t query_index = -1;
  int64_t match_index = -1;
  bool accepted = false;
  /// The candidate is held (reason kDeferred, accepted false): the host must not use the loop
  /// now; Verifier::takeDecisions() says later whether it was released or dropped.
  bool deferred = false;
  Reason reason = Reason::kInvalidInput;
  /// The trial's deformation score: RMSE of the aligned positions [m]; NaN without a trial
  /// (the innovation gate, decision chi2, invalid input).
  double score = std::numeric_limits<double>::quiet_NaN();
  /// The score's threshold [m], effective (threshold + threshold_per_metre x path length); the
  /// configured one where no trial ran (NaN: decision chi2, which has none).
  double threshold = std::numeric_limits<double>::quiet_NaN();
  /// The innovation's squared Mahalanobis distance under the drift model through the graph
  /// (decision chi2; revisit: a candidate the trial rejected, tested for holding); NaN if not
  /// computed.
  double d2 = std::numeric_limits<double>::quiet_NaN();
  /// The chi-square quantile d2 was compared with (chi2: gate_probability; revisit:
  /// revisit_reject_probability); NaN if none.
  double gate = std::numeric_limits<double>::quiet_NaN();
  std::string detail;     ///< human-readable explanation (what was wrong, what was done)
  bool converged = false;
  int iterations = 0;     ///< solver iterations of the trial optimisation
  int window_size = 0;    ///< keyframes optimised and scored by the trial; 0 without a trial
  /// Distance between where the candidate puts the query keyframe and where the current
  /// estimate X has it, in the match keyframe's frame [m]; NaN if not computed.
  double innovation = std::numeric_limits<double>::quiet_NaN();
  /// Odometry path length from the match to the query keyframe through the current graph
  /// (accepted loops count as zero length) [m]: the distance over which drift accumulated.
  double path_length = std::numeric_limits<double>::quiet_NaN();
  double solve_ms = 0.0;  ///< Ceres time
  double elapsed_ms = 0.0;  ///< whole verify() call

  /// A verdict that lets the candidate's loop in: reason kAccepted, or kNoTrajectoryPrior for a
  /// candidate accepted by policy (accept_without_prior).
  static Verdict Accept(const LoopCandidate& candidate, std::string detail,
                        Reason reason = Reason::kAccepted);
  /// A verdict that keeps the candidate's loop out, with why (kAccepted is taken as kInvalidInput).
  static Verdict Reject(Reason reason, const LoopCandidate& candidate, std::string detail);
  /// A verdict that holds the candidate (reason kDeferred, deferred true, accepted false).
  static Verdict Defer(const LoopCandidate& candidate, std::string detail);
};

/// A decision about a candidate made after verify() returned for it (Verifier::takeDecisions;
/// here so that the plugin interface can hand them on without the verifier's header).
struct LoopDecision {
  enum class Kind {
    kRelease,  ///< a held candidate accepted (and committed by the verifier)
    kDrop,     ///< a held candidate rejected (reason kUnconfirmed)
    kRevoke,   ///< an accepted loop removed again (reason kRevoked)
  };
  Kind kind = Kind::kDrop;
  LoopCandidate candidate;  ///< as handed to verify()
  Verdict verdict;          ///< the final verdict: accepted for kRelease, rejected otherwise
};
const char* toString(LoopDecision::Kind kind);  // "release", "drop", "revoke"

/// One keyframe of a trajectory, as reported by Verifier::trajectory(), KeyframeGraph::trajectory()
/// and the plugins.
struct TrajectoryPoint {
  int64_t index = -1;
  double stamp = 0.0;
  int sequence = 0;
  Pose vio;       ///< as handed to addKeyframe (after any sequence anchoring shift)
  Pose estimate;  ///< the current estimate X (VIO + accepted loops)
};

/// What one Ceres solve reported.
struct SolveSummary {
  bool converged = false;  ///< Ceres' CONVERGENCE
  bool timed_out = false;  ///< stopped by the time limit
  bool finite = false;     ///< every parameter of the solution is finite
  int iterations = 0;      ///< iterations, without Ceres' initial evaluation
  double solve_ms = 0.0;
  std::string message;     ///< Ceres' summary message
};

/// Result of calls that can refuse input (addKeyframe, commit). Never throws.
/// ok with a message is a warning: the call did what was asked, but something deserves a
/// WARN in the host's log (the message says what).
struct Status {
  bool ok = true;
  std::string message;
  static Status Ok() { return Status(); }
  static Status Error(std::string msg) {
    Status s;
    s.ok = false;
    s.message = std::move(msg);
    return s;
  }
  static Status Warning(std::string msg) {
    Status s;
    s.message = std::move(msg);
    return s;
  }
  bool warning() const { return ok && !message.empty(); }
  explicit operator bool() const { return ok; }
};

/// An accepted verdict whose commit the verifier refused (the same loop again: "already in the
/// graph"): the loop is not in the graph, so the verdict becomes an invalid_input rejection
/// that says why ("...; but the verifier refused to commit it: ..."). The hosts and rover_replay
/// report a refused commit this way, so that a verdict says what was committed.
void rejectRefusedCommit(Verdict* v, const Status& commit);

// ---- the verifier's parameters (VerifierConfig), nested by concern --------------------------
// Every field is a row of the parameter table (core/parameters.h: its YAML name, unit, range and
// doc) and is named by its key; adding a field means adding its row there.

/// The metric decision's tests, in metres (decision metric; revisit's fast path).
struct MetricConfig {
  /// Accept iff score <= threshold + threshold_per_metre * path_length [m], where
  /// path_length is the odometry distance from the match to the query through the graph
  /// (accepted loops count zero): a true loop's score grows with the drift it corrects, and
  /// drift grows with the distance travelled since the places were last tied together.
  /// threshold_per_metre = 0 is a fixed threshold, as in the paper (0.5 indoor, 1.0
  /// outdoor). The default 0.2 m is measured, not the paper's: docs/design-notes.md.
  double threshold = 0.2;
  double threshold_per_metre = 0.0;
  /// Upper bound of the effective threshold [m] (0: none).
  double max_threshold = 0.0;
  /// Innovation gate, checked before the trial solve: reject when the candidate puts the query
  /// keyframe farther from the current estimate than
  ///   max_innovation + max_innovation_per_metre * path_length   [m]
  /// (a drift rate over the odometry path from match to query through the graph). It catches
  /// what a diluted score misses: a look-alike next to places the graph already ties together
  /// (innovation ~ offset, path ~ metres). max_innovation = 0 disables the gate.
  double max_innovation = 0.5;
  double max_innovation_per_metre = 0.02;
};

/// The trial optimisation: limits, graph and loss, condensed trials.
struct TrialConfig {
  /// Trial optimisation limits. A solve that stops on either limit did not converge and the
  /// candidate is rejected (fail closed). time_budget_ms = 0 disables the time limit.
  int max_iterations = 50;
  double time_budget_ms = 200.0;
  /// Relative cost change at which the trial optimisation counts as converged. 1e-4 changes
  /// scores by millimetres against Ceres' default 1e-6 and saves about 40 % of the iterations.
  double function_tolerance = 1e-4;
  /// Odometry edges from each keyframe to its previous N keyframes of the same sequence
  /// (loop_fusion uses 4).
  int odometry_neighbours = 4;
  /// Huber scale of committed loop edges (loop_fusion: HuberLoss(0.1)).
  double loop_huber = 0.1;
  /// Whether the candidate itself gets the Huber loss in the trial optimisation. ROVER asks
  /// "how would the trajectory deform if this loop were true", so by default it does not:
  /// a robust loss would let a false loop pull only weakly and hide the tear.
  bool robust_candidate = false;
  /// Keyframes before the match keyframe that are also optimised and scored (the trial
  /// window is [match - window_margin, newest]; everything older is held fixed).
  int window_margin = 0;
  /// Bounded cost (4-DoF): a trial whose window holds more than this many keyframes is solved on
  /// the condensed graph (core/condensed.h: the chains of odometry between the loop ends, the
  /// match and the query become single edges with loop_fusion's unit weighting; the keyframes
  /// between them follow as the linear solve places them; the score is taken on at most
  /// kCondensedScoredKeyframes of them). 0 = always the full window (Ceres), as the paper.
  /// The default is where the full trial starts to cost more than ~2 ms (docs/results.md).
  int condense_min_window = 200;
  /// Accepted loops at most in a condensed trial (loops of one revisit merged first, then older
  /// ones thinned): what bounds its cost. Thinning leaves the trial less stiff than the full
  /// window, so keep it above the loops a window usually holds.
  int trial_loop_anchors = 1024;
};

/// Plausibility of what a host hands in: candidates' relative poses, keyframe streams.
struct InputLimits {
  /// Plausibility limits of a candidate's relative pose (loop_fusion's findConnection drops
  /// |t| >= 20 m and |yaw| >= 30 deg). Beyond them the candidate is invalid input.
  double max_relative_translation = 20.0;
  double max_relative_yaw = 30.0 * M_PI / 180.0;
  /// Tolerance on | |q| - 1 | for quaternions handed in.
  double quaternion_tolerance = 1e-3;
  /// Plausibility of the keyframe stream of a live sequence (not of sequence 0, a loaded map).
  /// A keyframe farther than max_keyframe_jump [m] from the previous keyframe of its sequence,
  /// or stamped not after it or more than max_stamp_jump [s] after it, is refused (one glitch,
  /// e.g. x += 1e30 or a stamp of 4e9 s, costs one keyframe, not the session). When
  /// jump_confirmations consecutive keyframes each follow the one before plausibly, the last of
  /// them is accepted: after a position jump as the start of a new segment (the VIO relocated:
  /// no odometry across the jump), after a stamp jump on the new clock.
  double max_keyframe_jump = 10.0;
  double max_stamp_jump = 3600.0;
  int jump_confirmations = 3;
};

/// Set by the host (the loop_fusion adapter, rover_verifier_node, rover_replay flags), never
/// from a verifier YAML.
struct HostPolicy {
  /// Policy for candidates between sequences that nothing connects yet (no prior to test
  /// against). true = accept as upstream loop_fusion does when merging maps.
  bool accept_without_prior = true;
  /// true: keyframe poses arrive in the raw VIO frame of their sequence (the standalone node
  /// fed from /vins_estimator/keyframe_pose) and the verifier applies the sequence anchoring
  /// shift itself. false: the caller already did (patched loop_fusion hands poses after its
  /// w_r_vio / w_t_vio shift).
  bool anchor_incoming_keyframes = false;
  /// Candidates between sequences nothing connects yet (relocalisation, map merging): hold and
  /// release them once confirmed (takes precedence over accept_without_prior).
  bool confirm_without_prior = false;
};

/// The odometry drift model and the loops' noise (decisions chi2 and revisit; docs/method.md).
struct DriftConfig {
  /// Odometry drift model (core/drift.h): standard deviation per square root of a metre
  /// travelled, horizontal and vertical translation [m/sqrt(m)] and yaw [rad/sqrt(m)]; every
  /// keyframe step counts as at least drift_min_step [m] (rotations in place drift too).
  double drift_xy = 0.05;
  double drift_z = 0.025;
  double drift_yaw = 0.2 * M_PI / 180.0;
  double drift_min_step = 0.05;
  /// Standard deviation of a loop's relative pose (what PnP on the place returns) [m], [rad].
  double loop_sigma = 0.05;
  double loop_sigma_yaw = 1.0 * M_PI / 180.0;
  /// Scale the drift model's variances to the innovations of the loops accepted so far (a
  /// robust maximum-likelihood fit, clamped to [1/100, 100]): the user need not know the VIO's
  /// drift rate exactly.
  bool calibrate_drift = false;
};

/// Decision chi2: the gate, the look-alike test, the condensed graph's anchors, holding a weak prior.
struct Chi2Config {
  /// The gate: reject iff the innovation's Mahalanobis distance d2 (4 dof) exceeds the
  /// chi-square quantile of this probability.
  double gate_probability = 0.999;
  /// The look-alike test: the environment repeats itself lookalike_distance [m] away
  /// horizontally (aisles, doors) and lookalike_distance_vertical [m] away vertically (floors);
  /// 0 = no such look-alikes. Reject a candidate when "a look-alike that far away" explains its
  /// innovation nearly as well as "this is the place": d2(nu - o) - d2(nu) < lookalike_margin
  /// for some such offset o.
  double lookalike_distance = 1.5;
  double lookalike_distance_vertical = 1.5;
  double lookalike_margin = 4.0;
  /// Accepted loops at most in the condensed graph (O(anchors) per verification): loops of one
  /// revisit are merged, then older ones thinned.
  int max_loop_anchors = 64;
  /// chi2: hold a candidate that passes the tests while the relative position's largest
  /// standard deviation exceeds hold_sigma [m] (the prior alone is too weak to trust a single
  /// candidate); 0 = never hold.
  double hold_sigma = 0.0;
};

/// Holding and confirming groups, and revocation (every decision).
struct HoldConfig {
  /// Holding and confirming (both decisions; Verifier::takeDecisions): a held candidate is
  /// released once confirm_count held candidates of the same stretch (queries within
  /// confirm_stretch keyframes, same segments) agree with each other (every pair: the cycle
  /// loop - odometry - loop - odometry closes within chi-square gate_probability) and no rival
  /// group of at least half its size contradicts them; dropped if not confirmed within
  /// confirm_window keyframes after it arrived. confirm_stretch is also the stretch of a rival
  /// (revocation): the accepted loops whose queries lie that close.
  int confirm_count = 3;
  int confirm_window = 40;
  int confirm_stretch = 40;
  /// Revocation (both decisions; 0 = off): a candidate rejected for contradicting the graph
  /// (innovation_above_bound, score_above_threshold, inconsistent_with_drift) that is
  /// inconsistent with an accepted loop of its own stretch (the cycle test above) is held as a
  /// rival instead. Once revoke_group rivals of one stretch agree with each other and outnumber
  /// the accepted loops of the stretch they contradict, those loops leave the graph; if the
  /// rivals then fit it (median squared Mahalanobis distance of the innovations within the
  /// gate) decisively better than the loops (lower by revoke_margin) and at least revoke_group
  /// of them pass the decision, the loops are revoked and the passing rivals released;
  /// otherwise everything is put back and the rivals dropped. Rivals not confirmed within
  /// confirm_window keyframes are dropped.
  int revoke_group = 0;
  /// Revocation: the rivals must fit the graph without the loops they contradict better than
  /// those loops fit it, by this much (difference of median squared Mahalanobis distances).
  double revoke_margin = 4.0;
};

/// Decision revisit: hypotheses of a revisit, their release and competition (docs/method.md).
struct RevisitConfig {
  /// Members a revisit hypothesis needs before it can be released.
  int revisit_support = 3;
  /// A hypothesis not released within this many keyframes after its first member arrived is
  /// dropped (the bound on the delay of a release).
  int revisit_window = 60;
  /// Queries at most this many keyframes apart belong to one revisit: members of one
  /// hypothesis, and rival hypotheses that compete with it.
  int revisit_stretch = 40;
  /// Candidates whose innovation's Mahalanobis distance exceeds this chi-square quantile are
  /// rejected at once (no drift explains them); the rest that the fast path does not accept
  /// are held.
  double revisit_reject_probability = 0.999999;
  /// A hypothesis' median member must lie within this chi-square quantile of the prior (4 dof)
  /// to be released.
  double revisit_gate_probability = 0.999;
  /// A hypothesis whose relative position std exceeds this [m] is not released: the prior is
  /// too weak to tell a revisit from a row of look-alikes (0: no bound).
  double revisit_max_sigma = 0.0;
  /// The hypothesis' trial: its deformation score must be at most
  /// max(threshold, revisit_score_sigmas x the relative position's largest standard deviation).
  double revisit_score_sigmas = 0.65;
  /// That standard deviation in units of the drift the accepted loops have shown: scaled by
  /// sqrt(s), s the drift model's variance scale fitted to their innovations (the robust fit of
  /// calibrate_drift, at least 5 loops; never below 1, the model's), unless a look-alike
  /// (lookalike_distance, lookalike_distance_vertical) explains the hypothesis' median member
  /// nearly as well as the place (lookalike_margin). false: the model's std alone.
  bool revisit_observed_drift = true;
  /// Rival hypotheses of one revisit compete by misfit = median Mahalanobis distance of their
  /// members minus revisit_member_weight per member beyond the first (support counts, in units
  /// of d2); a hypothesis is released only if its misfit is lower than every rival's by
  /// revisit_margin.
  double revisit_member_weight = 1.0;
  double revisit_margin = 4.0;
  /// A candidate the per-candidate test rejects (innovation gate or score) is accepted as an
  /// extension of its revisit if at least this many accepted loops of its stretch (queries and
  /// matches within revisit_stretch keyframes) each close a cycle with it along the VIO odometry
  /// (the cycle test, gate_probability, and a translation residual of at most
  /// revisit_extend_residual), none of them contradicts it, and its trial converges. After a
  /// steady drift X keeps most of the yaw that loop_fusion's weakly weighted loop yaw cannot
  /// correct, and a revisit's later true loops fail the gate against X; the short cycle through
  /// its accepted loops does not see that yaw. 0: off.
  int revisit_extend = 2;
  /// [m] the largest translation residual of such a cycle (the loops' relative poses and the
  /// odometry between their queries and between their matches). The cycle test's covariance
  /// alone let look-alikes through where the odometry's own covariance is loose (pose graphs).
  double revisit_extend_residual = 0.25;
  /// What the re-tests of dropped revisit members (each a trial, bounded by time_budget_ms) may
  /// spend together on one keyframe's arrival [ms] (counted from the arrival, the hypotheses'
  /// judges included): once it is spent, the members still due wait for the next keyframe (at
  /// least one re-test runs per keyframe). Judges and re-tests never run inside verify().
  /// 0, or time_budget_ms 0 (verdicts independent of the machine's load): no bound.
  double revisit_retest_budget_ms = 200.0;
};

/// Decision revisit's global pass (docs/method.md): what the per-candidate test and the revisit
/// hypotheses leave out (single-candidate revisits after long drift) judged against every loop
/// at once.
struct GlobalConfig {
  /// On (decision revisit only; off in every shipped YAML: docs/results.md, "The global pass"):
  /// candidates rejected for contradicting the graph (gate, score, drift) and members of dropped
  /// revisit hypotheses are held in a pool; every global_period keyframes a graduated
  /// non-convexity solve with a truncated quadratic loss over the condensed graph (accepted
  /// loops + the pool) finds the pool's inliers. An inlier is released if the solution does not
  /// tear the odometry of its cycle (global_tear_probability), the other loops predict it
  /// (leave one out: within global_inlier_probability, std <= global_max_sigma), its
  /// innovation against the prior of the accepted loops alone lies within
  /// global_prior_probability, and no rival of its revisit passes without it (global_compete).
  bool global_check = false;
  /// Keyframes between two passes (while candidates are held).
  int global_period = 25;
  /// A pooled candidate not released within this many keyframes is dropped.
  int global_window = 5000;
  /// Candidates pooled at most (the oldest is dropped first): bounds the cost of a pass.
  int global_max_held = 400;
  /// Chi-square quantile (4 dof) of a loop's residual that counts as an inlier, and of its
  /// leave-one-out innovation.
  double global_inlier_probability = 0.99;
  /// A pooled inlier is released only if its innovation against the prior alone (the accepted
  /// loops, not the pool) lies within this chi-square quantile (4 dof).
  double global_prior_probability = 0.95;
  /// Chi-square quantile (4 dof) beyond which a chain of odometry between two anchors counts as
  /// torn by the robust solution: an inlier whose cycle holds a torn chain is not released (a
  /// row of look-alikes that agree with each other bends the odometry instead).
  double global_tear_probability = 0.999;
  /// A pooled inlier is released only if the other loops predict its relative pose this well:
  /// the leave-one-out relative position's largest std [m] (0: no bound).
  double global_max_sigma = 1.0;
  /// Competition: before a release, the pass is solved again without the candidates it would
  /// release; if a candidate of the same revisit (queries within revisit_stretch) that the
  /// first solve rejected now passes every test, the revisit is ambiguous and nothing of it is
  /// released (two incompatible sets of loops explain it: a row of look-alikes beside the true
  /// one). false: release what the first solve finds.
  bool global_compete = true;
  /// A pass that runs longer than this [ms] stops and releases nothing; its pool waits for the
  /// next pass (and a candidate at most global_window keyframes). The pass runs in the
  /// keyframe's arrival (addKeyframe), on loop_fusion's thread: this bounds what it can cost one
  /// keyframe. 0, or time_budget_ms 0 (verdicts independent of the machine's load): no bound.
  double global_budget_ms = 200.0;
};

/// The verifier's parameters, nested by concern. Every field is named by its key (YAML, ROS
/// parameter, rover_replay flag); core/parameters.h is the one source of each key's text.
struct VerifierConfig {
  /// How candidates are decided: kMetric (`metric`, the default: threshold and innovation gate
  /// in metres), kChi2 (`drift`, `chi2`: in units of drift) or kRevisit (the metric test as the
  /// fast path, `revisit` for what it rejects; opt-in: it releases rows of look-alikes). See
  /// Decision.
  Decision decision = Decision::kMetric;
  Mode mode = Mode::kFourDof;
  Alignment alignment = Alignment::kSE3;
  MetricConfig metric;
  TrialConfig trial;
  InputLimits input;
  HostPolicy host;
  DriftConfig drift;
  Chi2Config chi2;
  HoldConfig hold;
  RevisitConfig revisit;
  GlobalConfig global;

  /// Empty when every field lies in its range (the table of core/parameters.h); otherwise
  /// says which fields are wrong and why.
  std::string validate() const;
};

}  // namespace core
}  // namespace rover_loop_fusion
