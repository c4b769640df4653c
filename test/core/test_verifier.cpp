#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

using namespace rover_loop_fusion;
using core::Reason;
using core::Verdict;
using core::Verifier;

namespace {

/// A corridor loop (20 m x 10 m, keyframes every 0.5 m) driven twice with VIO-like drift.
sim::Scene corridor(uint32_t seed = 7, double lap_z_step = 0.0) {
  sim::LapsOptions o;
  o.laps = 2;
  o.seed = seed;
  o.sigma_yaw = 0.004;
  o.lap_z_step = lap_z_step;
  return sim::makeLapsScene(o);
}

void addUpTo(Verifier& v, const sim::Scene& s, int64_t last_index, int sequence = 1) {
  for (const sim::SimKeyframe& kf : s.keyframes) {
    if (kf.index > last_index) break;
    if (v.hasKeyframe(kf.index)) continue;
    ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, sequence, kf.vio.t, kf.vio.q).ok);
  }
}

const sim::SimCandidate& first(const sim::Scene& s, bool is_true) {
  for (const sim::SimCandidate& c : s.candidates)
    if (c.is_true == is_true) return c;
  throw std::runtime_error("scene has no such candidate");
}

std::vector<core::Pose> truthUpTo(const sim::Scene& s, size_t n) {
  std::vector<core::Pose> t;
  for (size_t i = 0; i < n; ++i) t.push_back(s.keyframes[i].truth);
  return t;
}

std::vector<core::Pose> estimates(const Verifier& v) {
  std::vector<core::Pose> e;
  for (const core::TrajectoryPoint& p : v.trajectory()) e.push_back(p.estimate);
  return e;
}

std::vector<core::Pose> vio(const Verifier& v) {
  std::vector<core::Pose> e;
  for (const core::TrajectoryPoint& p : v.trajectory()) e.push_back(p.vio);
  return e;
}

}  // namespace

TEST(Verifier, TrueLoopScoresUnderThresholdAndLowersAte) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, true);
  Verifier v;
  addUpTo(v, s, c.candidate.query_index);
  const double ate_before = sim::ate(estimates(v), truthUpTo(s, v.keyframeCount()));
  const Verdict vd = v.verify(c.candidate);
  EXPECT_TRUE(vd.accepted) << vd.detail;
  EXPECT_EQ(vd.reason, Reason::kAccepted);
  EXPECT_TRUE(vd.converged);
  EXPECT_LE(vd.score, v.config().metric.threshold);
  EXPECT_GT(vd.window_size, 50);
  ASSERT_TRUE(v.commit(c.candidate).ok);
  const double ate_after = sim::ate(estimates(v), truthUpTo(s, v.keyframeCount()));
  EXPECT_LT(ate_after, 0.7 * ate_before) << "before " << ate_before << " after " << ate_after;
}

TEST(Verifier, FalseRepetitiveLoopScoresOverThreshold) {
  // A look-alike place 3 m away, matched with a plausible small relative pose.
  // The deformation score itself (the innovation gate, which would reject these first, off).
  core::VerifierConfig score_only;
  score_only.metric.max_innovation = 0.0;
  for (uint32_t seed : {7u, 8u, 9u}) {
    const sim::Scene s = corridor(seed);
    const sim::SimCandidate& c = first(s, false);
    ASSERT_NEAR(c.truth_distance, 3.0, 0.5);
    ASSERT_LT(c.candidate.relative_t.norm(), 1.5);
    Verifier v(score_only);
    addUpTo(v, s, c.candidate.query_index);
    const Verdict vd = v.verify(c.candidate);
    EXPECT_FALSE(vd.accepted) << "seed " << seed << ": " << vd.detail;
    EXPECT_EQ(vd.reason, Reason::kScoreAboveThreshold);
    EXPECT_GT(vd.score, v.config().metric.threshold);
  }
}

