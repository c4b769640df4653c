// INTERNAL: not part of the core's API (include core/pose_graph.h). The state behind
// KeyframeGraph (KeyframeGraph::Impl) and the helpers its implementation files share:
//   core/pose_graph.cpp        the graph: keyframe lookup, poses and states, edges, loops, X
//   core/keyframe_intake.cpp   addKeyframe: plausibility, jump recovery, segments (union-find)
//   core/trial_solve.cpp       Ceres trials over a window (trial_budget.h: deadline, cost model)
//   core/condensed_trial.cpp   the condensed graph (core/condensed.h) of a component, and trials on it
//   core/graph_uncertainty.cpp drift moments and covariances (core/drift.h), the chi2 estimate
//   core/batch_solve.cpp       loop_fusion's own batch solve
#pragma once

#include "rover_loop_fusion/core/pose_graph.h"

#include "rover_loop_fusion/core/ceres_compat.h"
#include "rover_loop_fusion/core/condensed.h"
#include "rover_loop_fusion/core/condensed6.h"
#include "rover_loop_fusion/core/cost_functions.h"
#include "rover_loop_fusion/core/drift.h"
#include "rover_loop_fusion/core/place_graph.h"
#include "rover_loop_fusion/core/trial_budget.h"

#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// A loop of a trial that is not (yet) in the graph: its ends and the candidate (nullptr: no
/// edge; a trial without a candidate still keeps its ends as anchors).
struct TrialLoop {
  size_t match_pos = 0, query_pos = 0;
  const LoopCandidate* candidate = nullptr;
};

/// buildTrial's component for "every segment" (segment numbers are >= 0 or small negatives).
constexpr int kEverySegment = std::numeric_limits<int>::min();

inline bool unitQuaternion(const Eigen::Quaterniond& q, double tol) {
  return q.coeffs().allFinite() && std::abs(q.norm() - 1.0) <= tol;
}

inline std::string describeIndex(int64_t i) { return std::to_string(static_cast<long long>(i)); }

/// A rigid correction: 4-DoF keeps it to yaw + translation.
struct Correction {
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double yaw = 0;
};

struct KeyframeGraph::Impl {
  struct Keyframe {
    int64_t index;
    double stamp;
    int sequence;
    /// Connectivity: odometry joins keyframes of one segment; loops join segments (union-find).
    /// A sequence's first segment has the sequence's number; a keyframe jump accepted as a
    /// relocation starts a new segment with a negative number.
    int segment;
    Pose vio;
    double yaw, pitch, roll;  // of vio, radians
  };
  /// The last refused implausible keyframe and how many consecutive refused keyframes, each
  /// plausible after the one before, end with it (0: none).
  struct Suspect {
    int run = 0;
    Keyframe keyframe;
  };
  /// A loop edge (an accepted loop, or a trial's candidate) between two keyframes.
  /// `information` weights its residual (core/cost_functions.h; 4-DoF: the top-left 4 x 4
  /// block, residual order x, y, z, yaw; 6-DoF: all of it); null is unit information,
  /// loop_fusion's weighting (today every edge's).
  struct Edge {
    size_t from, to;  // positions; from is the older keyframe
    std::shared_ptr<const Matrix6d> information;
    std::shared_ptr<ceres::CostFunction> cost;
    LoopCandidate loop;
  };
  /// An odometry edge as measured when its newer keyframe arrived, without a Ceres cost (a
  /// trial builds the costs of the edges in its window, trial_solve.cpp): 72 bytes where an
  /// Edge with its cost took ~420 per edge, four edges per keyframe. `t`: the newer
  /// keyframe's position in the older one's frame; `r`: 4-DoF the yaw change and the older
  /// keyframe's pitch and roll, 6-DoF the relative rotation's coefficients (x, y, z, w).
  struct OdometryEdge {
    size_t from, to;
    double t[3];
    double r[4];
  };
  /// A trial problem over the window [first, newest] of one component.
  struct Trial {
    explicit Trial() : problem(compat::problemOptionsNotOwning()) {}
    /// The costs of the window's odometry edges (the problem does not own its costs).
    std::vector<std::shared_ptr<ceres::CostFunction>> costs;
    ceres::Problem problem;
    size_t first = 0;
    std::vector<size_t> positions;   // window keyframes, increasing
    std::vector<int> local;          // position - first -> index into positions, or -1
    std::vector<KeyframeState> states;  // same order as positions
    std::deque<KeyframeState> constants;  // loop endpoints outside the window (stable addresses)
  };

