// Fuzzes the verifier's API with arbitrary call sequences and values: keyframes with
// duplicate, out-of-order or negative indices, NaN/inf/huge positions, position and stamp jumps
// (refused, or accepted as relocations), non-unit quaternions, stamps going backwards;
// candidates to unknown, future or the same keyframes; commits of anything. Besides crashes
// and sanitizer reports it traps on broken invariants:
//   - a refused keyframe or commit leaves the graph unchanged;
//   - verify() never changes the graph;
//   - an accepted verdict is either `accepted` (converged, score <= threshold or d2 <= gate) or
//     `no_trajectory_prior` (by policy); a rejected one never says `accepted`;
//   - every estimate stays finite, no path length is infinite.
#include "rover_loop_fusion/core/geometry.h"
#include "rover_loop_fusion/core/verifier.h"

#include <fuzzer/FuzzedDataProvider.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <vector>

using namespace rover_loop_fusion::core;

namespace {

#define CHECK(c) \
  do {           \
    if (!(c)) __builtin_trap(); \
  } while (0)

double value(FuzzedDataProvider& in, double range) {
  switch (in.ConsumeIntegralInRange<int>(0, 9)) {
    case 0: return std::numeric_limits<double>::quiet_NaN();
    case 1: return std::numeric_limits<double>::infinity();
    case 2: return -std::numeric_limits<double>::infinity();
    case 3: return in.ConsumeBool() ? 1e300 : -1e-300;
    default: return in.ConsumeFloatingPointInRange<double>(-range, range);
  }
}

Eigen::Quaterniond rotation(FuzzedDataProvider& in) {
  if (in.ConsumeIntegralInRange<int>(0, 7) == 0)  // raw, maybe not unit or not finite
    return Eigen::Quaterniond(value(in, 2), value(in, 2), value(in, 2), value(in, 2));
  const double yaw = in.ConsumeFloatingPointInRange<double>(-4, 4);
  const double tilt = in.ConsumeFloatingPointInRange<double>(-0.3, 0.3);
  return Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                            Eigen::AngleAxisd(tilt, Eigen::Vector3d::UnitX()));
}

struct Snapshot {
  size_t keyframes, loops;
  std::vector<double> values;
  bool operator==(const Snapshot& o) const {
    if (keyframes != o.keyframes || loops != o.loops || values.size() != o.values.size()) return false;
    for (size_t i = 0; i < values.size(); ++i)
      if (!(values[i] == o.values[i]) && !(std::isnan(values[i]) && std::isnan(o.values[i]))) return false;
    return true;
  }
};

Snapshot snapshot(const Verifier& v) {
  Snapshot s{v.keyframeCount(), v.loopCount(), {}};
  for (const TrajectoryPoint& p : v.trajectory()) {
    s.values.insert(s.values.end(), p.estimate.t.data(), p.estimate.t.data() + 3);
    s.values.insert(s.values.end(), p.estimate.q.coeffs().data(), p.estimate.q.coeffs().data() + 4);
    s.values.push_back(static_cast<double>(p.index));
  }
  return s;
}

LoopCandidate candidate(FuzzedDataProvider& in, const std::vector<int64_t>& known) {
  LoopCandidate c;
  auto pick = [&]() -> int64_t {
    if (known.empty() || in.ConsumeIntegralInRange<int>(0, 9) == 0)
      return in.ConsumeIntegralInRange<int64_t>(-3, 300);
    return known[in.ConsumeIntegralInRange<size_t>(0, known.size() - 1)];
  };
  c.query_index = pick();
  c.match_index = pick();
  c.relative_t = Eigen::Vector3d(value(in, 25), value(in, 25), value(in, 3));
  c.relative_q = rotation(in);
  c.relative_yaw = in.ConsumeBool() ? value(in, 1) : yawOf(c.relative_q);
  c.inliers = in.ConsumeIntegral<int>();
  return c;
}

