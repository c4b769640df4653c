// The condensed trial (condense_min_window): on a scene with long spans (laps; a
// revisit's match can lie several laps back), a verifier whose trials run on the condensed graph
// decides every candidate as the full-window (Ceres) trial does, with nearly the same score.
// Both verifiers see the same keyframes and commit the same loops (the true ones they accept,
// as rover_replay's oracle protocol), so every candidate is judged against the same graph.
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

using namespace rover_loop_fusion;

namespace {

constexpr int64_t kLap = 120;  // keyframes a lap (20 x 10 m at 0.5 m)

sim::Scene longLaps() {
  sim::LapsOptions o;
  o.laps = 8;  // spans up to ~950 keyframes
  o.sigma_t = 0.01;
  o.sigma_yaw = 0.003;
  o.true_every = 6;
  o.false_every = 6;
  o.false_offset = 1.5;
  o.seed = 11;
  sim::Scene s = sim::makeLapsScene(o);
  // loop_fusion matches the oldest look-alike: every candidate's match moves to the same place
  // on the first lap (flat laps: the same true pose, so its relative pose stays what it was).
  for (sim::SimCandidate& sc : s.candidates) {
    core::LoopCandidate& c = sc.candidate;
    const sim::SimKeyframe& first_lap = s.keyframes[c.match_index % kLap];
    c.match_index = first_lap.index;
  }
  return s;
}

/// The laps with a 3-D drift for the 6-DoF trial: the VIO integrated again from the true steps
/// with a random tilt (roll and pitch) on each, so that the odometry's rotation drifts off the
/// vertical and lifts the laps apart as they go; the candidates keep their (true) relative poses.
sim::Scene tiltedLaps(double sigma_tilt) {
  sim::Scene s = longLaps();
  std::vector<core::Pose> steps;  // the scene's (planar) odometry steps, drift included
  for (size_t k = 1; k < s.keyframes.size(); ++k)
    steps.push_back(sim::relative(s.keyframes[k - 1].vio, s.keyframes[k].vio));
  sim::Gaussian noise(23);
  for (size_t k = 1; k < s.keyframes.size(); ++k) {
    core::Pose step = steps[k - 1];
    step.q = step.q * Eigen::Quaterniond(Eigen::AngleAxisd(noise(sigma_tilt), Eigen::Vector3d::UnitX())) *
             Eigen::Quaterniond(Eigen::AngleAxisd(noise(sigma_tilt), Eigen::Vector3d::UnitY()));
    s.keyframes[k].vio = sim::compose(s.keyframes[k - 1].vio, step);
  }
  return s;
}

core::VerifierConfig config(int condense_min_window, int trial_loop_anchors = 256,
                            core::Mode mode = core::Mode::kFourDof) {
  core::VerifierConfig cfg;
  cfg.mode = mode;
  cfg.trial.time_budget_ms = 0;  // nothing depends on the machine's load
  cfg.trial.condense_min_window = condense_min_window;
  cfg.trial.trial_loop_anchors = trial_loop_anchors;
  return cfg;
}

struct Comparison {
  int candidates = 0, solved = 0, agree = 0, near_threshold_disagreements = 0, long_spans = 0;
  std::vector<double> score_differences;  // |condensed - full| where both scored
  size_t full_solves = 0, condensed_solves = 0;
};

Comparison compare(const sim::Scene& scene, const core::VerifierConfig& condensed_config) {
  core::VerifierConfig full_config = condensed_config;
  full_config.trial.condense_min_window = 0;
  core::Verifier full(full_config), condensed(condensed_config);
  Comparison out;
  size_t next = 0;
  for (const sim::SimKeyframe& kf : scene.keyframes) {
    EXPECT_TRUE(full.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    EXPECT_TRUE(condensed.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    for (; next < scene.candidates.size() && scene.candidates[next].candidate.query_index == kf.index; ++next) {
      const sim::SimCandidate& sc = scene.candidates[next];
      const core::Verdict a = full.verify(sc.candidate);
      const core::Verdict b = condensed.verify(sc.candidate);
      ++out.candidates;
      if (sc.candidate.query_index - sc.candidate.match_index > 4 * kLap) ++out.long_spans;
      if (a.accepted == b.accepted) {
        ++out.agree;
      } else if (std::abs(a.score - a.threshold) < 0.01) {
        ++out.near_threshold_disagreements;
      } else {
        ADD_FAILURE() << "decisions differ for " << sc.candidate.query_index << "->" << sc.candidate.match_index
                      << " (true: " << sc.is_true << "): full " << a.detail << "; condensed " << b.detail;
      }
      if (std::isfinite(a.score) && std::isfinite(b.score)) {
        ++out.solved;
        out.score_differences.push_back(std::abs(a.score - b.score));
      }
      if (sc.is_true && a.accepted) {  // the same loops in both graphs
        EXPECT_TRUE(full.commit(sc.candidate).ok);
        EXPECT_TRUE(condensed.commit(sc.candidate).ok);
      }
    }
  }
  out.full_solves = full.solveCount();
  out.condensed_solves = condensed.solveCount();
  std::sort(out.score_differences.begin(), out.score_differences.end());
  return out;
}

double quantile(const std::vector<double>& sorted, double q) {
  return sorted.empty() ? 0.0 : sorted[std::min(sorted.size() - 1, static_cast<size_t>(q * sorted.size()))];
}

/// What both modes' tests ask of the condensed trial against the full window on the laps.
void expectLikeTheFullWindow(const Comparison& c, const char* what) {
  ASSERT_GE(c.candidates, 100);
  ASSERT_GE(c.long_spans, 30) << "the scene must hold long spans";
  ASSERT_GE(c.solved, 60);
  // Every trial of the condensed verifier over more than 100 keyframes, its commits included,
  // ran without Ceres; the full one solved each.
  EXPECT_GT(c.full_solves, 60u);
  EXPECT_LT(c.condensed_solves, c.full_solves / 4);
  // At most one decision differs, and only for a score within 1 cm of the threshold.
  EXPECT_GE(c.agree, c.candidates - 1);
  EXPECT_LE(c.near_threshold_disagreements, 1);
  const double median = quantile(c.score_differences, 0.5), worst = c.score_differences.back();
  EXPECT_LT(median, 0.005) << "median |score difference| [m]";
  EXPECT_LT(worst, 0.03) << "largest |score difference| [m]";
  std::printf("%s condensed vs full: %d candidates (%d spans > 480 keyframes), %d agree, %d scored; "
              "|score difference| median %.4f m, max %.4f m; Ceres solves %zu vs %zu\n",
              what, c.candidates, c.long_spans, c.agree, c.solved, median, worst, c.condensed_solves, c.full_solves);
}

}  // namespace

TEST(CondensedTrial, DecidesLikeTheFullWindowOnLongSpans) {
  expectLikeTheFullWindow(compare(longLaps(), config(100)), "4-DoF");
}

TEST(CondensedTrial, ThinningTheLoopsBelowWhatTheWindowHoldsChangesTheScores) {
  // The comparison above can fail: a condensed trial that keeps only 2 of the accepted loops
  // is much less stiff than the full window, and its scores move away from the full trial's.
  const Comparison c = compare(longLaps(), config(100, 2));
  ASSERT_GE(c.solved, 30);
  EXPECT_GT(c.score_differences.back(), 0.03);
}

TEST(CondensedTrial, SixDofDecidesLikeTheFullWindowOnLongSpans) {
  // The 6-DoF trial condensed: the same laps, their odometry tilted at random on every step
  // (roll and pitch drift, 0.003 rad per step), judged by the 6-DoF full window and by the
  // condensed 6-DoF graph with the same loops committed.
  const sim::Scene scene = tiltedLaps(0.003);
  double lift = 0.0;  // how far the tilt lifts the VIO off the plane: the test needs 3-D drift
  for (const sim::SimKeyframe& kf : scene.keyframes) lift = std::max(lift, std::abs(kf.vio.t.z()));
  ASSERT_GT(lift, 1.0);
  std::printf("VIO %.1f m off the plane\n", lift);
  expectLikeTheFullWindow(compare(scene, config(100, 256, core::Mode::kSixDof)), "6-DoF");
}
