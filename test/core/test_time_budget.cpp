// The time budget bounds a verification and the commit of a loop accepted without a prior,
// whatever the graph: a trial that cannot reach the end of its first Ceres
// iteration within the budget is not started (neither building it nor one iteration can be
// interrupted: one iteration over 20k keyframes took 531 ms), and the solve stops before an
// iteration that would end past it. Nothing here measures time: the tests assert on reasons,
// solve counts and what changed in the graph. A fresh verifier predicts the cost of a trial
// from a fixed, cautious cost per keyframe (~40 us), so its first decision is deterministic.
#include "rover_loop_fusion/core/geometry.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

using namespace rover_loop_fusion;
using core::Reason;
using core::Verdict;

namespace {

/// `n` keyframes doing laps of 100 keyframes (a 50 m circuit), no loops closed yet.
sim::Scene laps(int n) {
  sim::LapsOptions o;
  o.width = 50.0 / 3;
  o.height = 50.0 / 6;
  o.laps = (n + 99) / 100;
  o.sigma_t = 0.005;
  o.sigma_yaw = 0.001;
  o.true_every = 0;
  o.false_every = 0;
  sim::Scene s = sim::makeLapsScene(o);
  s.keyframes.resize(n);
  return s;
}

/// A loop between two keyframes at their true relative pose.
core::LoopCandidate loop(const sim::SimKeyframe& query, const sim::SimKeyframe& match) {
  return sim::loopCandidate(query, match, sim::relative(match.truth, query.truth));
}

core::VerifierConfig budget(double ms) {
  core::VerifierConfig cfg;
  cfg.trial.time_budget_ms = ms;
  cfg.metric.max_innovation = 0.0;  // the gate off: every candidate reaches the trial solve
  cfg.trial.condense_min_window = 0;  // the full-window (Ceres) trial: what the budget has to bound
  return cfg;
}

}  // namespace

TEST(TimeBudget, AHugeWindowFailsClosedWithoutSolvingAndTheVerifierStaysUsable) {
  const sim::Scene s = laps(20000);
  core::Verifier v(budget(500.0));
  for (const sim::SimKeyframe& kf : s.keyframes) ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  const sim::SimKeyframe& query = s.keyframes.back();

  // The query's place in the first lap: a trial over 19901 keyframes (~800 ms predicted).
  const Verdict whole = v.verify(loop(query, s.keyframes[query.index % 100]));
  EXPECT_FALSE(whole.accepted);
  EXPECT_EQ(whole.reason, Reason::kTimeBudgetExceeded) << whole.detail;
  EXPECT_EQ(whole.iterations, 0);
  EXPECT_EQ(v.solveCount(), 0u) << "no Ceres solve may start";
  EXPECT_NE(whole.detail.find("not started: a trial over 19901 keyframes"), std::string::npos) << whole.detail;
  EXPECT_NE(whole.detail.find("time_budget_ms 500"), std::string::npos) << whole.detail;

  // The same place one lap back: a 101-keyframe trial is solved, accepted and committed.
  const core::LoopCandidate lap = loop(query, s.keyframes[query.index - 100]);
  const Verdict near = v.verify(lap);
  EXPECT_NE(near.reason, Reason::kTimeBudgetExceeded) << near.detail;
  EXPECT_TRUE(near.accepted) << near.detail;
  EXPECT_EQ(near.window_size, 101);
  EXPECT_GT(near.iterations, 0);
  EXPECT_EQ(v.solveCount(), 1u);
  ASSERT_TRUE(v.commit(lap).ok);
  EXPECT_EQ(v.solveCount(), 1u) << "commit keeps the verified solution";
  EXPECT_EQ(v.loopCount(), 1u);
}

TEST(TimeBudget, TheCommitOfALoopWithoutPriorIsBoundedToo) {
  // A 20k-keyframe session, then a second one starting where the first started: its first
  // loop has no prior (accepted by policy), and its commit would solve the whole graph.
  const sim::Scene s = laps(20000);
  const sim::Scene second = laps(10);
  core::Verifier v(budget(500.0));
  for (const sim::SimKeyframe& kf : s.keyframes) ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  // The second session's VIO frame: its own origin, turned by 0.5 rad and 7 m away.
  const core::Pose frame(Eigen::Vector3d(7, -3, 0), Eigen::Quaterniond(core::yawRotation(0.5)));
  for (const sim::SimKeyframe& kf : second.keyframes) {
    const core::Pose vio = sim::compose(frame, kf.vio);
    ASSERT_TRUE(v.addKeyframe(20000 + kf.index, 1000.0 + kf.stamp, 2, vio.t, vio.q).ok);
  }
  sim::SimKeyframe query = second.keyframes[5];
  query.index = 20005;
  const core::LoopCandidate c = loop(query, s.keyframes[5]);

  const Verdict vd = v.verify(c);
  ASSERT_TRUE(vd.accepted) << vd.detail;
  ASSERT_EQ(vd.reason, Reason::kNoTrajectoryPrior);
  const core::Status st = v.commit(c);
  EXPECT_TRUE(st.ok) << st.message;
  EXPECT_TRUE(st.warning());
  EXPECT_NE(st.message.find("time_budget_ms"), std::string::npos) << st.message;
  EXPECT_NE(st.message.find("not started: a trial over 20005 keyframes"), std::string::npos) << st.message;
  EXPECT_EQ(v.solveCount(), 0u) << "no Ceres solve may start";
  EXPECT_EQ(v.loopCount(), 1u) << "the loop is in the graph: the host uses it";

  // The loop is used all the same: the second session is anchored where the loop puts it.
  core::Pose q, m;
  ASSERT_TRUE(v.estimate(c.query_index, &q));
  ASSERT_TRUE(v.estimate(c.match_index, &m));
  EXPECT_LT((q.t - (m.t + m.q * c.relative_t)).norm(), 1e-6);
}