TEST(Verifier, FalseFloorLoopInParkingDeckIsRejected) {
  // Parking deck: each lap one floor (3 m) up; the candidate is "the same spot one floor
  // over". Closing it squashes a 3 m climb over one 60 m lap: a ramp that a tilt half
  // absorbs, so the score is about 0.44 m: rejected at the default threshold (0.2 m), but
  // not at the paper's 0.5 m (measured limit, docs/method.md).
  const sim::Scene s = corridor(7, 3.0);
  const sim::SimCandidate& c = first(s, false);
  core::VerifierConfig score_only;
  score_only.metric.max_innovation = 0.0;
  Verifier v(score_only);
  addUpTo(v, s, c.candidate.query_index);
  const Verdict vd = v.verify(c.candidate);
  EXPECT_FALSE(vd.accepted) << vd.detail;
  EXPECT_GT(vd.score, 0.3) << vd.detail;
  Verifier defaults;  // with the gate as well: rejected
  addUpTo(defaults, s, c.candidate.query_index);
  EXPECT_FALSE(defaults.verify(c.candidate).accepted);
}

TEST(Verifier, VerdictReportsInnovationAndPathLength) {
  // The false candidate is a place 3 m from the query: the candidate disagrees with the
  // estimate by about that much; the true one by the drift only. Both loops span one lap
  // (60 m of odometry) before any loop is in the graph; after the true loop is committed,
  // the next candidate's path runs through it and is short.
  const sim::Scene s = corridor();
  const sim::SimCandidate& t = first(s, true);
  const sim::SimCandidate& f = first(s, false);
  Verifier v;
  addUpTo(v, s, std::max(t.candidate.query_index, f.candidate.query_index));
  const Verdict vt = v.verify(t.candidate), vf = v.verify(f.candidate);
  EXPECT_GT(vf.innovation, 2.0);
  EXPECT_LT(vt.innovation, vf.innovation);
  EXPECT_GT(vt.path_length, 50.0);
  EXPECT_LT(vt.path_length, 70.0);
  ASSERT_TRUE(v.commit(t.candidate).ok);
  core::LoopCandidate next = t.candidate;
  next.query_index += 2;
  next.match_index += 2;
  addUpTo(v, s, next.query_index);
  EXPECT_LT(v.verify(next).path_length, 5.0);
}

TEST(Verifier, ThresholdGrowsWithPathLengthWhenAsked) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, false);
  core::VerifierConfig cfg;
  cfg.metric.threshold_per_metre = 0.01;
  cfg.metric.max_threshold = 0.4;
  Verifier v(cfg);
  addUpTo(v, s, c.candidate.query_index);
  const Verdict vd = v.verify(c.candidate);
  EXPECT_NEAR(vd.threshold, std::min(0.4, cfg.metric.threshold + 0.01 * vd.path_length), 1e-12);
  EXPECT_DOUBLE_EQ(vd.threshold, 0.4);  // ~60 m of path: capped
}

