// Copies of a candidate (the same query -> match proposed again: loop_fusion re-detects a pair,
// a bag replayed twice, a driver that retransmits) are one piece of evidence (core/verifier.h):
// they confirm nothing, under decision metric (confirm_count of candidates without a prior) and
// decision revisit (revisit_support), and each gets what its first candidate got.
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

using namespace rover_loop_fusion;
using core::LoopCandidate;
using core::LoopDecision;
using core::Reason;
using core::Verdict;
using core::Verifier;

namespace {

bool samePair(const LoopCandidate& a, const LoopCandidate& b) {
  return a.query_index == b.query_index && a.match_index == b.match_index;
}

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

/// Two laps of the corridor, keyframes from `split` on in a second sequence in its own frame
/// (a relocation no loop ties yet); the first true candidate across the split.
struct TwoSessions {
  sim::Scene scene;
  int64_t split = 100;
  LoopCandidate across;
};

TwoSessions twoSessions() {
  sim::LapsOptions o;
  o.laps = 2;
  o.seed = 7;
  o.sigma_yaw = 0.004;
  TwoSessions t{sim::makeLapsScene(o), 100, LoopCandidate()};
  for (const sim::SimCandidate& c : t.scene.candidates)
    if (c.is_true && c.candidate.query_index > t.split && c.candidate.match_index < t.split) {
      t.across = c.candidate;
      break;
    }
  return t;
}

void addKeyframes(Verifier& v, const TwoSessions& t, int64_t from, int64_t to) {
  const core::Pose origin = t.scene.keyframes[t.split].vio;
  for (int64_t k = from; k <= to && k < static_cast<int64_t>(t.scene.keyframes.size()); ++k) {
    const sim::SimKeyframe& kf = t.scene.keyframes[k];
    const core::Pose p = k < t.split ? kf.vio : sim::relative(origin, kf.vio);
    ASSERT_TRUE(v.addKeyframe(k, kf.stamp, k < t.split ? 1 : 2, p.t, p.q).ok);
  }
}

core::VerifierConfig confirmWithoutPrior() {
  core::VerifierConfig cfg;
  cfg.trial.time_budget_ms = 0;
  cfg.host.accept_without_prior = false;
  cfg.host.confirm_without_prior = true;
  cfg.host.anchor_incoming_keyframes = true;
  return cfg;
}

}  // namespace

TEST(Copies, CopiesOfAHeldCandidateDoNotConfirmItAndAreDecidedWithIt) {
  // decision metric (the default): a candidate without a prior is held until confirm_count
  // candidates between the sessions agree. The same candidate sent confirm_count times was
  // "confirmed: 3 held candidates agree with each other (loops 204->21 .. 204->21)".
  const TwoSessions t = twoSessions();
  ASSERT_GT(t.across.query_index, t.split);
  const core::VerifierConfig cfg = confirmWithoutPrior();
  ASSERT_EQ(cfg.decision, core::Decision::kMetric);
  Verifier v(cfg);
  addKeyframes(v, t, 0, t.across.query_index);
  const int copies = cfg.hold.confirm_count;
  std::vector<Verdict> verdicts;
  for (int i = 0; i < copies; ++i) verdicts.push_back(v.verify(t.across));
  for (const Verdict& vd : verdicts) EXPECT_TRUE(vd.deferred) << vd.detail;
  for (int i = 1; i < copies; ++i) EXPECT_TRUE(has(verdicts[i].detail, "a copy of held candidate")) << verdicts[i].detail;
  EXPECT_EQ(v.heldCount(), static_cast<size_t>(copies)) << "the candidate and its copies wait for one decision";
  std::vector<LoopDecision> decisions = v.takeDecisions();
  EXPECT_TRUE(decisions.empty()) << decisions.front().verdict.detail;
  // Nothing else confirms it: it expires after confirm_window, and every copy with it.
  addKeyframes(v, t, t.across.query_index + 1, t.across.query_index + cfg.hold.confirm_window + 2);
  decisions = v.takeDecisions();
  ASSERT_EQ(decisions.size(), static_cast<size_t>(copies));
  for (const LoopDecision& d : decisions) {
    EXPECT_TRUE(samePair(d.candidate, t.across));
    EXPECT_EQ(d.kind, LoopDecision::Kind::kDrop) << d.verdict.detail;
    EXPECT_EQ(d.verdict.reason, Reason::kUnconfirmed);
    EXPECT_EQ(d.verdict.detail, decisions.front().verdict.detail) << "the same final verdict";
  }
  EXPECT_EQ(v.heldCount(), 0u);
  EXPECT_EQ(v.loopCount(), 0u);
  // A later copy gets the drop's reason, not a new hold.
  const Verdict later = v.verify(t.across);
  EXPECT_FALSE(later.deferred);
  EXPECT_EQ(later.reason, Reason::kUnconfirmed) << later.detail;
  EXPECT_TRUE(has(later.detail, "rejected earlier")) << later.detail;
  EXPECT_EQ(v.heldCount(), 0u);
}

