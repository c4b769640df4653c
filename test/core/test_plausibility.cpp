// Faults a red team found in the core, each reproduced and pinned: one implausible
// keyframe (a huge but finite position, a stamp far in the future) must cost one keyframe, not
// the session; a real relocation or clock jump is accepted after confirmation; a loaded map
// saved out of time order keeps its keyframes; the relative yaw is checked as it is used.
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scenario_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <set>

using namespace rover_loop_fusion;
using core::Reason;
using core::Status;
using core::Verdict;
using core::Verifier;

namespace {

const Eigen::Quaterniond kI = Eigen::Quaterniond::Identity();

struct Outcome {
  int tp = 0, fp = 0, fn = 0, tn = 0, refused = 0;
  bool paths_finite = true;  ///< every computed path length is finite
  std::vector<std::string> refusals;
};

/// rover_replay's sequential protocol on a scenario, with one keyframe changed by `edit`.
template <class Edit>
Outcome replay(const std::string& scenario, int64_t edited_index, Edit edit, bool every = false) {
  sim::Scenario s;
  std::string error;
  EXPECT_TRUE(sim::loadScenario(scenario, &s, &error)) << error;
  core::VerifierConfig cfg;
  cfg.trial.time_budget_ms = 0.0;  // the verdicts must not depend on the machine's load
  Verifier v(cfg);
  Outcome o;
  size_t next = 0;
  for (sim::ScenarioKeyframe k : s.keyframes) {
    if (every || k.index == edited_index) edit(&k);
    const Status st = v.addKeyframe(k.index, k.stamp, k.sequence, k.vio.t, k.vio.q);
    if (!st.ok) {
      ++o.refused;
      o.refusals.push_back(st.message);
    }
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index <= k.index; ++next) {
      const sim::ScenarioCandidate& c = s.candidates[next];
      const Verdict vd = v.verify(c.candidate);
      if (vd.accepted) v.commit(c.candidate);
      if (std::isinf(vd.path_length)) o.paths_finite = false;
      if (c.label == 1) (vd.accepted ? o.tp : o.fn)++;
      if (c.label == 0) (vd.accepted ? o.fp : o.tn)++;
    }
  }
  return o;
}

/// rover_replay's sequential protocol on a scenario, with every keyframe passed through `edit`.
template <class Edit>
Outcome replayEdited(const std::string& scenario, Edit edit) {
  return replay(scenario, -2, edit, true);
}

/// A keyframe of the shipped corridor that no candidate names, after the first loops.
int64_t unnamedKeyframe(const std::string& scenario) {
  sim::Scenario s;
  std::string error;
  EXPECT_TRUE(sim::loadScenario(scenario, &s, &error)) << error;
  std::set<int64_t> named;
  for (const sim::ScenarioCandidate& c : s.candidates) {
    named.insert(c.candidate.query_index);
    named.insert(c.candidate.match_index);
  }
  for (int64_t k = 150;; ++k)
    if (!named.count(k)) return k;
}

/// 120 keyframes along a straight corridor (0.5 m, 1 s apart), sequence 1.
void fill(Verifier& v, int n = 120) {
  for (int k = 0; k < n; ++k) ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 1, Eigen::Vector3d(0.5 * k, 0, 0), kI).ok);
}

core::LoopCandidate loop(int64_t query, int64_t match, double dx = 0.0) {
  core::LoopCandidate c;
  c.query_index = query;
  c.match_index = match;
  c.relative_t = Eigen::Vector3d(dx, 0, 0);
  return c;
}

const std::string kCorridor = std::string(ROVER_SOURCE_DIR) + "/data/corridor";

}  // namespace