TEST(Verifier, InnovationGateRejectsLookAlikesNextToTiedPlacesWithoutSolving) {
  // After the true loop of a revisit is in the graph, a look-alike 3 m away seen from the
  // next keyframes contradicts the graph over a few metres of path: the gate rejects it
  // before any solve. A true loop of the same revisit passes the gate and is scored.
  const sim::Scene s = corridor();
  const sim::SimCandidate& t = first(s, true);
  Verifier v;
  addUpTo(v, s, t.candidate.query_index);
  ASSERT_TRUE(v.verify(t.candidate).accepted);
  ASSERT_TRUE(v.commit(t.candidate).ok);
  const int64_t q = t.candidate.query_index + 2;
  addUpTo(v, s, q);
  core::LoopCandidate lookalike = t.candidate;  // the keyframe 6 places (3 m) before the revisit
  lookalike.query_index = q;
  lookalike.match_index = t.candidate.match_index + 2 - 6;
  lookalike.relative_t = sim::relative(s.keyframes[t.candidate.match_index + 2].truth, s.keyframes[q].truth).t;
  const size_t solves = v.solveCount();
  const Verdict vd = v.verify(lookalike);
  EXPECT_FALSE(vd.accepted);
  EXPECT_EQ(vd.reason, Reason::kInnovationAboveBound) << vd.detail;
  EXPECT_GT(vd.innovation, 2.5);
  EXPECT_LT(vd.path_length, 10.0);
  EXPECT_EQ(v.solveCount(), solves) << "the gate decides without a trial solve";

  core::LoopCandidate truth = t.candidate;
  truth.query_index = q;
  truth.match_index = t.candidate.match_index + 2;
  truth.relative_t = lookalike.relative_t;
  const Verdict vt = v.verify(truth);
  EXPECT_TRUE(vt.accepted) << vt.detail;

  core::VerifierConfig no_gate;
  no_gate.metric.max_innovation = 0.0;
  Verifier w(no_gate);
  addUpTo(w, s, t.candidate.query_index);
  ASSERT_TRUE(w.commit(t.candidate).ok);
  addUpTo(w, s, q);
  EXPECT_NE(w.verify(lookalike).reason, Reason::kInnovationAboveBound);
}

TEST(Verifier, VerifyDoesNotChangeTheGraph) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, false);
  core::VerifierConfig score_only;  // so that the trial solve runs
  score_only.metric.max_innovation = 0.0;
  Verifier v(score_only);
  addUpTo(v, s, c.candidate.query_index);
  const std::vector<core::Pose> before = estimates(v);
  const Verdict a = v.verify(c.candidate);
  const Verdict b = v.verify(c.candidate);
  const std::vector<core::Pose> after = estimates(v);
  EXPECT_EQ(v.loopCount(), 0u);
  ASSERT_EQ(before.size(), after.size());
  for (size_t i = 0; i < before.size(); ++i) {
    EXPECT_EQ(before[i].t, after[i].t);
    EXPECT_EQ(before[i].q.coeffs(), after[i].q.coeffs());
  }
  EXPECT_DOUBLE_EQ(a.score, b.score);
}

TEST(Verifier, CommitKeepsTheVerifiedSolutionWithoutSolvingAgain) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, true);
  Verifier v;
  addUpTo(v, s, c.candidate.query_index);
  const core::Pose before = estimates(v).back();
  const Verdict vd = v.verify(c.candidate);
  ASSERT_TRUE(vd.accepted);
  const size_t solves = v.solveCount();
  ASSERT_TRUE(v.commit(c.candidate).ok);
  EXPECT_EQ(v.solveCount(), solves) << "commit after an accepting verify must not solve again";
  EXPECT_EQ(v.loopCount(), 1u);
  const core::Pose after = estimates(v).back();
  EXPECT_GT((after.t - before.t).norm(), 1e-3) << "the query keyframe must move to X*";

  // The same loop committed on a verifier that never verified it solves once and lands close
  // by (not on it: verify trusts the candidate fully, a committed loop has loop_fusion's
  // Huber loss like every loop in the graph).
  Verifier w;
  addUpTo(w, s, c.candidate.query_index);
  ASSERT_TRUE(w.commit(c.candidate).ok);
  EXPECT_EQ(w.solveCount(), 1u);
  EXPECT_NEAR((estimates(w).back().t - after.t).norm(), 0.0, 0.05);
}

TEST(Verifier, NewKeyframesFollowTheCorrection) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, true);
  Verifier v;
  addUpTo(v, s, c.candidate.query_index);
  ASSERT_TRUE(v.verify(c.candidate).accepted);
  ASSERT_TRUE(v.commit(c.candidate).ok);
  addUpTo(v, s, c.candidate.query_index + 10);
  // Keyframes after the loop keep the corrected estimate's relation to the VIO pose.
  const std::vector<core::TrajectoryPoint> traj = v.trajectory();
  const core::TrajectoryPoint& q = traj[c.candidate.query_index];
  const core::TrajectoryPoint& later = traj.back();
  const core::Pose rel_vio = sim::relative(q.vio, later.vio);
  const core::Pose rel_est = sim::relative(q.estimate, later.estimate);
  EXPECT_NEAR((rel_vio.t - rel_est.t).norm(), 0.0, 1e-6);
  EXPECT_GT((later.estimate.t - later.vio.t).norm(), 1e-3);
}