TEST(Copies, CopiesOfAReleasedCandidateAreReleasedWithItAndACopyOfALoopInTheGraphIsRefused) {
  // Three different candidates across the sessions confirm each other; a copy of one of them,
  // sent while it is held, is released with it; a copy sent after the release is refused.
  const TwoSessions t = twoSessions();
  const core::VerifierConfig cfg = confirmWithoutPrior();
  std::vector<LoopCandidate> across;
  for (const sim::SimCandidate& c : t.scene.candidates)
    if (c.is_true && c.candidate.query_index > t.split && c.candidate.match_index < t.split &&
        (across.empty() || c.candidate.query_index > across.back().query_index))
      across.push_back(c.candidate);
  ASSERT_GE(across.size(), static_cast<size_t>(cfg.hold.confirm_count));
  across.resize(cfg.hold.confirm_count);
  Verifier v(cfg);
  std::vector<LoopDecision> decisions;
  int64_t added = -1;
  for (size_t i = 0; i < across.size(); ++i) {
    addKeyframes(v, t, added + 1, across[i].query_index);
    added = across[i].query_index;
    EXPECT_TRUE(v.verify(across[i]).deferred);
    if (i == 0) {
      EXPECT_TRUE(v.verify(across[0]).deferred) << "a copy while it is held";
    }
    for (const LoopDecision& d : v.takeDecisions()) decisions.push_back(d);
  }
  ASSERT_EQ(decisions.size(), across.size() + 1) << "the group of 3 and the copy";
  int copy_releases = 0;
  for (const LoopDecision& d : decisions) {
    EXPECT_EQ(d.kind, LoopDecision::Kind::kRelease) << d.verdict.detail;
    EXPECT_TRUE(d.verdict.accepted);
    EXPECT_TRUE(has(d.verdict.detail, "3 held candidates agree")) << d.verdict.detail;
    copy_releases += samePair(d.candidate, across[0]);
  }
  EXPECT_EQ(copy_releases, 2) << "the first candidate and its copy";
  EXPECT_TRUE(samePair(decisions[1].candidate, across[0])) << "a copy's decision comes right after its candidate's";
  EXPECT_EQ(v.loopCount(), across.size()) << "each loop once";
  const size_t solves = v.solveCount();
  const Verdict again = v.verify(across[1]);
  EXPECT_FALSE(again.accepted);
  EXPECT_FALSE(again.deferred);
  EXPECT_EQ(again.reason, Reason::kInvalidInput);
  EXPECT_TRUE(has(again.detail, "already in the graph")) << again.detail;
  EXPECT_EQ(v.solveCount(), solves) << "a copy of a loop in the graph is not verified again";
  EXPECT_TRUE(v.takeDecisions().empty());
}