/// Outcome counts, printed at exit when ROVER_FUZZ_STATS is set: shows that inputs reach
/// solves, accepted and rejected verdicts and commits, not only refusals.
struct Stats {
  long keyframes = 0, refused = 0, accepted = 0, rejected_by_score = 0, invalid = 0, commits = 0;
  ~Stats() {
    if (std::getenv("ROVER_FUZZ_STATS"))
      std::fprintf(stderr, "keyframes %ld refused %ld | verdicts: accepted %ld score_above %ld invalid %ld | commits %ld\n",
                   keyframes, refused, accepted, rejected_by_score, invalid, commits);
  }
} stats;

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  FuzzedDataProvider in(data, size);
  VerifierConfig cfg;
  cfg.mode = in.ConsumeBool() ? Mode::kFourDof : Mode::kSixDof;
  cfg.alignment = in.ConsumeBool() ? Alignment::kSE3 : Alignment::kSim3;
  cfg.host.accept_without_prior = in.ConsumeBool();
  cfg.trial.window_margin = in.ConsumeIntegralInRange<int>(0, 3);
  cfg.trial.odometry_neighbours = in.ConsumeIntegralInRange<int>(1, 4);
  cfg.metric.threshold_per_metre = in.ConsumeBool() ? 0.01 : 0.0;
  cfg.host.anchor_incoming_keyframes = in.ConsumeBool();
  cfg.input.max_keyframe_jump = in.ConsumeBool() ? 10.0 : 2.0;  // 2 m: segments (relocations) are frequent
  cfg.input.jump_confirmations = in.ConsumeIntegralInRange<int>(2, 4);
  cfg.trial.max_iterations = 8;      // keep one input fast
  cfg.trial.time_budget_ms = 50.0;
  Verifier v(cfg);
  CHECK(v.configError().empty());

  std::vector<int64_t> known;
  int64_t next_index = 0;
  double stamp = 0.0;
  int sequence = 1;
  for (int op = 0; op < 200 && in.remaining_bytes() > 0; ++op) {
    switch (in.ConsumeIntegralInRange<int>(0, 7)) {
      case 0: case 1: case 2: {  // keyframe
        if (known.size() >= 48) break;
        const int64_t index = next_index + in.ConsumeIntegralInRange<int64_t>(-2, 3);
        stamp += in.ConsumeBool() ? in.ConsumeFloatingPointInRange<double>(-0.2, 1.0) : value(in, 5);
        if (in.ConsumeIntegralInRange<int>(0, 15) == 0) sequence += in.ConsumeIntegralInRange<int>(-1, 1);
        const double step = 0.5;
        const Eigen::Vector3d t(step * static_cast<double>(known.size()) + value(in, 0.2),
                                in.ConsumeFloatingPointInRange<double>(-3, 3), value(in, 0.5));
        const Snapshot before = snapshot(v);
        const Status st = v.addKeyframe(index, stamp, sequence, t, rotation(in));
        (st.ok ? stats.keyframes : stats.refused)++;
        if (st.ok) {
          known.push_back(index);
          next_index = index + 1;
        } else {
          CHECK(!st.message.empty());
          CHECK(snapshot(v) == before);
        }
        break;
      }
      case 3: case 4: {  // verify
        const LoopCandidate c = candidate(in, known);
        const Snapshot before = snapshot(v);
        const Verdict vd = v.verify(c);
        CHECK(snapshot(v) == before);
        CHECK(!vd.detail.empty());
        CHECK(!std::isinf(vd.path_length));  // finite input never makes a path infinite
        if (vd.accepted) ++stats.accepted;
        if (vd.reason == Reason::kScoreAboveThreshold) ++stats.rejected_by_score;
        if (vd.reason == Reason::kInvalidInput) ++stats.invalid;
        if (vd.accepted) {
          CHECK(vd.reason == Reason::kAccepted || vd.reason == Reason::kNoTrajectoryPrior);
          // accepted by the trial (score within its threshold) or, decision chi2, by the gate
          if (vd.reason == Reason::kAccepted) CHECK(vd.converged && (vd.score <= vd.threshold || vd.d2 <= vd.gate));
        } else {
          CHECK(vd.reason != Reason::kAccepted);
        }
        if (vd.accepted && in.ConsumeBool() && v.commit(c).ok) ++stats.commits;
        break;
      }
      case 5: {  // commit whatever
        const LoopCandidate c = candidate(in, known);
        const Snapshot before = snapshot(v);
        const Status st = v.commit(c);
        if (st.ok) ++stats.commits;
        else CHECK(snapshot(v) == before);
        break;
      }
      case 6: {  // reads
        for (const TrajectoryPoint& p : v.trajectory()) {
          CHECK(p.estimate.t.allFinite());
          CHECK(p.estimate.q.coeffs().allFinite());
        }
        Pose p;
        if (!known.empty()) CHECK(v.estimate(known.back(), &p));
        CHECK(!v.estimate(-7, &p));
        break;
      }
      case 7: {
        if (in.ConsumeIntegralInRange<int>(0, 3) == 0) {
          const BatchSolveResult r = v.solveLikeLoopFusion(2);
          CHECK(r.poses.size() == v.keyframeCount());
        }
        break;
      }
    }
  }
  return 0;
}
