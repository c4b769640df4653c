// Simulated keyframe trajectories with VIO-like drift and labelled loop candidates.
// ROS-free; used by the gtests, the command-line demo and the cost benchmark.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace sim {

struct SimKeyframe {
  int64_t index = 0;
  double stamp = 0.0;
  core::Pose truth;
  core::Pose vio;  ///< integrated noisy odometry (drifts)
};

struct SimCandidate {
  core::LoopCandidate candidate;
  bool is_true = false;
  /// Ground-truth distance between the query and the match keyframe [m].
  double truth_distance = 0.0;
};

struct Scene {
  std::vector<SimKeyframe> keyframes;
  std::vector<SimCandidate> candidates;  ///< ordered by query index
};

struct LapsOptions {
  int laps = 3;
  double width = 20.0;   ///< rectangle [m]
  double height = 10.0;
  double step = 0.5;     ///< keyframe spacing [m]
  double lap_z_step = 0.0;  ///< climb per lap (a parking deck spiral); 0 = flat
  /// Odometry noise per keyframe step: translation [m] per axis, yaw [rad].
  double sigma_t = 0.01;
  double sigma_yaw = 0.003;
  /// Noise of a true candidate's relative pose (what PnP returns on the right place).
  double candidate_sigma_t = 0.03;
  double candidate_sigma_yaw = 0.005;
  int min_gap = 50;          ///< keyframes between query and match (loop_fusion: 50)
  double revisit_radius = 0.6;  ///< a ground-truth revisit is closer than this [m]
  int true_every = 5;        ///< take every n-th revisit keyframe as a true candidate (<= 0: none)
  double false_offset = 3.0; ///< false candidates: look-alike place this far away [m]
  int false_every = 5;       ///< one false candidate every n-th revisit keyframe (<= 0: none)
  uint32_t seed = 7;
};

/// Laps of a rectangle (corridor loop / warehouse block / parking deck with lap_z_step).
Scene makeLapsScene(const LapsOptions& options);

/// Deterministic normal samples (Box-Muller on mt19937), identical on every platform.
class Gaussian {
 public:
  explicit Gaussian(uint32_t seed) : rng_(seed) {}
  double operator()(double sigma);
  double uniform();  ///< [0, 1)
 private:
  std::mt19937 rng_;
};

/// Relative pose of b in a's frame.
core::Pose relative(const core::Pose& a, const core::Pose& b);
core::Pose compose(const core::Pose& a, const core::Pose& b);

/// ATE RMSE of positions after SE(3) (or Sim(3)) alignment.
double ate(const std::vector<core::Pose>& estimate, const std::vector<core::Pose>& truth,
           bool with_scale = false);

/// The loop candidate "query seen from match at relative pose rel" (rel: query in match's
/// frame), as loop_fusion would report it.
core::LoopCandidate loopCandidate(const SimKeyframe& query, const SimKeyframe& match, const core::Pose& rel,
                                  int inliers = -1);

/// num / den with three decimals, or "-" when den is 0 (precision of no accepted loop, recall
/// without a true loop: no decision to take it from, never 1.0).
std::string ratioText(int num, int den);

}  // namespace sim
}  // namespace rover_loop_fusion
