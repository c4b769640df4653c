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
// Every public method is safe to call from any thread (one internal mutex), never throws for
// bad input and never leaves the graph half-changed: bad input comes back as a Status or as a
// Verdict with reason kInvalidInput.
#pragma once

#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/types.h"

#include <mutex>
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

  /// Registers a keyframe (PoseGraph::addKeyframe: the rules, the plausibility limits and the
  /// recovery from a jump). Refused input leaves the graph unchanged; ok with a message is a
  /// warning for the host's log.
  Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                     const Eigen::Quaterniond& q);

  /// Scores a candidate against the trajectory prior. Does not change the graph.
  Verdict verify(const LoopCandidate& candidate);

  /// Adds a loop edge that the host is going to use and updates X. If the last verify()
  /// accepted this very candidate, its X* is kept (no second solve); otherwise (stored loops
  /// of a loaded map, loops accepted without a prior, an override) the graph is solved once.
  /// A first loop between two sequences anchors the query's sequence to the match's frame
  /// exactly as loop_fusion shifts it (w_r_vio / w_t_vio). (A graph that only collects loops,
  /// solved once at the end: PoseGraph::addLoop.)
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

 private:
  /// The X* of the last verify() that accepted, for commit() to keep.
  struct Pending {
    bool valid = false;
    LoopCandidate candidate;
    uint64_t revision = 0;  ///< the graph's revision it was solved on
    TrialSolution solution;
  };
  std::string config_error_;  // before config_: the constructor validates first
  VerifierConfig config_;
  mutable std::mutex mutex_;
  PoseGraph graph_;
  Pending pending_;
};

}  // namespace core
}  // namespace rover_loop_fusion