TEST(Verifier, SequentialVerificationOfAScene) {
  // Every candidate in order, accepted ones committed: no false loop gets in and the
  // verified map is better than odometry and than accepting everything.
  sim::LapsOptions o;
  o.laps = 3;
  const sim::Scene s = sim::makeLapsScene(o);
  core::VerifierConfig cfg;  // defaults
  Verifier v(cfg), all(cfg);
  size_t next = 0;
  int tp = 0, fp = 0, fn = 0;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    ASSERT_TRUE(all.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
      const sim::SimCandidate& c = s.candidates[next];
      const Verdict vd = v.verify(c.candidate);
      if (vd.accepted) {
        ASSERT_TRUE(v.commit(c.candidate).ok);
      }
      ASSERT_TRUE(all.commit(c.candidate).ok);
      if (c.is_true) (vd.accepted ? tp : fn)++;
      else if (vd.accepted) fp++;
    }
  }
  EXPECT_EQ(fp, 0);
  EXPECT_GE(tp, (tp + fn) * 9 / 10);
  const std::vector<core::Pose> truth = truthUpTo(s, s.keyframes.size());
  const double ate_odom = sim::ate(vio(v), truth);
  const double ate_verified = sim::ate(v.solveLikeLoopFusion(5).poses, truth);
  const double ate_all = sim::ate(all.solveLikeLoopFusion(5).poses, truth);
  EXPECT_LT(ate_verified, ate_odom);
  EXPECT_LE(ate_verified, ate_all);
}

TEST(Verifier, SixDofMode) {
  // Visual odometry without IMU: roll and pitch drift too.
  sim::LapsOptions o;
  o.laps = 2;
  sim::Scene s = sim::makeLapsScene(o);
  sim::Gaussian g(3);
  for (size_t k = 1; k < s.keyframes.size(); ++k) {
    core::Pose rel = sim::relative(s.keyframes[k - 1].truth, s.keyframes[k].truth);
    rel.t += Eigen::Vector3d(g(0.01), g(0.01), g(0.01));
    rel.q = (Eigen::Quaterniond(Eigen::AngleAxisd(g(0.002), Eigen::Vector3d::UnitX())) *
             Eigen::Quaterniond(Eigen::AngleAxisd(g(0.002), Eigen::Vector3d::UnitY())) *
             Eigen::Quaterniond(Eigen::AngleAxisd(g(0.004), Eigen::Vector3d::UnitZ())) * rel.q)
                .normalized();
    s.keyframes[k].vio = sim::compose(s.keyframes[k - 1].vio, rel);
  }
  core::VerifierConfig cfg;
  cfg.mode = core::Mode::kSixDof;
  const sim::SimCandidate& t = first(s, true);
  const sim::SimCandidate& f = first(s, false);
  Verifier v(cfg);
  addUpTo(v, s, std::max(t.candidate.query_index, f.candidate.query_index));
  const Verdict vf = v.verify(f.candidate);
  EXPECT_FALSE(vf.accepted) << vf.detail;
  const Verdict vt = v.verify(t.candidate);
  EXPECT_TRUE(vt.accepted) << vt.detail;
  const double ate_before = sim::ate(estimates(v), truthUpTo(s, v.keyframeCount()));
  ASSERT_TRUE(v.commit(t.candidate).ok);
  EXPECT_LT(sim::ate(estimates(v), truthUpTo(s, v.keyframeCount())), ate_before);
  // 6-DoF estimates carry their own roll/pitch: the estimate is not the VIO rotation.
  const std::vector<core::TrajectoryPoint> traj = v.trajectory();
  EXPECT_GT(traj.back().estimate.q.angularDistance(traj.back().vio.q), 1e-4);
}

