// The sequential protocol of a host (core/verifier.h), shared by the tests of held candidates
// (test_revisit.cpp, test_global_pass.cpp): every keyframe, then its candidates in query order;
// accepted ones committed; deferred verdicts followed to their later decision (kRelease,
// kDrop), each counted once as the candidate's final outcome.
#ifndef ROVER_LOOP_FUSION_TEST_CORE_HOST_RUN_H
#define ROVER_LOOP_FUSION_TEST_CORE_HOST_RUN_H

#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace test_support {

struct HostRun {
  /// Final outcomes: accepted at verify() or released later; rejected at verify() or dropped.
  int true_accepted = 0, false_accepted = 0, true_rejected = 0, false_rejected = 0;
  int true_total = 0, false_total = 0;
  int deferred = 0, released = 0, dropped = 0;
  size_t held_at_end = 0;  ///< deferred and not decided when the keyframes ran out
  std::vector<core::LoopDecision> decisions;
  std::vector<core::Verdict> verdicts;  ///< verify()'s, in order
  std::vector<std::string> warnings;    ///< addKeyframe()'s warnings, in order
  double ate = 0.0;                     ///< of the verifier's trajectory against the truth
};

/// `candidates` (any order: verified by query, stably) through a host; is_false labels them.
/// With `out`, that verifier is used (and can be inspected afterwards).
inline HostRun runAsHost(const core::VerifierConfig& cfg, const sim::Scene& s,
                         std::vector<core::LoopCandidate> candidates,
                         const std::function<bool(const core::LoopCandidate&)>& is_false,
                         core::Verifier* out = nullptr) {
  core::Verifier local(cfg);
  core::Verifier& v = out ? *out : local;
  EXPECT_TRUE(v.configError().empty()) << v.configError();
  std::stable_sort(candidates.begin(), candidates.end(),
                   [](const core::LoopCandidate& a, const core::LoopCandidate& b) { return a.query_index < b.query_index; });
  HostRun r;
  std::set<std::pair<int64_t, int64_t>> decided;  // each held candidate decided once
  auto collect = [&]() {
    for (const core::LoopDecision& d : v.takeDecisions()) {
      EXPECT_TRUE(decided.insert({d.candidate.query_index, d.candidate.match_index}).second)
          << "decided twice: " << d.candidate.query_index << "->" << d.candidate.match_index;
      const bool f = is_false(d.candidate);
      if (d.kind == core::LoopDecision::Kind::kRelease) {
        ++r.released;
        ++(f ? r.false_accepted : r.true_accepted);
      } else if (d.kind == core::LoopDecision::Kind::kDrop) {
        ++r.dropped;
        ++(f ? r.false_rejected : r.true_rejected);
      }
      r.decisions.push_back(d);
    }
  };
  size_t next = 0;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    const core::Status added = v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q);
    EXPECT_TRUE(added.ok) << added.message;
    if (added.warning()) r.warnings.push_back(added.message);
    collect();
    for (; next < candidates.size() && candidates[next].query_index == kf.index; ++next) {
      const core::LoopCandidate& c = candidates[next];
      const bool f = is_false(c);
      ++(f ? r.false_total : r.true_total);
      const core::Verdict vd = v.verify(c);
      r.verdicts.push_back(vd);
      if (vd.accepted) {
        EXPECT_TRUE(v.commit(c).ok);
        ++(f ? r.false_accepted : r.true_accepted);
      } else if (vd.deferred) {
        ++r.deferred;
      } else {
        ++(f ? r.false_rejected : r.true_rejected);
      }
      collect();
    }
  }
  r.held_at_end = v.heldCount();
  std::vector<core::Pose> est, truth;
  for (const core::TrajectoryPoint& p : v.trajectory()) est.push_back(p.estimate);
  for (size_t i = 0; i < est.size(); ++i) truth.push_back(s.keyframes[i].truth);
  r.ate = sim::ate(est, truth);
  return r;
}

}  // namespace test_support
}  // namespace rover_loop_fusion

#endif  // ROVER_LOOP_FUSION_TEST_CORE_HOST_RUN_H