TEST(KeyframeJump, OneHugeFinitePositionCostsOneKeyframeNotTheGate) {
  // Red team: the shipped corridor with one keyframe at x += 1e155 switched the innovation gate
  // off (path length inf) and lost 35 of 40 true loops; x += 1e30 collapsed every later path
  // to 0 (28 lost). Now the keyframe is refused and nothing else changes.
  const int64_t k = unnamedKeyframe(kCorridor);
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  ASSERT_EQ(clean.refused, 0);
  for (double offset : {1e155, 1e30, 1e5, 30.0}) {
    SCOPED_TRACE(offset);
    const Outcome o = replay(kCorridor, k, [&](sim::ScenarioKeyframe* kf) { kf->vio.t.x() += offset; });
    EXPECT_EQ(o.refused, 1);
    ASSERT_EQ(o.refusals.size(), 1u);
    EXPECT_TRUE(o.refusals[0].find("max_keyframe_jump") != std::string::npos ||
                o.refusals[0].find("not a VIO pose") != std::string::npos)
        << o.refusals[0];
    EXPECT_TRUE(o.paths_finite);
    EXPECT_EQ(o.fp, 0);
    EXPECT_EQ(o.tp, clean.tp);
    EXPECT_EQ(o.tn, clean.tn);
  }
}

TEST(KeyframeJump, ARelocationStartsANewSegmentAfterConfirmations) {
  core::VerifierConfig cfg;
  cfg.host.accept_without_prior = false;
  Verifier v(cfg);
  fill(v);
  // The VIO relocates 100 m away and carries on from there.
  auto at = [](int k) { return Eigen::Vector3d(100.0 + 0.5 * k, 0, 0); };
  const Status first = v.addKeyframe(120, 130.0, 1, at(120), kI);
  EXPECT_FALSE(first.ok);
  EXPECT_NE(first.message.find("max_keyframe_jump"), std::string::npos) << first.message;
  EXPECT_NE(first.message.find("2 more consecutive keyframes"), std::string::npos) << first.message;
  const Status second = v.addKeyframe(121, 131.0, 1, at(121), kI);
  EXPECT_FALSE(second.ok);
  EXPECT_NE(second.message.find("1 more consecutive keyframe "), std::string::npos) << second.message;
  const Status third = v.addKeyframe(122, 132.0, 1, at(122), kI);
  ASSERT_TRUE(third.ok) << third.message;
  EXPECT_TRUE(third.warning());
  EXPECT_NE(third.message.find("new segment"), std::string::npos) << third.message;
  EXPECT_EQ(v.keyframeCount(), 121u);
  for (int k = 123; k < 260; ++k) {
    const Status st = v.addKeyframe(k, 10.0 + k, 1, at(k), kI);
    ASSERT_TRUE(st.ok && !st.warning()) << st.message;
  }
  // Across the jump there is no prior (policy); within the new segment candidates are scored.
  const Verdict across = v.verify(loop(200, 50));
  EXPECT_EQ(across.reason, Reason::kNoTrajectoryPrior) << across.detail;
  EXPECT_NE(across.detail.find("keyframe jump"), std::string::npos) << across.detail;
  const Verdict within = v.verify(loop(250, 130, 0.0));  // 60 m apart on a straight line: false
  EXPECT_NE(within.reason, Reason::kNoTrajectoryPrior) << within.detail;
  EXPECT_TRUE(std::isfinite(within.path_length)) << within.detail;
  EXPECT_NEAR(within.path_length, 60.0, 1e-6);
  EXPECT_FALSE(within.accepted);
  // A candidate within the new segment is solved over that segment only, whatever comes later.
  for (int k = 260; k < 270; ++k) ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 2, Eigen::Vector3d(0, 0.5 * k, 0), kI).ok);
  const Verdict solved = v.verify(loop(250, 240, 5.0));
  EXPECT_TRUE(solved.accepted) << solved.detail;
  EXPECT_EQ(solved.window_size, 20) << "keyframes 240..259 of the new segment";
  // A loop across the jump ties the segments: later candidates across it have a prior again.
  ASSERT_TRUE(v.commit(loop(200, 100, 0.0)).ok);
  const Verdict tied = v.verify(loop(201, 101, 0.0));
  EXPECT_NE(tied.reason, Reason::kNoTrajectoryPrior) << tied.detail;
  EXPECT_TRUE(std::isfinite(tied.path_length));
}

