// Bad input at the core's API boundary: refused with a clear message (Status) or an
// invalid_input verdict; never a crash, never a changed or corrupted graph.
#include "rover_loop_fusion/core/verifier.h"

#include <gtest/gtest.h>

#include <limits>

using namespace rover_loop_fusion::core;

namespace {

const double kNaN = std::numeric_limits<double>::quiet_NaN();
const double kInf = std::numeric_limits<double>::infinity();

/// 120 keyframes along a straight corridor, sequence 1.
void fill(Verifier& v, int n = 120) {
  for (int k = 0; k < n; ++k)
    ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 1, Eigen::Vector3d(0.5 * k, 0, 0), Eigen::Quaterniond::Identity()).ok);
}

LoopCandidate goodCandidate() {
  LoopCandidate c;
  c.query_index = 110;
  c.match_index = 10;
  c.relative_t = Eigen::Vector3d(0.2, 0.0, 0.0);
  return c;
}

/// The full observable state: to check that refused input changed nothing.
std::vector<double> snapshot(const Verifier& v) {
  std::vector<double> s = {static_cast<double>(v.keyframeCount()), static_cast<double>(v.loopCount())};
  for (const TrajectoryPoint& p : v.trajectory()) {
    s.insert(s.end(), {static_cast<double>(p.index), p.stamp, static_cast<double>(p.sequence)});
    s.insert(s.end(), p.estimate.t.data(), p.estimate.t.data() + 3);
    s.insert(s.end(), p.estimate.q.coeffs().data(), p.estimate.q.coeffs().data() + 4);
  }
  return s;
}

void expectInvalid(Verifier& v, const LoopCandidate& c, const std::string& words) {
  const std::vector<double> before = snapshot(v);
  const Verdict vd = v.verify(c);
  EXPECT_FALSE(vd.accepted);
  EXPECT_EQ(vd.reason, Reason::kInvalidInput);
  EXPECT_NE(vd.detail.find(words), std::string::npos) << "detail: " << vd.detail;
  const Status st = v.commit(c);
  EXPECT_FALSE(st.ok);
  EXPECT_NE(st.message.find(words), std::string::npos) << "message: " << st.message;
  EXPECT_EQ(snapshot(v), before);
}

void expectRefused(Verifier& v, int64_t index, double stamp, int seq, const Eigen::Vector3d& t,
                   const Eigen::Quaterniond& q, const std::string& words) {
  const std::vector<double> before = snapshot(v);
  const Status st = v.addKeyframe(index, stamp, seq, t, q);
  EXPECT_FALSE(st.ok);
  EXPECT_NE(st.message.find(words), std::string::npos) << "message: " << st.message;
  EXPECT_EQ(snapshot(v), before);
}

}  // namespace

TEST(BadKeyframe, NonFinitePose) {
  Verifier v;
  fill(v);
  const Eigen::Quaterniond I = Eigen::Quaterniond::Identity();
  expectRefused(v, 200, 500, 1, Eigen::Vector3d(kNaN, 0, 0), I, "not finite");
  expectRefused(v, 200, 500, 1, Eigen::Vector3d(0, kInf, 0), I, "not finite");
  expectRefused(v, 200, 500, 1, Eigen::Vector3d::Zero(), Eigen::Quaterniond(kNaN, 0, 0, 0), "unit quaternion");
  expectRefused(v, 200, kNaN, 1, Eigen::Vector3d::Zero(), I, "stamp");
}

TEST(BadKeyframe, NonUnitQuaternion) {
  Verifier v;
  fill(v);
  expectRefused(v, 200, 500, 1, Eigen::Vector3d::Zero(), Eigen::Quaterniond(2, 0, 0, 0), "unit quaternion");
  expectRefused(v, 200, 500, 1, Eigen::Vector3d::Zero(), Eigen::Quaterniond(0, 0, 0, 0), "unit quaternion");
}

TEST(BadKeyframe, IndexAndStampOrder) {
  Verifier v;
  fill(v);
  const Eigen::Quaterniond I = Eigen::Quaterniond::Identity();
  expectRefused(v, -3, 500, 1, Eigen::Vector3d::Zero(), I, "negative index");
  expectRefused(v, 119, 500, 1, Eigen::Vector3d::Zero(), I, "duplicate");
  expectRefused(v, 50, 500, 1, Eigen::Vector3d::Zero(), I, "older");
  expectRefused(v, 200, 129.0, 1, Eigen::Vector3d::Zero(), I, "stamp");  // the newest has 129
  expectRefused(v, 200, 129.5, 0, Eigen::Vector3d::Zero(), I, "sequence");
  expectRefused(v, 200, 129.5, -1, Eigen::Vector3d::Zero(), I, "negative sequence");
  // A new sequence may restart its clock (a map recorded later than the live session).
  EXPECT_TRUE(v.addKeyframe(200, 1.0, 2, Eigen::Vector3d::Zero(), I).ok);
}