  const VerifierConfig& cfg;
  std::vector<Keyframe> kfs;
  std::vector<double> arc;  // VIO distance travelled since the start of the keyframe's segment
  std::vector<KeyframeState> x;
  std::vector<OdometryEdge> odometry;  // appended in increasing `to`
  std::vector<Edge> loops;
  /// The loops by endpoint: at each position that ends a loop, the other end of each (and
  /// whether this end is the loop's `from`), in the order the loops were added. Kept with
  /// `loops` (addLoop, removeLoop) so that pathLength and the duplicate check need not scan or
  /// rebuild anything per candidate.
  struct LoopEnd {
    size_t other;
    bool is_from;
  };
  std::map<size_t, std::vector<LoopEnd>> loop_ends;
  /// The loop ends as places (core/place_graph.h), for pathLength: built from `loop_ends` by
  /// keepPathLengths, the first pathLength or the first after a removal (`places_stale`), kept
  /// up to date as loops are added in between (a graph that never asks, the node's
  /// loop_fusion stand-in, never builds it).
  mutable PlaceGraph places;
  mutable bool places_stale = true;
  std::map<int, int> seg_parent;     // union-find over segments
  std::map<int, bool> seq_anchored;  // loop_fusion's sequence_loop
  std::map<int, Correction> seq_shift;  // applied to incoming poses if anchor_incoming_keyframes
  std::unique_ptr<ceres::LossFunction> huber;
  std::unique_ptr<compat::ParameterManifold> angle_manifold;
  std::unique_ptr<compat::ParameterManifold> quaternion_manifold;
  uint64_t revision = 0;
  size_t solves = 0;
  // Uncertainty (decision chi2, the revisit rule's tests, condensed trials): per segment (its
  // keyframes are contiguous positions from `start`: odometry joins only keyframes of one
  // segment) the prefix moments of the drift model along its VIO poses, kept from the start if
  // the verifier's configuration will need them (keepMoments), else built when first needed
  // (momentsOf, unitOf): a graph that never needs them (the node's loop_fusion stand-in, the
  // metric rule without a long trial) does not pay for them (~140 bytes per keyframe, both kinds:
  // the moments hold checkpoints; the steps they sum are the keyframes' VIO poses, SegmentSteps).
  struct SequenceChain {
    size_t start = 0;
    size_t count = 0;  // keyframes of the segment so far
    ChainMoments moments;  // its first moments.size() keyframes
    /// The same with loop_fusion's unit weighting (condensed trials; 4-DoF only).
    ChainMoments unit;
  };
  /// A segment's keyframes as the steps of its moments: VIO positions and rotations, and the
  /// drift model's step covariance (or the one handed in with the keyframe), or loop_fusion's
  /// unit weighting.
  class SegmentSteps : public ChainSteps {
   public:
    SegmentSteps(const Impl& m, size_t start, bool unit) : m_(m), start_(start), unit_(unit) {
      if (unit) unit_cov_ = m.unitStepCovariance();
    }
    Eigen::Vector3d position(size_t j) const override { return m_.kfs[start_ + j].vio.t; }
    Eigen::Matrix3d rotation(size_t j) const override { return m_.kfs[start_ + j].vio.q.toRotationMatrix(); }
    Eigen::Matrix4d stepCovariance(size_t j) const override;