TEST(KeyframeJump, AGlitchInTheMiddleOfARunIsForgotten) {
  // A refused keyframe followed by keyframes that continue the old trajectory: the run is over,
  // the next jump needs its own confirmations.
  Verifier v;
  fill(v);
  EXPECT_FALSE(v.addKeyframe(120, 130.0, 1, Eigen::Vector3d(1e6, 0, 0), kI).ok);
  EXPECT_TRUE(v.addKeyframe(121, 131.0, 1, Eigen::Vector3d(60.5, 0, 0), kI).ok);
  EXPECT_FALSE(v.addKeyframe(122, 132.0, 1, Eigen::Vector3d(1e6 + 1, 0, 0), kI).ok);
  EXPECT_FALSE(v.addKeyframe(123, 133.0, 1, Eigen::Vector3d(1e6 + 2, 0, 0), kI).ok);
  EXPECT_TRUE(v.addKeyframe(124, 134.0, 1, Eigen::Vector3d(1e6 + 3, 0, 0), kI).warning());
}

TEST(StampJump, OneFutureStampCostsOneKeyframeNotTheSession) {
  // Red team: a keyframe stamped 4e9 s made every later keyframe "out of order" and every
  // candidate invalid_input for the rest of the session (209 keyframes of the corridor lost).
  const int64_t k = unnamedKeyframe(kCorridor);
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  const Outcome o = replay(kCorridor, k, [](sim::ScenarioKeyframe* kf) { kf->stamp = 4e9; });
  EXPECT_EQ(o.refused, 1);
  ASSERT_EQ(o.refusals.size(), 1u);
  EXPECT_NE(o.refusals[0].find("max_stamp_jump"), std::string::npos) << o.refusals[0];
  EXPECT_EQ(o.tp, clean.tp);
  EXPECT_EQ(o.fp, 0);
}

TEST(StampJump, ANewClockIsAcceptedAfterConfirmations) {
  Verifier v;
  fill(v);
  EXPECT_FALSE(v.addKeyframe(120, 1e5, 1, Eigen::Vector3d(60.0, 0, 0), kI).ok);
  EXPECT_FALSE(v.addKeyframe(121, 1e5 + 1, 1, Eigen::Vector3d(60.5, 0, 0), kI).ok);
  const Status st = v.addKeyframe(122, 1e5 + 2, 1, Eigen::Vector3d(61.0, 0, 0), kI);
  ASSERT_TRUE(st.ok) << st.message;
  EXPECT_NE(st.message.find("new clock"), std::string::npos) << st.message;
  EXPECT_TRUE(v.addKeyframe(123, 1e5 + 3, 1, Eigen::Vector3d(61.5, 0, 0), kI).ok);
  // Same segment: a candidate across the clock jump has a prior and a finite path.
  const Verdict vd = v.verify(loop(123, 20, 0.0));
  EXPECT_NE(vd.reason, Reason::kNoTrajectoryPrior) << vd.detail;
  EXPECT_TRUE(std::isfinite(vd.path_length));
}

TEST(StampJump, OneKeyframeStampedLateCostsNoKeyframe) {
  // Keyframe 100 of the corridor stamped 1000 s late (within max_stamp_jump,
  // so it is taken): the keyframes after it were "out of order" until 3 confirmed a new clock
  // (2 refused, loops into them invalid). Now the next keyframe, stamped after keyframe 99's,
  // says keyframe 100's stamp was the wrong one and nothing is refused.
  const int64_t k = unnamedKeyframe(kCorridor);
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  const Outcome o = replay(kCorridor, k, [](sim::ScenarioKeyframe* kf) { kf->stamp += 1000.0; });
  EXPECT_EQ(o.refused, 0) << (o.refusals.empty() ? "" : o.refusals[0]);
  EXPECT_EQ(o.tp, clean.tp);
  EXPECT_EQ(o.fp, 0);
  Verifier v;
  fill(v, 100);
  ASSERT_TRUE(v.addKeyframe(100, 110.0 + 1000.0, 1, Eigen::Vector3d(50.0, 0, 0), kI).ok);
  const Status next = v.addKeyframe(101, 111.0, 1, Eigen::Vector3d(50.5, 0, 0), kI);
  ASSERT_TRUE(next.ok) << next.message;
  EXPECT_NE(next.message.find("keyframe 100's stamp was wrong"), std::string::npos) << next.message;
  EXPECT_TRUE(v.addKeyframe(102, 112.0, 1, Eigen::Vector3d(51.0, 0, 0), kI).ok);
  // A stamp before both is still out of order.
  EXPECT_FALSE(v.addKeyframe(103, 105.0, 1, Eigen::Vector3d(51.5, 0, 0), kI).ok);
}