TEST(BadCandidate, UnknownSelfAndFutureKeyframes) {
  Verifier v;
  fill(v);
  LoopCandidate c = goodCandidate();
  c.query_index = 500;
  expectInvalid(v, c, "unknown query");
  c = goodCandidate();
  c.match_index = 777;
  expectInvalid(v, c, "unknown match");
  c = goodCandidate();
  c.match_index = c.query_index;
  expectInvalid(v, c, "to itself");
  c = goodCandidate();
  std::swap(c.query_index, c.match_index);
  expectInvalid(v, c, "newer than query");
  c = goodCandidate();
  c.match_index = -4;
  expectInvalid(v, c, "negative");
}

TEST(BadCandidate, NonFiniteOrImplausibleRelativePose) {
  Verifier v;
  fill(v);
  LoopCandidate c = goodCandidate();
  c.relative_t.x() = kNaN;
  expectInvalid(v, c, "not finite");
  c = goodCandidate();
  c.relative_yaw = kInf;
  expectInvalid(v, c, "not finite");
  c = goodCandidate();
  c.relative_q = Eigen::Quaterniond(0.5, 0, 0, 0);
  expectInvalid(v, c, "unit quaternion");
  c = goodCandidate();
  c.relative_t = Eigen::Vector3d(150, 0, 0);
  expectInvalid(v, c, "max_relative_translation");
  c = goodCandidate();
  c.relative_yaw = 1.2;  // ~69 deg: findConnection would never pass it
  expectInvalid(v, c, "max_relative_yaw");
}

TEST(BadCandidate, EmptyGraph) {
  Verifier v;
  expectInvalid(v, goodCandidate(), "unknown query");
}

TEST(BadCandidate, BothInFixedLoadedMap) {
  Verifier v;
  for (int k = 0; k < 120; ++k)
    ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 0, Eigen::Vector3d(0.5 * k, 0, 0), Eigen::Quaterniond::Identity()).ok);
  const Verdict vd = v.verify(goodCandidate());
  EXPECT_FALSE(vd.accepted);
  EXPECT_EQ(vd.reason, Reason::kInvalidInput);
  // Stored loops of a loaded map are committed without a solve: nothing there can move.
  EXPECT_TRUE(v.commit(goodCandidate()).ok);
  EXPECT_EQ(v.solveCount(), 0u);
}

TEST(BadCandidate, DuplicateCommitIsRefused) {
  Verifier v;
  fill(v);
  ASSERT_TRUE(v.commit(goodCandidate()).ok);
  const std::vector<double> before = snapshot(v);
  const Status st = v.commit(goodCandidate());
  EXPECT_FALSE(st.ok);
  EXPECT_NE(st.message.find("already"), std::string::npos);
  EXPECT_EQ(snapshot(v), before);
}

TEST(BadConfig, InvalidValuesFallBackToDefaults) {
  VerifierConfig cfg;
  cfg.metric.threshold = -1;
  cfg.trial.max_iterations = 0;
  cfg.trial.window_margin = -5;
  const Verifier v(cfg);
  EXPECT_NE(v.configError().find("threshold"), std::string::npos);
  EXPECT_NE(v.configError().find("max_iterations"), std::string::npos);
  EXPECT_NE(v.configError().find("window_margin"), std::string::npos);
  EXPECT_DOUBLE_EQ(v.config().metric.threshold, VerifierConfig().metric.threshold);
  VerifierConfig nan_cfg;
  nan_cfg.metric.threshold = kNaN;
  EXPECT_FALSE(nan_cfg.validate().empty());
  EXPECT_TRUE(VerifierConfig().validate().empty());
}

TEST(LoopInfo, DegreesAreConvertedAtTheBoundary) {
  const double info[8] = {1.0, 2.0, 3.0, 1.0, 0.0, 0.0, 0.0, 12.0};
  const LoopCandidate c = candidateFromLoopInfo(40, 3, info, 31);
  EXPECT_EQ(c.query_index, 40);
  EXPECT_EQ(c.match_index, 3);
  EXPECT_EQ(c.inliers, 31);
  EXPECT_NEAR(c.relative_yaw, 12.0 * M_PI / 180.0, 1e-15);
  EXPECT_EQ(c.relative_t, Eigen::Vector3d(1, 2, 3));
  EXPECT_DOUBLE_EQ(c.relative_q.w(), 1.0);
}

TEST(Reasons, HaveStableNames) {
  EXPECT_STREQ(toString(Reason::kAccepted), "accepted");
  EXPECT_STREQ(toString(Reason::kScoreAboveThreshold), "score_above_threshold");
  EXPECT_STREQ(toString(Reason::kNotConverged), "not_converged");
  EXPECT_STREQ(toString(Reason::kNoTrajectoryPrior), "no_trajectory_prior");
  EXPECT_STREQ(toString(Reason::kInvalidInput), "invalid_input");
  EXPECT_STREQ(toString(Reason::kTimeBudgetExceeded), "time_budget_exceeded");
  EXPECT_STREQ(toString(Reason::kInnovationAboveBound), "innovation_above_bound");
  Mode m;
  EXPECT_TRUE(parseMode("6dof", &m));
  EXPECT_EQ(m, Mode::kSixDof);
  EXPECT_FALSE(parseMode("7dof", &m));
  Alignment a;
  EXPECT_TRUE(parseAlignment("sim3", &a));
  EXPECT_EQ(a, Alignment::kSim3);
  EXPECT_FALSE(parseAlignment("affine", &a));
}
