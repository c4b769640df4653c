// The ROVER loop verifier: ROS-free, one instance per loop_fusion process.
//
// It keeps its own pose graph (keyframe VIO poses, odometry edges to the previous
// `odometry_neighbours` keyframes of the same sequence, accepted loop edges) and its own
// current estimate X of every keyframe. For a candidate it solves the graph plus the
// candidate, warm-started from X, over the window [match - window_margin, newest keyframe]
// (everything older held fixed, as loop_fusion holds the keyframes before its earliest loop)
// and scores the deformation: s = RMSE of the positions of X and X* after Umeyama alignment.
// verify() never changes the graph; commit() adds the loop and keeps the X* of the verify()
// that accepted it (no second solve).
//
// Every public method is safe to call from any thread (one internal mutex), never throws for
// bad input and never leaves the graph half-changed: bad input comes back as a Status or as a
// Verdict with reason kInvalidInput.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <memory>
#include <mutex>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// One keyframe of the verifier's trajectory, as reported by trajectory().
struct TrajectoryPoint {
  int64_t index = -1;
  double stamp = 0.0;
  int sequence = 0;
  Pose vio;       ///< as handed to addKeyframe (after any sequence anchoring shift)
  Pose estimate;  ///< the verifier's current estimate X (VIO + accepted loops)
};

/// Result of solveLikeLoopFusion(): the trajectory loop_fusion's own optimisation would give.
struct BatchSolveResult {
  bool ok = false;
  std::string message;
  int iterations = 0;
  double solve_ms = 0.0;
  int free_keyframes = 0;
  std::vector<Pose> poses;  ///< one per keyframe, in trajectory() order
};

class Verifier {
 public:
  /// An invalid config is replaced by the defaults; configError() says why.
  explicit Verifier(const VerifierConfig& config = VerifierConfig());
  ~Verifier();
  Verifier(const Verifier&) = delete;
  Verifier& operator=(const Verifier&) = delete;

  const VerifierConfig& config() const { return config_; }
  const std::string& configError() const { return config_error_; }

  /// Registers a keyframe. Indices must be strictly increasing (loop_fusion's global index),
  /// stamps strictly increasing within a sequence, sequences non-decreasing; the pose must be
  /// finite with a unit quaternion. Refused input leaves the graph unchanged.
  Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                     const Eigen::Quaterniond& q);

  /// Scores a candidate against the trajectory prior. Does not change the graph.
  Verdict verify(const LoopCandidate& candidate);

  /// Adds a loop edge that the host is going to use and updates X. If the last verify()
  /// accepted this very candidate, its X* is kept (no second solve); otherwise (stored loops
  /// of a loaded map, loops accepted without a prior, an override) the graph is solved once.
  /// A first loop between two sequences anchors the query's sequence to the match's frame
  /// exactly as loop_fusion shifts it (w_r_vio / w_t_vio).
  /// update_estimate=false only adds the edge (no solve; X unchanged): for replaying a saved
  /// map or building an accept-all baseline that is solved once at the end.
  Status commit(const LoopCandidate& candidate, bool update_estimate = true);

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
  struct Impl;
  VerifierConfig config_;
  std::string config_error_;
  mutable std::mutex mutex_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace core
}  // namespace rover_loop_fusion