   private:
    const Impl& m_;
    size_t start_;
    bool unit_;
    Eigen::Matrix4d unit_cov_ = Eigen::Matrix4d::Zero();
  };
  /// A chain's moments with the steps they sum (ChainMoments' queries need both).
  struct ChainMomentsView {
    const ChainMoments& moments;
    SegmentSteps steps;
    Eigen::Matrix4d cross(size_t a, size_t k, size_t b) const { return moments.cross(steps, a, k, b); }
    ChainMoments::Sums prefix(size_t a) const { return moments.prefix(steps, a); }
    Eigen::Matrix4d cross(const ChainMoments::Sums& prefix_a, size_t a, size_t k, size_t b) const {
      return moments.cross(steps, prefix_a, a, k, b);
    }
    Eigen::Matrix4d relative(size_t a, size_t b, const Eigen::Matrix3d& Ra) const {
      return moments.relative(steps, a, b, Ra);
    }
  };
  /// mutable: the moments are filled in on first use by const readers (one thread at a time,
  /// as the whole graph).
  mutable std::map<int, SequenceChain> chains;
  /// Once a kind of moments has been needed, addKeyframe keeps it up to date (extendChain), so
  /// that only the first use pays for the keyframes before it.
  mutable bool moments_used = false, unit_used = false;
  /// Step covariances handed in with keyframes (addKeyframe), by position; the drift model's
  /// for the others.
  std::unordered_map<size_t, Eigen::Matrix4d, std::hash<size_t>, std::equal_to<size_t>,
                     Eigen::aligned_allocator<std::pair<const size_t, Eigen::Matrix4d>>>
      step_covariance;
  DriftModel drift;
  Suspect suspect;
  int next_segment = -1;
  bool warned_loaded_map_stamps = false;
  /// The previous keyframe of a live sequence carried the same stamp: the clock stopped (said
  /// once per stretch).
  bool clock_stopped = false;
  /// Keyframes (by position) that a run of jump_confirmations keyframes contradicted while they
  /// were their sequence's only keyframe: a bad first pose, kept apart (its own segment) and
  /// refused in loops (checkLoop), with why.
  std::map<size_t, std::string> discredited;
  /// What a budgeted trial costs on this machine per window keyframe, learned from the
  /// budgeted solves of >= 500 keyframes so far (below, fixed costs dominate): setup (build,
  /// Ceres' preprocessing and initial evaluation, teardown) and the longest iteration. Before
  /// the first such solve, a cautious guess (1k-20k-keyframe 4-DoF windows on a loaded 2-core
  /// VM: ~10 + ~30 us per keyframe; 3x for 6-DoF).
  CostRate setup_cost{0.010};
  CostRate iteration_cost{0.030};

  explicit Impl(const VerifierConfig& c)
      : cfg(c), huber(new ceres::HuberLoss(c.trial.loop_huber)),
        angle_manifold(new compat::AngleManifold()),
        quaternion_manifold(compat::newQuaternionManifold()) {
    drift.sigma_xy = c.drift.drift_xy;
    drift.sigma_z = c.drift.drift_z;
    drift.sigma_yaw = c.drift.drift_yaw;
    drift.min_step = c.drift.drift_min_step;
    if (!fourDof()) {  // autodiff 6-DoF residuals: 2-7x the 4-DoF cost (docs/results.md)
      setup_cost.mean *= 3;
      iteration_cost.mean *= 3;
    }
  }

  bool fourDof() const { return cfg.mode == Mode::kFourDof; }

  // ---- the graph (pose_graph.cpp): lookup, poses and states, edges, loops ------------------
  bool find(int64_t index, size_t* pos) const;
  KeyframeState stateFromPose(const Pose& p) const;
  Pose poseFromState(const KeyframeState& s, const Keyframe& kf) const;
  Eigen::Matrix3d rotationOf(const KeyframeState& s, const Keyframe& kf) const;
  /// The correction that maps `before` onto `after` (4-DoF: yaw + translation only, like
  /// loop_fusion's r_drift / t_drift).
  Correction correctionBetween(const KeyframeState& before, const KeyframeState& after,
                               const Keyframe& kf) const;
  KeyframeState applyCorrection(const Correction& c, const KeyframeState& s, const Keyframe& kf) const;
  Pose applyCorrection(const Correction& c, const Pose& p) const;
  void setYawPitchRoll(Keyframe& kf) const;
  /// s.yaw := yaw; 6-DoF: q turned about the world z axis by the change (roll and pitch kept).
  /// A 6-DoF state's yaw is always that of its q (the chi2 decision works on x, y, z, yaw).
  void setYaw(KeyframeState& s, double yaw) const;

  /// The Ceres cost of an edge with the given measurement, weighted by its information.
  std::shared_ptr<ceres::CostFunction> edgeCost(const Eigen::Vector3d& t_ij, double yaw_ij,
                                                const Eigen::Quaterniond& q_ij, const Keyframe& from,
                                                double yaw_weight, const Matrix6d* information) const;
  OdometryEdge odometryEdge(size_t from, size_t to) const;
  std::shared_ptr<ceres::CostFunction> odometryCost(const OdometryEdge& e) const;
  void setLoopCost(Edge& e) const;

