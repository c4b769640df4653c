// The verifier is called from loop_fusion's keyframe thread while other threads (ROS
// callbacks, an optimisation thread, tools) read it. Every public method takes the internal
// mutex; this stress test mixes them from several threads. Under ThreadSanitizer
// (-DROVER_TSAN=ON, docs/testing.md) it shows no data race; in the normal and the ASan
// builds it checks the results stay consistent.
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

using namespace rover_loop_fusion;

TEST(Concurrency, KeyframeThreadWithReadersAndVerifiers) {
  sim::LapsOptions o;
  o.laps = 2;
  const sim::Scene s = sim::makeLapsScene(o);
  core::VerifierConfig cfg;
  cfg.trial.max_iterations = 10;
  core::Verifier v(cfg);
  std::atomic<bool> done(false);
  std::atomic<int> verdicts(0), bad(0);

  // The keyframe thread: keyframes in order, each candidate verified and committed if
  // accepted, as the loop_fusion patch does.
  std::thread keyframes([&] {
    size_t next = 0;
    for (const sim::SimKeyframe& kf : s.keyframes) {
      if (!v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok) ++bad;
      for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
        const core::Verdict vd = v.verify(s.candidates[next].candidate);
        ++verdicts;
        if (vd.accepted && !v.commit(s.candidates[next].candidate).ok) ++bad;
      }
    }
    done = true;
  });
  // Readers: what a ROS callback or a visualisation thread would ask for.
  auto reader = [&] {
    while (!done) {
      const std::vector<core::TrajectoryPoint> t = v.trajectory();
      for (size_t i = 1; i < t.size(); ++i)
        if (t[i].index <= t[i - 1].index || !t[i].estimate.t.allFinite()) ++bad;
      core::Pose p;
      if (!t.empty() && !v.estimate(t.back().index, &p)) ++bad;
      (void)v.keyframeCount();
      (void)v.loopCount();
    }
  };
  // Another thread verifying (never committing) the candidates it can already see, and one
  // running loop_fusion's batch optimisation now and then.
  std::thread verifier([&] {
    while (!done) {
      for (const sim::SimCandidate& c : s.candidates) {
        if (!v.hasKeyframe(c.candidate.query_index)) break;
        const core::Verdict vd = v.verify(c.candidate);
        if (vd.accepted && vd.reason != core::Reason::kAccepted) ++bad;
      }
    }
  });
  std::thread batch([&] {
    while (!done) {
      const core::BatchSolveResult r = v.solveLikeLoopFusion(2);
      if (!r.ok || r.poses.size() > v.keyframeCount()) ++bad;
    }
  });
  std::thread r1(reader), r2(reader);
  keyframes.join();
  verifier.join();
  batch.join();
  r1.join();
  r2.join();
  EXPECT_EQ(bad.load(), 0);
  EXPECT_EQ(v.keyframeCount(), s.keyframes.size());
  EXPECT_EQ(verdicts.load(), static_cast<int>(s.candidates.size()));
  EXPECT_GT(v.loopCount(), 0u);
}