TEST(Verifier, Sim3AlignmentIgnoresScale) {
  // Monocular VO: the odometry is 20 % too long; a true loop then needs the trajectory to
  // shrink, which Sim(3) alignment does not count as deformation.
  sim::LapsOptions o;
  o.laps = 2;
  o.sigma_t = 0.002;
  o.sigma_yaw = 0.0005;
  sim::Scene s = sim::makeLapsScene(o);
  for (sim::SimKeyframe& kf : s.keyframes) kf.vio.t *= 1.2;
  const sim::SimCandidate& c = first(s, true);
  core::VerifierConfig se3, sim3;
  sim3.alignment = core::Alignment::kSim3;
  Verifier a(se3), b(sim3);
  addUpTo(a, s, c.candidate.query_index);
  addUpTo(b, s, c.candidate.query_index);
  const Verdict va = a.verify(c.candidate);
  const Verdict vb = b.verify(c.candidate);
  EXPECT_LT(vb.score, va.score);
}

TEST(Verifier, NoTrajectoryPriorBetweenUnconnectedSequences) {
  // Sequence 2 is a second session starting in its own frame (VIO origin); its first loop to
  // sequence 1 has no prior. Policy decides; after commit the sequences are one map.
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, true);
  const int64_t split = 100;
  ASSERT_GT(c.candidate.query_index, split);
  for (bool policy : {true, false}) {
    core::VerifierConfig cfg;
    cfg.host.accept_without_prior = policy;
    cfg.host.anchor_incoming_keyframes = true;  // raw per-session poses, as the node hands them
    Verifier v(cfg);
    addUpTo(v, s, split - 1, 1);
    // Sequence 2 re-expressed in its own VIO frame: starts at the origin.
    const core::Pose origin = s.keyframes[split].vio;
    for (int64_t k = split; k <= c.candidate.query_index; ++k) {
      const core::Pose p = sim::relative(origin, s.keyframes[k].vio);
      ASSERT_TRUE(v.addKeyframe(k, s.keyframes[k].stamp, 2, p.t, p.q).ok);
    }
    const Verdict vd = v.verify(c.candidate);
    EXPECT_EQ(vd.reason, Reason::kNoTrajectoryPrior) << vd.detail;
    EXPECT_EQ(vd.accepted, policy);
    if (!policy) continue;
    ASSERT_TRUE(v.commit(c.candidate).ok);
    // Anchored: the query keyframe now sits where the loop puts it relative to the match.
    core::Pose q, m;
    ASSERT_TRUE(v.estimate(c.candidate.query_index, &q));
    ASSERT_TRUE(v.estimate(c.candidate.match_index, &m));
    EXPECT_NEAR((sim::relative(m, q).t - c.candidate.relative_t).norm(), 0.0, 0.2);
    // The next candidate across the two sequences is scored against the prior.
    ASSERT_TRUE(v.addKeyframe(c.candidate.query_index + 1, s.keyframes[c.candidate.query_index + 1].stamp, 2,
                              sim::relative(origin, s.keyframes[c.candidate.query_index + 1].vio).t,
                              sim::relative(origin, s.keyframes[c.candidate.query_index + 1].vio).q)
                    .ok);
    core::LoopCandidate next = c.candidate;
    next.query_index += 1;
    next.match_index += 1;
    const Verdict vn = v.verify(next);
    EXPECT_NE(vn.reason, Reason::kNoTrajectoryPrior) << vn.detail;
    EXPECT_TRUE(std::isfinite(vn.score)) << vn.detail;
    EXPECT_LT(vn.innovation, 0.5) << "the anchored session continues in the map's frame";
  }
}