TEST(StampJump, TwoKeyframesStampedLateInARowCostNoKeyframe) {
  // Issue 45 item 4: keyframes 100 and 101 of the corridor stamped 1000 s late. The keyframe
  // after them, stamped before both, was "out of order" until 3 keyframes confirmed a new
  // clock (2 refused). Now it says that both stamps were wrong, and nothing is refused.
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  const Outcome o = replayEdited(kCorridor, [](sim::ScenarioKeyframe* kf) {
    if (kf->index == 100 || kf->index == 101) kf->stamp += 1000.0;
  });
  EXPECT_EQ(o.refused, 0) << (o.refusals.empty() ? "" : o.refusals[0]);
  EXPECT_EQ(o.tp, clean.tp);
  EXPECT_EQ(o.fp, 0);
  Verifier v;
  fill(v, 100);
  ASSERT_TRUE(v.addKeyframe(100, 110.0 + 1000.0, 1, Eigen::Vector3d(50.0, 0, 0), kI).ok);
  ASSERT_TRUE(v.addKeyframe(101, 111.0 + 1000.0, 1, Eigen::Vector3d(50.5, 0, 0), kI).ok);
  const Status next = v.addKeyframe(102, 112.0, 1, Eigen::Vector3d(51.0, 0, 0), kI);
  ASSERT_TRUE(next.ok) << next.message;
  EXPECT_NE(next.message.find("keyframes 100 .. 101's stamps were wrong"), std::string::npos) << next.message;
  EXPECT_TRUE(v.addKeyframe(103, 113.0, 1, Eigen::Vector3d(51.5, 0, 0), kI).ok);
  // A stamp between two earlier keyframes' is its own fault, not two late stamps: refused.
  Verifier u;
  fill(u, 100);
  EXPECT_FALSE(u.addKeyframe(100, 107.5, 1, Eigen::Vector3d(50.0, 0, 0), kI).ok);
  // As many late keyframes in a row as confirm a new clock are one: coming back from it is a
  // step back, confirmed the same way.
  Verifier w;
  fill(w, 100);
  for (int k = 100; k < 103; ++k)
    ASSERT_TRUE(w.addKeyframe(k, 10.0 + k + 1000.0, 1, Eigen::Vector3d(0.5 * k, 0, 0), kI).ok);
  EXPECT_FALSE(w.addKeyframe(103, 113.0, 1, Eigen::Vector3d(51.5, 0, 0), kI).ok);
}

TEST(StampJump, AGlitchOnAStoppedClockCostsNoKeyframe) {
  // Issue 45 item 5: stamps frozen from keyframe 200 of the corridor and keyframe 250 stamped
  // 1000 s late: the keyframes after it carry the frozen stamp, which is not after 250's, and
  // equal stamps never confirm a new clock: 109 keyframes refused, 12 of 31 true loops. Now the
  // keyframe after the glitch, stamped as the stopped clock reads, says 250's stamp was wrong.
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  double frozen = -1.0;
  const Outcome o = replayEdited(kCorridor, [&](sim::ScenarioKeyframe* kf) {
    if (kf->index == 200) frozen = kf->stamp;
    if (kf->index >= 200) kf->stamp = frozen;
    if (kf->index == 250) kf->stamp += 1000.0;
  });
  EXPECT_EQ(o.refused, 0) << (o.refusals.empty() ? "" : o.refusals[0]);
  EXPECT_EQ(o.tp, clean.tp);
  EXPECT_EQ(o.fp, 0);
  Verifier v;
  fill(v, 100);
  ASSERT_TRUE(v.addKeyframe(100, 109.0, 1, Eigen::Vector3d(50.0, 0, 0), kI).warning());  // the clock stopped
  ASSERT_TRUE(v.addKeyframe(101, 109.0 + 1000.0, 1, Eigen::Vector3d(50.5, 0, 0), kI).ok);
  const Status next = v.addKeyframe(102, 109.0, 1, Eigen::Vector3d(51.0, 0, 0), kI);
  ASSERT_TRUE(next.ok) << next.message;
  EXPECT_NE(next.message.find("keyframe 101's stamp was wrong"), std::string::npos) << next.message;
  const Status after = v.addKeyframe(103, 109.0, 1, Eigen::Vector3d(51.5, 0, 0), kI);
  EXPECT_TRUE(after.ok && !after.warning()) << after.message;  // still the same stopped stretch
  // A repeat of the keyframe before the glitch is still a repeat.
  Verifier w;
  fill(w, 100);
  ASSERT_TRUE(w.addKeyframe(100, 109.0 + 1000.0, 1, Eigen::Vector3d(50.0, 0, 0), kI).ok);
  EXPECT_FALSE(w.addKeyframe(101, 109.0, 1, Eigen::Vector3d(49.5, 0, 0), kI).ok);
}

