// core::KeyframeGraph on its own: loop_fusion's stand-in graph (rover_verifier_node's ~pose_graph_path,
// rover_replay's accept-all baseline) collects loops without solving and solves once, like
// loop_fusion, to the same result as a verifier that committed the same loops.
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

using namespace rover_loop_fusion;

namespace {

sim::Scene corridor() {
  sim::LapsOptions o;
  o.laps = 2;
  o.sigma_yaw = 0.004;
  return sim::makeLapsScene(o);
}

}  // namespace

TEST(KeyframeGraph, StandInCollectsLoopsAndSolvesLikeLoopFusionOnce) {
  const sim::Scene s = corridor();
  core::KeyframeGraph graph;
  core::Verifier verifier;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    ASSERT_TRUE(graph.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    ASSERT_TRUE(verifier.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  }
  size_t loops = 0;
  for (const sim::SimCandidate& c : s.candidates) {
    if (!c.is_true) continue;
    ASSERT_TRUE(graph.addLoop(c.candidate).ok);
    ASSERT_TRUE(verifier.commit(c.candidate).ok);
    ++loops;
  }
  ASSERT_GT(loops, 5u);
  EXPECT_EQ(graph.loopCount(), loops);
  EXPECT_EQ(graph.solveCount(), 0u) << "addLoop does not solve";
  // The estimate X stays the VIO trajectory; loop_fusion's batch solve uses the loops.
  const std::vector<core::TrajectoryPoint> t = graph.trajectory();
  EXPECT_EQ((t.back().estimate.t - t.back().vio.t).norm(), 0.0);
  const core::BatchSolveResult a = graph.solveLikeLoopFusion(5), b = verifier.solveLikeLoopFusion(5);
  ASSERT_TRUE(a.ok) << a.message;
  EXPECT_EQ(graph.solveCount(), 1u);
  ASSERT_EQ(a.poses.size(), b.poses.size());
  for (size_t i = 0; i < a.poses.size(); ++i) EXPECT_EQ(a.poses[i].t, b.poses[i].t) << i;
  std::vector<core::Pose> truth;
  for (const sim::SimKeyframe& kf : s.keyframes) truth.push_back(kf.truth);
  std::vector<core::Pose> vio;
  for (const core::TrajectoryPoint& p : t) vio.push_back(p.vio);
  EXPECT_LT(sim::ate(a.poses, truth), 0.7 * sim::ate(vio, truth));
}

TEST(KeyframeGraph, AddLoopRefusesWhatCannotBeAnEdge) {
  const sim::Scene s = corridor();
  core::KeyframeGraph graph;
  for (const sim::SimKeyframe& kf : s.keyframes) ASSERT_TRUE(graph.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  core::LoopCandidate c = s.candidates.front().candidate;
  ASSERT_TRUE(graph.addLoop(c).ok);
  const core::Status twice = graph.addLoop(c);
  EXPECT_FALSE(twice.ok);
  EXPECT_NE(twice.message.find("already in the graph"), std::string::npos) << twice.message;
  c.match_index = 100000;
  EXPECT_NE(graph.addLoop(c).message.find("unknown match keyframe"), std::string::npos);
  c = s.candidates.front().candidate;
  c.relative_t.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(graph.addLoop(c).message.find("not finite"), std::string::npos);
  EXPECT_EQ(graph.loopCount(), 1u);
  EXPECT_EQ(graph.revision(), 1u);
}