  std::string checkLoop(const LoopCandidate& c, size_t* qpos, size_t* mpos) const;
  double innovation(const LoopCandidate& c, size_t qpos, size_t mpos) const;
  /// The shortest odometry path between two keyframes, every loop a shortcut of length 0: the
  /// stretch between them if they share a segment, or a walk over `places` from the loop ends
  /// next to `from` to those next to `to` (arc-length differences within a segment).
  double pathLength(size_t from, size_t to) const;
  /// The nearest loop end before (after) `pos` on its segment; false if there is none.
  bool loopEndBefore(size_t pos, size_t* end) const;
  bool loopEndAfter(size_t pos, size_t* end) const;
  /// A new loop end `pos` (not yet in `loop_ends`): its stretches to the loop ends beside it.
  void addPlaceStretches(size_t pos) const;
  void rebuildPlaces() const;
  void indexLoop(size_t from, size_t to);
  void unindexLoop(size_t from, size_t to);
  /// loop_fusion's first-loop-between-sequences shift of the query's sequence.
  void anchorSequence(const LoopCandidate& c, size_t qpos, size_t mpos);

  // ---- keyframe intake and segments (keyframe_intake.cpp) ----------------------------------
  /// Why keyframe b cannot follow keyframe a of its sequence (too far, stamp not after a's or
  /// too long after it); empty if it can.
  std::string implausibleStep(const Keyframe& a, const Keyframe& b) const;
  /// The stamp faults of live keyframe kf after prev told apart from a jump: a repeated message
  /// (an error in *status, true returned: refuse), a clock that stopped, keyframes stamped late
  /// (kept, a warning in *status). Clears *implausible when one of them explains it.
  bool stampFaults(const Keyframe& kf, const Keyframe& prev, const std::string& who, std::string* implausible,
                   Status* status);
  /// kf stamped before prev but plausibly after an earlier keyframe, the ones between stamped
  /// late: a warning, *implausible cleared, *stopped when that keyframe carries kf's stamp.
  void lateStamps(const Keyframe& kf, const Keyframe& prev, const std::string& who, std::string* implausible,
                  Status* status, bool* stopped);
  /// An implausible step from prev to kf: refused (an error, true returned) until
  /// jump_confirmations consecutive keyframes agree, then accepted as a relocation (kf starts a
  /// new segment), a new clock, or the discrediting of the sequence's first keyframes (a warning).
  bool confirmJump(Keyframe& kf, const Keyframe& prev, const std::string& who, const std::string& implausible,
                   Status* status);
  /// Appends kf (checked) after prev (nullptr: the first of its sequence): its estimate, arc
  /// length, step covariance (a bad one ignored, said in *status), chain and odometry edges.
  void appendKeyframe(const Keyframe& kf, const Keyframe* prev, const Eigen::Matrix4d* given_covariance,
                      const std::string& who, Status* status);
  int root(int segment);
  /// The segment root of the keyframe at `pos` (root() without path compression).
  int componentOf(size_t pos) const;

  // ---- global pass (global_pass.cpp) --------------------------------------------------------
  /// The condensed graph of `component` for the global pass: its chains and accepted loops, the
  /// gauge held, and an edge per candidate loop (matches[k] -> queries[k], kfs positions;
  /// (*edge)[k] its edge, or SIZE_MAX if it could not be added); *chains: the odometry chains
  /// (the first edges). false if it cannot be condensed.
  bool globalGraph(int component, const std::vector<size_t>& matches, const std::vector<size_t>& queries,
                   const std::vector<const LoopCandidate*>& loops, double variance_scale, CondensedGraph* cg,
                   std::vector<size_t>* anchors, std::vector<size_t>* edge, size_t* chains) const;

