// The decision as functions on plain values (core/decision.h) and the verdict factories: each
// test, its boundary and its reason, without a pose graph.
#include "rover_loop_fusion/core/decision.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

using namespace rover_loop_fusion::core;

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

SolveSummary converged() {
  SolveSummary s;
  s.converged = true;
  s.finite = true;
  s.iterations = 3;
  s.message = "Function tolerance reached.";
  return s;
}

}  // namespace

TEST(Decision, ScoreThresholdIsFixedUnlessItGrowsWithThePath) {
  VerifierConfig c;
  c.metric.threshold = 0.2;
  EXPECT_DOUBLE_EQ(scoreThreshold(c, 100.0), 0.2);
  c.metric.threshold_per_metre = 0.01;
  EXPECT_DOUBLE_EQ(scoreThreshold(c, 10.0), 0.2 + 0.1);
  c.metric.max_threshold = 0.25;
  EXPECT_DOUBLE_EQ(scoreThreshold(c, 10.0), 0.25);
  EXPECT_DOUBLE_EQ(scoreThreshold(c, kInf), 0.2) << "no path: the fixed threshold";
}

TEST(Decision, InnovationGateBoundGrowsWithThePath) {
  VerifierConfig c;
  c.metric.max_innovation = 0.5;
  c.metric.max_innovation_per_metre = 0.02;
  EXPECT_TRUE(innovationGate(c, 0.69, 10.0).passed);  // bound 0.7 m
  const Check far = innovationGate(c, 0.71, 10.0);
  EXPECT_FALSE(far.passed);
  EXPECT_EQ(far.reason, Reason::kInnovationAboveBound);
  EXPECT_NE(far.detail.find("innovation 0.710 m > 0.700 m"), std::string::npos) << far.detail;
  c.metric.max_innovation = 0.0;
  EXPECT_TRUE(innovationGate(c, 50.0, 10.0).passed) << "max_innovation 0: no gate";
}

TEST(Decision, InnovationGateFailsClosedWhenItsInputsAreNotFinite) {
  // Red team: a path length of inf (one keyframe at x += 1e155) skipped the gate for the rest
  // of the run. Whatever makes an input non-finite, the gate rejects and says why.
  VerifierConfig c;
  for (double innovation : {0.1, kNaN, kInf}) {
    for (double path : {10.0, kInf, kNaN}) {
      if (std::isfinite(innovation) && std::isfinite(path)) continue;
      const Check g = innovationGate(c, innovation, path);
      EXPECT_FALSE(g.passed) << innovation << " " << path;
      EXPECT_EQ(g.reason, Reason::kInvalidInput);
      EXPECT_NE(g.detail.find("not finite"), std::string::npos) << g.detail;
    }
  }
  c.metric.max_innovation_per_metre = 2.0;  // (beyond the parameter's range: the function must not care)
  EXPECT_FALSE(innovationGate(c, 0.1, std::numeric_limits<double>::max()).passed) << "the bound overflows";
}

TEST(Decision, ScoreTestAcceptsOnlyAConvergedFiniteSolutionUnderTheThreshold) {
  const Check ok = scoreTest(converged(), 0.1, 0.2, 80, 200.0);
  EXPECT_TRUE(ok.passed);
  EXPECT_NE(ok.detail.find("score 0.100 m <= threshold 0.200 m over 80 keyframes"), std::string::npos) << ok.detail;
  const Check above = scoreTest(converged(), 0.3, 0.2, 80, 200.0);
  EXPECT_FALSE(above.passed);
  EXPECT_EQ(above.reason, Reason::kScoreAboveThreshold);
  SolveSummary s = converged();
  s.converged = false;
  EXPECT_EQ(scoreTest(s, 0.1, 0.2, 80, 200.0).reason, Reason::kNotConverged);
  s = converged();
  s.finite = false;
  EXPECT_EQ(scoreTest(s, 0.1, 0.2, 80, 200.0).reason, Reason::kNotConverged);
  EXPECT_EQ(scoreTest(converged(), kNaN, 0.2, 80, 200.0).reason, Reason::kNotConverged);
  s = converged();
  s.timed_out = true;
  const Check late = scoreTest(s, 0.1, 0.2, 80, 200.0);
  EXPECT_EQ(late.reason, Reason::kTimeBudgetExceeded);
  EXPECT_NE(late.detail.find("time_budget_ms"), std::string::npos) << late.detail;
}

TEST(Decision, DeformationScoreIgnoresRigidMotionAndSeesBending) {
  Eigen::Matrix3Xd before(3, 4);
  before << 0, 1, 2, 3, 0, 0, 0, 0, 0, 0, 0, 0;
  const Eigen::Matrix3Xd moved = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix() * before).colwise() +
                                 Eigen::Vector3d(5, -2, 1);
  EXPECT_NEAR(deformationScore(before, moved, Alignment::kSE3), 0.0, 1e-12);
  Eigen::Matrix3Xd bent = before;
  bent(1, 3) = 1.0;
  EXPECT_GT(deformationScore(before, bent, Alignment::kSE3), 0.1);
  EXPECT_NEAR(deformationScore(before, 2.0 * before, Alignment::kSim3), 0.0, 1e-12) << "Sim(3): scale is free";
  EXPECT_TRUE(std::isnan(deformationScore(Eigen::Matrix3Xd(3, 0), Eigen::Matrix3Xd(3, 0), Alignment::kSE3)));
}

TEST(VerdictFactories, SayWhatWasDecidedAboutWhichCandidate) {
  LoopCandidate c;
  c.query_index = 40;
  c.match_index = 3;
  const Verdict a = Verdict::Accept(c, "fine");
  EXPECT_TRUE(a.accepted);
  EXPECT_EQ(a.reason, Reason::kAccepted);
  EXPECT_EQ(a.query_index, 40);
  EXPECT_EQ(a.match_index, 3);
  EXPECT_EQ(a.detail, "fine");
  EXPECT_EQ(Verdict::Accept(c, "policy", Reason::kNoTrajectoryPrior).reason, Reason::kNoTrajectoryPrior);
  const Verdict r = Verdict::Reject(Reason::kScoreAboveThreshold, c, "torn");
  EXPECT_FALSE(r.accepted);
  EXPECT_EQ(r.reason, Reason::kScoreAboveThreshold);
  EXPECT_EQ(r.detail, "torn");
  EXPECT_TRUE(std::isnan(r.score));
  EXPECT_EQ(Verdict::Reject(Reason::kAccepted, c, "?").reason, Reason::kInvalidInput)
      << "a rejection never says accepted";
}