TEST(StampJump, AClockThatStopsIsKeptAndARepeatedMessageIsNot) {
  // Every stamp from keyframe 200 on equal (a stalled driver) refused every
  // keyframe after it: 160 of the corridor's, recall 0.16. A pose that moves plausibly keeps
  // its keyframe (one warning for the stretch); the same stamp and the same pose is a repeat.
  const Outcome clean = replay(kCorridor, -1, [](sim::ScenarioKeyframe*) {});
  double frozen = -1.0;
  {
    sim::Scenario s;
    std::string error;
    ASSERT_TRUE(sim::loadScenario(kCorridor, &s, &error)) << error;
    Verifier v;
    int refused = 0, warnings = 0, tp = 0;
    size_t next = 0;
    for (sim::ScenarioKeyframe k : s.keyframes) {
      if (k.index == 200) frozen = k.stamp;
      if (k.index >= 200) k.stamp = frozen;
      const Status st = v.addKeyframe(k.index, k.stamp, k.sequence, k.vio.t, k.vio.q);
      refused += !st.ok;
      warnings += st.ok && st.warning();
      for (; next < s.candidates.size() && s.candidates[next].candidate.query_index <= k.index; ++next) {
        const sim::ScenarioCandidate& c = s.candidates[next];
        const Verdict vd = v.verify(c.candidate);
        if (vd.accepted) v.commit(c.candidate);
        tp += c.label == 1 && vd.accepted;
      }
    }
    EXPECT_EQ(refused, 0);
    EXPECT_EQ(warnings, 1) << "one warning for the stretch";
    EXPECT_EQ(tp, clean.tp);
  }
  Verifier v;
  fill(v, 100);
  const Status repeat = v.addKeyframe(100, 109.0, 1, Eigen::Vector3d(49.5, 0, 0), kI);
  EXPECT_FALSE(repeat.ok);
  EXPECT_NE(repeat.message.find("duplicate"), std::string::npos) << repeat.message;
  const Status stopped = v.addKeyframe(101, 109.0, 1, Eigen::Vector3d(50.0, 0, 0), kI);
  ASSERT_TRUE(stopped.ok) << stopped.message;
  EXPECT_NE(stopped.message.find("clock stopped"), std::string::npos) << stopped.message;
  const Status again = v.addKeyframe(102, 109.0, 1, Eigen::Vector3d(50.5, 0, 0), kI);
  EXPECT_TRUE(again.ok && !again.warning()) << again.message;
  // The clock goes on: a later stopped stretch is said again.
  ASSERT_TRUE(v.addKeyframe(103, 110.0, 1, Eigen::Vector3d(51.0, 0, 0), kI).ok);
  EXPECT_TRUE(v.addKeyframe(104, 110.0, 1, Eigen::Vector3d(51.5, 0, 0), kI).warning());
}

