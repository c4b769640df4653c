// decision revisit's global pass (global_check; core/global_pass.cpp, core/global_release.cpp):
// revisits that yield a single candidate after long drift fail the per-candidate test and never
// make a revisit hypothesis; judged against every loop at once, the true ones are released and
// the look-alikes stay out; a revisit that a rival row explains as well is not released
// (global_compete). The pool is bounded (global_max_held) and a candidate waits at most
// global_window keyframes.
#include "host_run.h"

#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>
#include <string>
#include <utility>
#include <vector>

using namespace rover_loop_fusion;
using core::LoopDecision;
using core::Verdict;
using core::Verifier;

namespace {

/// Three laps of a 120 m block with yaw drift, a true candidate only every 25th revisit
/// keyframe (single-candidate revisits: no hypothesis ever has revisit_support members) and a
/// look-alike every 25th, offset by 3 m (false_offset): the metric test alone rejects most of
/// lap 2 and 3's true candidates.
sim::Scene sparseRevisits() {
  sim::LapsOptions o;
  o.laps = 3;
  o.width = 40.0;
  o.height = 20.0;
  o.seed = 11;
  o.sigma_t = 0.01;
  o.sigma_yaw = 0.005;
  o.true_every = 25;
  o.false_every = 25;
  return sim::makeLapsScene(o);
}

core::VerifierConfig config(bool global) {
  core::VerifierConfig c;
  c.decision = core::Decision::kRevisit;
  c.trial.time_budget_ms = 0;  // verdicts must not depend on the machine's load
  c.global.global_check = global;
  return c;
}

using Outcome = test_support::HostRun;

/// Every candidate of the scene through a host (host_run.h).
Outcome run(const core::VerifierConfig& cfg, const sim::Scene& s) {
  std::set<std::pair<int64_t, int64_t>> lookalikes;
  std::vector<core::LoopCandidate> all;
  for (const sim::SimCandidate& c : s.candidates) {
    all.push_back(c.candidate);
    if (!c.is_true) lookalikes.insert({c.candidate.query_index, c.candidate.match_index});
  }
  return test_support::runAsHost(cfg, s, all, [&](const core::LoopCandidate& c) {
    return lookalikes.count({c.query_index, c.match_index}) > 0;
  });
}

}  // namespace

TEST(GlobalPass, ReleasesSingleCandidateRevisitsThatThePerCandidateTestRejects) {
  const sim::Scene s = sparseRevisits();
  ASSERT_TRUE(std::is_sorted(s.candidates.begin(), s.candidates.end(), [](const sim::SimCandidate& a, const sim::SimCandidate& b) {
    return a.candidate.query_index < b.candidate.query_index;
  }));
  const Outcome without = run(config(false), s);
  const Outcome with = run(config(true), s);
  ASSERT_GE(with.true_total, 10);
  ASSERT_GE(with.false_total, 10);
  // The per-candidate test (and the revisit hypotheses) lose most of the true loops here...
  EXPECT_LT(without.true_accepted, with.true_total / 2) << "the scene no longer has the long drift this test needs";
  // ...the global pass keeps them, and no look-alike.
  EXPECT_GE(with.true_accepted, without.true_accepted + with.true_total / 3);
  EXPECT_EQ(with.false_accepted, 0);
  EXPECT_EQ(without.false_accepted, 0);
  bool said = false;
  for (const LoopDecision& d : with.decisions)
    if (d.kind == LoopDecision::Kind::kRelease && d.verdict.detail.find("global pass") != std::string::npos) said = true;
  EXPECT_TRUE(said) << "a release says it came from the global pass";
  // Every deferred verdict ends in exactly one later decision, or is still held.
  EXPECT_EQ(with.released + with.dropped + static_cast<int>(with.held_at_end), with.deferred);
}

