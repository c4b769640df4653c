// What the stages of Verifier::verify() hand on (core/verifier.h): the candidate on its way
// (Passage: where it lies in the graph and the numbers measured so far) and each stage's outcome
// (StageOutcome: go on to the next stage, or the verdict and why). A stage decides and says so;
// it acts on nothing outside itself: the verifier holds what is to be held and keeps what an
// accepted candidate worked out, and the emitter writes the verdict.
#pragma once

#include "rover_loop_fusion/core/decision_rule.h"
#include "rover_loop_fusion/core/held_candidates.h"
#include "rover_loop_fusion/core/types.h"

#include <chrono>
#include <cstddef>
#include <string>
#include <utility>

namespace rover_loop_fusion {
namespace core {

/// A candidate on its way through the stages.
struct Passage {
  using Clock = std::chrono::steady_clock;
  Passage(const LoopCandidate& candidate, Clock::time_point started, double threshold)
      : c(candidate), t0(started) {
    measured.threshold = threshold;
  }
  const LoopCandidate& c;
  Clock::time_point t0;           ///< when verify() began (the time budget counts from there)
  size_t qpos = 0, mpos = 0;      ///< its query and match in the graph (input stage)
  bool in_graph = false;          ///< the very loop is in the graph already (input stage)
  Verdict measured;               ///< the numbers gathered on the way to the decision
  Decided decided;                ///< what the rule worked out, when it accepts
};

/// What a stage says: go on, or the verdict (accept, reject, defer) and why.
struct StageOutcome {
  enum class Kind { kNext, kAccept, kReject, kDefer };
  Kind kind = Kind::kNext;
  Reason reason = Reason::kAccepted;
  std::string detail;
  /// kDefer: the verifier holds the candidate as `hold` (d2: its innovation's distance, where
  /// the rule computed it); false for a copy of a held candidate, which is never held itself.
  bool held = false;
  HoldKind hold = HoldKind::kNoPrior;
  double d2 = 0.0;
  /// kReject by the decision rule: a failed test, which the hold stage may hold instead.
  bool holdable = false;
  /// kAccept by the decision rule: the verifier keeps Passage::decided for commit().
  bool keep_decided = false;
  /// A copy's verdict (the copies stage): what the first candidate's later copies get stays.
  bool copy = false;

  bool next() const { return kind == Kind::kNext; }
  static StageOutcome Next() { return StageOutcome(); }
  static StageOutcome Accept(std::string detail, Reason reason = Reason::kAccepted) {
    StageOutcome o;
    o.kind = Kind::kAccept;
    o.reason = reason;
    o.detail = std::move(detail);
    return o;
  }
  static StageOutcome Reject(Reason reason, std::string detail) {
    StageOutcome o;
    o.kind = Kind::kReject;
    o.reason = reason;
    o.detail = std::move(detail);
    return o;
  }
  static StageOutcome Hold(HoldKind kind, std::string detail, double d2 = 0.0) {
    StageOutcome o;
    o.kind = Kind::kDefer;
    o.reason = Reason::kDeferred;
    o.detail = std::move(detail);
    o.held = true;
    o.hold = kind;
    o.d2 = d2;
    return o;
  }
};

}  // namespace core
}  // namespace rover_loop_fusion