TEST(KeyframeJump, ABadFirstKeyframeIsOutvotedNotTakenAsTheReference) {
  // Keyframe 0 at x = 5e7 m became the session's reference: the keyframes
  // after it were refused, then taken as a relocation, and loops into keyframe 0 were held as
  // "no trajectory prior". Now the run that agrees with itself discredits the lone first pose:
  // loops that name it are invalid input.
  Verifier v;
  ASSERT_TRUE(v.addKeyframe(0, 10.0, 1, Eigen::Vector3d(5e7, 0, 0), kI).ok);
  EXPECT_FALSE(v.addKeyframe(1, 11.0, 1, Eigen::Vector3d(0.5, 0, 0), kI).ok);
  EXPECT_FALSE(v.addKeyframe(2, 12.0, 1, Eigen::Vector3d(1.0, 0, 0), kI).ok);
  const Status third = v.addKeyframe(3, 13.0, 1, Eigen::Vector3d(1.5, 0, 0), kI);
  ASSERT_TRUE(third.ok) << third.message;
  EXPECT_NE(third.message.find("keyframe 0, the first of sequence 1, is discredited"), std::string::npos)
      << third.message;
  for (int k = 4; k < 120; ++k) ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 1, Eigen::Vector3d(0.5 * k, 0, 0), kI).ok);
  const Verdict into = v.verify(loop(100, 0));
  EXPECT_EQ(into.reason, Reason::kInvalidInput) << into.detail;
  EXPECT_NE(into.detail.find("discredited"), std::string::npos) << into.detail;
  EXPECT_FALSE(v.commit(loop(100, 0)).ok);
  // The keyframes that outvoted it are one trajectory: a loop among them has its prior.
  const Verdict within = v.verify(loop(110, 100, 5.0));
  EXPECT_NE(within.reason, Reason::kNoTrajectoryPrior) << within.detail;
  EXPECT_TRUE(std::isfinite(within.path_length)) << within.detail;
  // A first keyframe with company is not outvoted: the later run is a relocation.
  core::VerifierConfig cfg;
  cfg.host.accept_without_prior = false;
  Verifier w(cfg);
  fill(w, 10);
  EXPECT_FALSE(w.addKeyframe(10, 20.0, 1, Eigen::Vector3d(100.0, 0, 0), kI).ok);
  EXPECT_FALSE(w.addKeyframe(11, 21.0, 1, Eigen::Vector3d(100.5, 0, 0), kI).ok);
  const Status reloc = w.addKeyframe(12, 22.0, 1, Eigen::Vector3d(101.0, 0, 0), kI);
  EXPECT_NE(reloc.message.find("new segment"), std::string::npos) << reloc.message;
  const Verdict across = w.verify(loop(12, 0, 1.0));
  EXPECT_EQ(across.reason, Reason::kNoTrajectoryPrior) << across.detail;
}

TEST(KeyframeJump, TwoBadFirstKeyframesThatAgreeAreOutvoted) {
  // Issue 45 item 6: keyframes 0 and 1 both bad (at 5e7 m, or 50 m off) and agreeing with each
  // other were not discredited: keyframes 2-3 refused, keyframe 4 started a "relocation" and
  // loops into 0 or 1 were held without a prior. The many keyframes after them agree with
  // each other: fewer first keyframes than the run that contradicts them are discredited.
  for (const double offset : {5e7, 50.0}) {
    Verifier v;
    ASSERT_TRUE(v.addKeyframe(0, 10.0, 1, Eigen::Vector3d(offset, 0, 0), kI).ok);
    ASSERT_TRUE(v.addKeyframe(1, 11.0, 1, Eigen::Vector3d(offset + 0.5, 0, 0), kI).ok);
    EXPECT_FALSE(v.addKeyframe(2, 12.0, 1, Eigen::Vector3d(1.0, 0, 0), kI).ok);
    EXPECT_FALSE(v.addKeyframe(3, 13.0, 1, Eigen::Vector3d(1.5, 0, 0), kI).ok);
    const Status third = v.addKeyframe(4, 14.0, 1, Eigen::Vector3d(2.0, 0, 0), kI);
    ASSERT_TRUE(third.ok) << third.message;
    EXPECT_NE(third.message.find("keyframes 0 .. 1, the first of sequence 1, are discredited"), std::string::npos)
        << third.message;
    for (int k = 5; k < 120; ++k) ASSERT_TRUE(v.addKeyframe(k, 10.0 + k, 1, Eigen::Vector3d(0.5 * k, 0, 0), kI).ok);
    for (const int64_t bad : {0, 1}) {
      const Verdict into = v.verify(loop(100, bad));
      EXPECT_EQ(into.reason, Reason::kInvalidInput) << offset << ": " << into.detail;
      EXPECT_NE(into.detail.find("discredited"), std::string::npos) << into.detail;
    }
    const Verdict within = v.verify(loop(110, 100, 5.0));
    EXPECT_NE(within.reason, Reason::kNoTrajectoryPrior) << within.detail;
  }
  // As many first keyframes as the run are not outvoted: the later run is a relocation.
  Verifier w;
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(w.addKeyframe(k, 10.0 + k, 1, Eigen::Vector3d(50.0 + 0.5 * k, 0, 0), kI).ok);
  EXPECT_FALSE(w.addKeyframe(3, 13.0, 1, Eigen::Vector3d(1.5, 0, 0), kI).ok);
  EXPECT_FALSE(w.addKeyframe(4, 14.0, 1, Eigen::Vector3d(2.0, 0, 0), kI).ok);
  const Status reloc = w.addKeyframe(5, 15.0, 1, Eigen::Vector3d(2.5, 0, 0), kI);
  EXPECT_NE(reloc.message.find("new segment"), std::string::npos) << reloc.message;
}