TEST(GlobalPass, AShiftedStretchOfLookAlikesThatAgreeWithEachOtherStaysOut) {
  // Every true candidate's match moved 6 keyframes (3 m) along the track, its relative pose
  // kept: a whole revisit of look-alikes that agree with each other and with the odometry.
  sim::Scene s = sparseRevisits();
  std::vector<sim::SimCandidate> shifted;
  for (sim::SimCandidate c : s.candidates) {
    if (!c.is_true) continue;
    c.candidate.match_index += 6;
    c.is_true = false;
    shifted.push_back(c);
  }
  s.candidates = shifted;
  ASSERT_GE(s.candidates.size(), 10u);
  const Outcome off = run(config(false), s);
  const Outcome r = run(config(true), s);
  EXPECT_EQ(r.false_accepted, off.false_accepted) << "released " << r.released << " of " << r.deferred << " held";
  EXPECT_EQ(r.released, 0);
  EXPECT_GT(r.deferred, 0) << "the look-alikes were held for the global pass (and dropped)";
}

TEST(GlobalPass, ThePoolIsBoundedAndWaitsAtMostGlobalWindow) {
  const sim::Scene s = sparseRevisits();
  core::VerifierConfig cfg = config(true);
  cfg.global.global_max_held = 2;
  cfg.global.global_period = 100;  // between two passes more candidates arrive than the pool holds
  cfg.global.global_window = 1;    // at a pass, everything that is not released has waited too long
  cfg.global.global_max_sigma = 1e-6;  // nothing is pinned down this tightly: nothing released
  cfg.revisit.revisit_support = 100;   // no revisit hypothesis is released: each goes to the pool
  cfg.revisit.revisit_window = 1;      // at the next keyframe
  const Outcome r = run(cfg, s);
  EXPECT_EQ(r.released, 0);
  EXPECT_EQ(r.false_accepted, 0);
  // The pool's 2, and at most the candidates of the last keyframe still in a revisit hypothesis.
  EXPECT_LE(r.held_at_end, 3u);
  bool full = false, expired = false;
  for (const LoopDecision& d : r.decisions) {
    EXPECT_EQ(d.kind, LoopDecision::Kind::kDrop);
    EXPECT_EQ(d.verdict.reason, core::Reason::kUnconfirmed);
    full = full || d.verdict.detail.find("global_max_held") != std::string::npos;
    expired = expired || d.verdict.detail.find("global_window") != std::string::npos;
  }
  EXPECT_TRUE(full) << "a full pool drops its oldest candidate and says so";
  EXPECT_TRUE(expired) << "a candidate not released within global_window is dropped and says so";
  EXPECT_EQ(r.dropped + static_cast<int>(r.held_at_end), r.deferred);
}

TEST(GlobalPass, APassOverGlobalBudgetMsReleasesNothingAndSaysSo) {
  // A pass runs on keyframe arrival (loop_fusion's thread); global_budget_ms bounds it. A budget
  // no pass can meet: nothing is released, the keyframes that ran a pass warn, and a candidate
  // that waited out global_window says why. The same run with a budget every pass meets
  // releases: the budget, nothing else, stopped it.
  const sim::Scene s = sparseRevisits();
  core::VerifierConfig bounded = config(true);
  bounded.trial.time_budget_ms = 60000;            // budgets on, no trial anywhere near its own
  bounded.revisit.revisit_retest_budget_ms = 0.0;  // the re-tests as in the runs without budgets
  bounded.global.global_window = 60;
  bounded.global.global_budget_ms = 1e-6;
  const Outcome stopped = run(bounded, s);
  const Outcome off = run(config(false), s);
  core::VerifierConfig generous = bounded;
  generous.global.global_budget_ms = 1e6;
  const Outcome passed = run(generous, s);

  EXPECT_EQ(stopped.true_accepted, off.true_accepted);
  EXPECT_EQ(stopped.false_accepted, off.false_accepted);
  for (const LoopDecision& d : stopped.decisions)
    EXPECT_FALSE(d.kind == LoopDecision::Kind::kRelease && d.verdict.detail.find("global pass") != std::string::npos)
        << d.verdict.detail;
  ASSERT_FALSE(stopped.warnings.empty()) << "a keyframe whose pass was stopped warns the host";
  for (const std::string& w : stopped.warnings)  // the budget as set, not rounded to "0.0" (0 means no bound)
    EXPECT_NE(w.find("global_budget_ms=1e-06)"), std::string::npos) << w;
  bool said = false;
  for (const LoopDecision& d : stopped.decisions)
    said = said || d.verdict.detail.find("stopped after global_budget_ms=1e-06 ms") != std::string::npos;
  EXPECT_TRUE(said) << "a candidate that waited out global_window says the budget stopped the last pass";

  EXPECT_TRUE(passed.warnings.empty()) << passed.warnings.front();
  EXPECT_GT(passed.true_accepted, off.true_accepted) << "the same passes within their budget release";
  EXPECT_EQ(passed.false_accepted, 0);
}