  // ---- trials (trial_solve.cpp; the deadline and cost model: trial_budget.h) ---------------
  void addBlocks(Trial& tr, KeyframeState& s, bool constant);
  double* rotBlock(KeyframeState& s) const { return fourDof() ? &s.yaw : s.q; }
  /// State of position p inside the trial, or a constant block holding x[p] if p is outside.
  KeyframeState* stateFor(Trial& tr, size_t p);
  void addEdge(Trial& tr, size_t from, size_t to, ceres::CostFunction* cost, ceres::LossFunction* loss);
  /// Builds the problem over keyframes [first, newest] whose segment is in `component`
  /// (kEverySegment: all; segment roots can be negative). from_vio: initial values from the VIO poses (loop_fusion) instead
  /// of X. The first window keyframe and sequence-0 keyframes are held fixed.
  void buildTrial(Trial& tr, size_t first, int component, bool from_vio, const std::vector<Edge>& extra,
                  ceres::LossFunction* extra_loss);
  /// Solves `tr` within the time left until start + time_budget_ms (<= 0: no limit): the
  /// callback stops it before an iteration that would end past that; the state keeps the
  /// last iterate. `callback` (optional) receives the iteration times.
  SolveSummary solve(Trial& tr, int max_iterations, double time_budget_ms, Clock::time_point start,
                     DeadlineCallback* callback = nullptr);
  /// Learns setup_cost / iteration_cost from a budgeted trial.
  void learnCost(size_t window, double total_ms, const DeadlineCallback& callback);
  size_t windowStart(size_t match_pos) const;
  void adopt(const std::vector<size_t>& positions, const std::vector<KeyframeState>& states);