TEST(LoadedMap, KeyframesSavedOutOfTimeOrderAreKeptWithOneWarning) {
  // loop_fusion's loadPoseGraph hands every saved keyframe as sequence 0, by index: a map of
  // two sessions, the second recorded earlier, has stamps that go back. Before: every keyframe
  // after the first step back was refused, and every loop into them with it.
  Verifier v;
  int warnings = 0;
  for (int k = 0; k < 80; ++k) {
    const double stamp = k < 40 ? 5000.0 + k : 100.0 + k;  // the second session is older
    const Status st = v.addKeyframe(k, stamp, 0, Eigen::Vector3d(0.5 * k, 0, 0), kI);
    ASSERT_TRUE(st.ok) << st.message;
    if (st.warning()) {
      ++warnings;
      EXPECT_NE(st.message.find("sequence 0"), std::string::npos) << st.message;
    }
  }
  EXPECT_EQ(warnings, 1);
  EXPECT_EQ(v.keyframeCount(), 80u);
  ASSERT_TRUE(v.commit(loop(70, 10)).ok) << "a stored loop into the map";
  // A live session relocalises into the older part of the map, then is verified against it.
  for (int k = 80; k < 140; ++k)
    ASSERT_TRUE(v.addKeyframe(k, 9000.0 + k, 1, Eigen::Vector3d(0.5 * (k - 80), 0, 0), kI).ok);
  EXPECT_EQ(v.verify(loop(100, 60, 0.0)).reason, Reason::kNoTrajectoryPrior);
  ASSERT_TRUE(v.commit(loop(100, 60, 0.0)).ok);
  const Verdict vd = v.verify(loop(110, 70, 0.0));
  EXPECT_NE(vd.reason, Reason::kInvalidInput) << vd.detail;
  EXPECT_TRUE(vd.accepted) << vd.detail;
}

TEST(BadCandidate, RelativeYawIsCheckedAsItIsUsed) {
  // Red team: 20 pi was range-checked after wrapping (0) but used unwrapped, and scored.
  Verifier v;
  fill(v);
  for (double yaw : {20 * M_PI, 2 * M_PI - 0.1, -7.0}) {
    core::LoopCandidate c = loop(110, 10, 0.2);
    c.relative_yaw = yaw;
    const Verdict vd = v.verify(c);
    EXPECT_EQ(vd.reason, Reason::kInvalidInput) << yaw << ": " << vd.detail;
    EXPECT_NE(vd.detail.find("max_relative_yaw"), std::string::npos) << vd.detail;
  }
  core::LoopCandidate c = loop(110, 10, 0.2);
  c.relative_yaw = 0.1;
  EXPECT_NE(v.verify(c).reason, Reason::kInvalidInput);
}