TEST(GlobalPass, OffByDefaultAndOnlyUnderDecisionRevisit) {
  EXPECT_FALSE(core::VerifierConfig().global.global_check);
  const sim::Scene s = sparseRevisits();
  core::VerifierConfig metric = config(true);
  metric.decision = core::Decision::kMetric;
  const Outcome r = run(metric, s);
  EXPECT_EQ(r.deferred, 0) << "decision metric holds nothing for the global pass";
}

TEST(GlobalPass, ARevisitThatARivalRowExplainsAsWellIsNotReleased) {
  // Beside every true candidate a rival for the same query, its match one keyframe (0.5 m)
  // along the track with the true relative pose: two rows of one revisit, each consistent with
  // itself and with the odometry, closer than the prior can tell apart.
  sim::Scene s = sparseRevisits();
  std::vector<sim::SimCandidate> both;
  for (const sim::SimCandidate& c : s.candidates) {
    if (!c.is_true) continue;
    both.push_back(c);
    sim::SimCandidate r = c;
    r.candidate.match_index += 1;
    r.is_true = false;
    both.push_back(r);
  }
  s.candidates = both;
  core::VerifierConfig cfg = config(true);
  cfg.global.global_window = 200;  // the ambiguous ones are dropped within the run, saying why
  core::VerifierConfig off = cfg;
  off.global.global_compete = false;
  const Outcome first = run(off, s);
  const Outcome r = run(cfg, s);
  auto falseReleases = [&](const Outcome& o) {
    int n = 0;
    for (const LoopDecision& d : o.decisions)
      if (d.kind == LoopDecision::Kind::kRelease) {
        for (const sim::SimCandidate& c : s.candidates)
          if (!c.is_true && c.candidate.query_index == d.candidate.query_index &&
              c.candidate.match_index == d.candidate.match_index)
            ++n;
      }
    return n;
  };
  ASSERT_GE(first.released, 2) << "without competition the pass releases one of the rows";
  // With it, a revisit whose rival row passes every test once it is gone is held, then dropped
  // saying so, and fewer look-alikes get in (the ones that do come through the per-candidate
  // test after a release).
  EXPECT_LT(r.released, first.released);
  EXPECT_LT(r.false_accepted, first.false_accepted);
  EXPECT_EQ(falseReleases(r), 0);
  int ambiguous = 0;
  for (const LoopDecision& d : r.decisions)
    if (d.kind == LoopDecision::Kind::kDrop && d.verdict.detail.find("ambiguous") != std::string::npos &&
        d.verdict.detail.find("rival loop") != std::string::npos)
      ++ambiguous;
  EXPECT_GE(ambiguous, 2) << "a dropped candidate names the rival that made its revisit ambiguous";
  EXPECT_EQ(r.released + r.dropped + static_cast<int>(r.held_at_end), r.deferred);
}