TEST(Verifier, AnchorsIncomingKeyframesWhenAsked) {
  // The standalone node gets raw per-session VIO poses and applies loop_fusion's sequence
  // shift itself; loop_fusion hands shifted poses. Both must end with the same estimate.
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, true);
  const int64_t split = 100, last = c.candidate.query_index + 20;
  const core::Pose origin = s.keyframes[split].vio;
  core::VerifierConfig raw_cfg;
  raw_cfg.host.anchor_incoming_keyframes = true;
  Verifier raw(raw_cfg);
  addUpTo(raw, s, split - 1, 1);
  for (int64_t k = split; k <= last; ++k) {
    const core::Pose p = sim::relative(origin, s.keyframes[k].vio);
    ASSERT_TRUE(raw.addKeyframe(k, s.keyframes[k].stamp, 2, p.t, p.q).ok);
    if (k == c.candidate.query_index) {
      ASSERT_TRUE(raw.verify(c.candidate).accepted);
      ASSERT_TRUE(raw.commit(c.candidate).ok);
    }
  }
  // Keyframes after the anchoring loop were handed in the raw frame but stored shifted:
  // their VIO poses continue the anchored sequence smoothly.
  const std::vector<core::TrajectoryPoint> t = raw.trajectory();
  const double step_before = (t[c.candidate.query_index].vio.t - t[c.candidate.query_index - 1].vio.t).norm();
  const double step_after = (t[c.candidate.query_index + 1].vio.t - t[c.candidate.query_index].vio.t).norm();
  EXPECT_NEAR(step_after, step_before, 0.1);
  EXPECT_NEAR((t.back().estimate.t - s.keyframes[last].truth.t).norm(), 0.0, 1.0);
}

TEST(Verifier, SolverLimitsFailClosed) {
  const sim::Scene s = corridor();
  const sim::SimCandidate& c = first(s, false);
  {
    core::VerifierConfig cfg;
    cfg.metric.max_innovation = 0.0;  // reach the solver with a false candidate
    cfg.trial.max_iterations = 1;
    Verifier v(cfg);
    addUpTo(v, s, c.candidate.query_index);
    const Verdict vd = v.verify(c.candidate);
    EXPECT_FALSE(vd.accepted);
    EXPECT_EQ(vd.reason, Reason::kNotConverged) << vd.detail;
    EXPECT_FALSE(vd.converged);
  }
  {
    core::VerifierConfig cfg;
    cfg.metric.max_innovation = 0.0;
    cfg.trial.time_budget_ms = 1e-6;
    Verifier v(cfg);
    addUpTo(v, s, c.candidate.query_index);
    const Verdict vd = v.verify(c.candidate);
    EXPECT_FALSE(vd.accepted);
    EXPECT_EQ(vd.reason, Reason::kTimeBudgetExceeded) << vd.detail;
  }
}

TEST(Verifier, SolveLikeLoopFusionUsesTheCommittedLoops) {
  const sim::Scene s = corridor();
  Verifier v;
  addUpTo(v, s, static_cast<int64_t>(s.keyframes.size()) - 1);
  const std::vector<core::Pose> truth = truthUpTo(s, s.keyframes.size());
  const core::BatchSolveResult none = v.solveLikeLoopFusion(5);
  ASSERT_TRUE(none.ok);
  EXPECT_NEAR(sim::ate(none.poses, truth), sim::ate(vio(v), truth), 1e-12);
  for (const sim::SimCandidate& c : s.candidates)
    if (c.is_true) {
      ASSERT_TRUE(v.commit(c.candidate).ok);
    }
  const core::BatchSolveResult r = v.solveLikeLoopFusion(5);
  ASSERT_TRUE(r.ok) << r.message;
  EXPECT_LE(r.iterations, 5);
  EXPECT_LT(sim::ate(r.poses, truth), 0.7 * sim::ate(vio(v), truth));
}