TEST(Copies, ACopyOfARejectedCandidateGetsItsRejection) {
  sim::LapsOptions o;
  o.laps = 2;
  o.seed = 7;
  o.sigma_yaw = 0.004;
  const sim::Scene s = sim::makeLapsScene(o);
  core::VerifierConfig cfg;
  cfg.trial.time_budget_ms = 0;
  Verifier v(cfg);
  const LoopCandidate* rejected = nullptr;
  Verdict first;
  size_t next = 0;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index && !rejected; ++next) {
      const LoopCandidate& c = s.candidates[next].candidate;
      const Verdict vd = v.verify(c);
      if (vd.accepted) {
        ASSERT_TRUE(v.commit(c).ok);
      }
      if (!vd.accepted && !vd.deferred && vd.reason != Reason::kInvalidInput) {
        rejected = &c;
        first = vd;
      }
    }
    if (rejected) break;
  }
  ASSERT_NE(rejected, nullptr) << "the scene must hold a rejected candidate";
  const Verdict copy = v.verify(*rejected);
  EXPECT_FALSE(copy.accepted);
  EXPECT_EQ(copy.reason, first.reason) << copy.detail;
  EXPECT_TRUE(copy.score == first.score || (std::isnan(copy.score) && std::isnan(first.score))) << copy.score;
  EXPECT_TRUE(copy.d2 == first.d2 || (std::isnan(copy.d2) && std::isnan(first.d2))) << copy.d2;
  EXPECT_TRUE(has(copy.detail, "rejected earlier")) << copy.detail;
}

TEST(Copies, CopiesDoNotMakeARevisitHypothesis) {
  // decision revisit: a candidate the metric test rejects alone is held until revisit_support
  // mutually consistent candidates of its revisit form a hypothesis. The same candidate sent
  // revisit_support times made a "revisit hypothesis of 3 (loops q->m .. q->m)".
  sim::LapsOptions o;
  o.laps = 2;
  o.width = 40.0;
  o.height = 20.0;
  o.seed = 7;
  o.sigma_t = 0.01;
  o.sigma_yaw = 0.005;
  o.true_every = 3;
  o.false_every = 0;
  const sim::Scene s = sim::makeLapsScene(o);
  core::VerifierConfig cfg;
  cfg.decision = core::Decision::kRevisit;
  cfg.trial.time_budget_ms = 0;
  cfg.revisit.revisit_support = 3;
  Verifier v(cfg);
  const LoopCandidate* held = nullptr;
  int copies = 0;
  std::vector<LoopDecision> decisions;
  size_t next = 0;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    ASSERT_TRUE(v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    for (const LoopDecision& d : v.takeDecisions()) decisions.push_back(d);
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
      if (held || !s.candidates[next].is_true) continue;  // after it, its copies alone
      const LoopCandidate& c = s.candidates[next].candidate;
      const Verdict vd = v.verify(c);
      if (vd.accepted) {
        ASSERT_TRUE(v.commit(c).ok);
      }
      if (!vd.deferred) continue;
      held = &c;
      for (copies = 1; copies < cfg.revisit.revisit_support; ++copies) EXPECT_TRUE(v.verify(c).deferred);
    }
    for (const LoopDecision& d : v.takeDecisions()) decisions.push_back(d);
  }
  ASSERT_NE(held, nullptr) << "the scene must hold a candidate under decision revisit";
  std::vector<LoopDecision> its;
  for (const LoopDecision& d : decisions)
    if (samePair(d.candidate, *held)) its.push_back(d);
  ASSERT_EQ(its.size(), static_cast<size_t>(copies)) << "one decision for it and one for each copy";
  for (const LoopDecision& d : its) {
    EXPECT_EQ(d.kind, LoopDecision::Kind::kDrop) << d.verdict.detail;
    EXPECT_FALSE(has(d.verdict.detail, "hypothesis of 3")) << d.verdict.detail;
    EXPECT_TRUE(has(d.verdict.detail, "(1 of revisit_support=3 members)")) << d.verdict.detail;
    EXPECT_EQ(d.verdict.detail, its.front().verdict.detail);
  }
}