  // ---- the condensed graph and condensed trials (condensed_trial.cpp; core/condensed.h) ----
  /// The accepted loops of a component as condensed-graph edges: loops of one revisit within
  /// kMergeKeyframes (query and match) merged into one edge with the information of all;
  /// beyond the cap, the newest half kept and the older thinned evenly.
  struct LoopRep {
    size_t from, to;
    const LoopCandidate* loop;
    int count;
  };
  /// `cap` loops at most (max_loop_anchors or trial_loop_anchors); loops ending before `first`
  /// left out first.
  std::vector<LoopRep> loopReps(int component, size_t first, int cap) const;
  std::vector<LoopRep> computeLoopReps(int component, size_t first, int cap) const;
  /// loopReps() of the last revision asked (they change only when the loops do).
  mutable uint64_t reps_revision = ~uint64_t(0);
  mutable std::map<std::tuple<int, size_t, int>, std::vector<LoopRep>> reps_cache;
  /// The condensed graph of a component on the loop ends plus `extra` positions, states from
  /// X; sequence 0 held fixed. Fills `anchors` (positions, increasing). False if an edge's
  /// covariance was unusable.
  struct CondenseOptions {
    double variance_scale = 1.0;  ///< drift model variances times this
    /// A condensed trial over the window [first, newest] (`first` in the component): loop_fusion's
    /// weighting (unit moments, loop edges with the loop yaw weight and the Huber loss) instead
    /// of the drift model's; anchors up to `first` held fixed, only loops that end after it.
    bool trial = false;
    size_t first = 0;
  };
  bool condense(int component, const std::vector<size_t>& extra, const CondenseOptions& options,
                CondensedGraph* cg, std::vector<size_t>* anchors) const;
  /// condense()'s chain edges, by their two positions, the weighting (unit: the trials') and
  /// the variance scale: the measurement, covariance and square-root information of a chain
  /// of odometry depend only on the VIO poses along it, which change only when a sequence is
  /// anchored (rebuildMoments() clears this). Most chains of a condensed graph are those of
  /// the one before (the same loop ends), so a trial builds only the few a new anchor splits.
  struct ChainEdge {
    Eigen::Vector3d t;
    double yaw;
    Eigen::Matrix4d covariance, sqrt_info;
  };
  using ChainEdgeKey = std::tuple<size_t, size_t, bool, double>;
  mutable std::map<ChainEdgeKey, ChainEdge, std::less<ChainEdgeKey>,
                   Eigen::aligned_allocator<std::pair<const ChainEdgeKey, ChainEdge>>>
      chain_edges;
  /// The anchors of a condensed graph (positions, increasing: `extra` and the ends of the loops
  /// returned, loopReps()).
  std::vector<LoopRep> condensedAnchors(int component, const std::vector<size_t>& extra,
                                        const CondenseOptions& options, std::vector<size_t>* anchors) const;
  /// 6-DoF (condensed_trial6.cpp): condense() of a trial (options.trial) with full poses, the
  /// chains' covariances from the 6-DoF chain model, loop edges with loop_fusion's 6-DoF sigmas.
  bool condense6(int component, const std::vector<size_t>& extra, const CondenseOptions& options,
                 CondensedGraph6* cg, std::vector<size_t>* anchors) const;
  Matrix6d unitLoopCovariance6() const;
  /// A chain step's translation and rotation variances (unitStepCovariance's stiffness).
  void unitStepVariances6(double* st, double* sq) const;
  /// `s` with position p and rotation q (its yaw that of q).
  KeyframeState stateWithPose(KeyframeState s, const Eigen::Vector3d& p, const Eigen::Quaterniond& q) const;
  /// Places keyframes between two anchors of a condensed solution by the chain model's
  /// conditional mean (expand()); it keeps what it computed per chain for the next keyframes.
  class ChainPlacer {
   public:
    virtual ~ChainPlacer() = default;
    /// The new state of position p between the solution's anchors i and i + 1 (one segment);
    /// `position_only`: its rotation left as in X (scoring needs the positions alone).
    virtual KeyframeState place(size_t i, size_t p, bool position_only) = 0;
  };
  /// 4-DoF (condensed_trial.cpp) and 6-DoF (condensed_trial6.cpp); the 6-DoF one wants its
  /// positions p increasing within a chain, as expand() hands them.
  class FourDofPlacer;
  class SixDofPlacer;
  std::unique_ptr<ChainPlacer> chainPlacer4(const TrialSolution& s) const;
  std::unique_ptr<ChainPlacer> chainPlacer6(const TrialSolution& s) const;
  /// loop_fusion's unit weighting as covariances: of a loop edge, and of one odometry step of a
  /// chain with odometry_neighbours edges per keyframe (a uniform strain e stretches the edge to
  /// the k-th neighbour by k e: stiffness sum k^2 per step). Yaw residuals are in degrees.
  Eigen::Matrix4d unitLoopCovariance() const;
  Eigen::Matrix4d unitStepCovariance() const;
  /// The stiffness of one chain step under edges to odometry_neighbours neighbours: sum k^2.
  double stepStiffness() const;
  /// Whether trials can be condensed (with odometry; 4-DoF keeps the unit moments then, 6-DoF
  /// sums its chains when a trial needs them).
  bool condensable() const { return cfg.trial.odometry_neighbours >= 1; }
  /// The condensed trial (solveWindow) with the `candidates` (their loops as extra edges; a
  /// TrialLoop without a candidate only makes its ends anchors); false if it could not be built
  /// or solved.
  bool solveCondensed(size_t first, int component, const std::vector<TrialLoop>& candidates, bool robust_candidate,
                      int max_iterations, TrialSolution* out) const;
  /// The trial behind both solveWindow()s.
  TrialSolution solveTrial(const std::vector<TrialLoop>& candidates, bool robust_candidate, int max_iterations,
                           double time_budget_ms, int condense_min_window);
  /// New states of `targets` (window positions of the component, increasing) under a condensed
  /// solution: between two anchors of a segment the chain's conditional mean (as the linear
  /// solve places them), before the first and after the last anchor rigidly with it.
  /// `position_only` (scoring): between anchors, the rotations are left as in X.
  std::vector<KeyframeState> expand(const TrialSolution& s, const std::vector<size_t>& targets,
                                    bool position_only = false) const;
  /// The window of a condensed solution: [begin, end) positions, one range per segment of its
  /// component (skip_fixed_map: not sequence 0's).
  std::vector<std::pair<size_t, size_t>> windowRanges(const TrialSolution& s, bool skip_fixed_map) const;
  /// Every `stride`-th keyframe of windowRanges(), increasing.
  std::vector<size_t> windowPositions(const TrialSolution& s, size_t stride, bool skip_fixed_map) const;
  /// Carries new anchor states to every keyframe of the component: chains between anchors by
  /// the chain model's conditional mean, the ends rigidly with their anchor.
  void spread(int component, const std::vector<size_t>& anchors, const CondensedGraph& cg);

  // ---- uncertainty (graph_uncertainty.cpp; core/drift.h) -----------------------------------
  /// Counts keyframe `pos` into its segment's chain (the moments follow when needed).
  void extendChain(size_t pos);
  /// The chain's drift-model (unit-weight) moments over all its keyframes (extended now over
  /// the keyframes that arrived since they were last needed), with the steps they sum.
  ChainMomentsView momentsOf(SequenceChain& ch) const;
  ChainMomentsView unitOf(SequenceChain& ch) const;
  /// After loop_fusion's shift of a sequence: its segments' moments dropped, to be built again
  /// from the new poses when needed.
  void rebuildMoments(int sequence);
  Eigen::Matrix4d loopCovariance() const;
};

}  // namespace core
}  // namespace rover_loop_fusion
