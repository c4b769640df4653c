// The one place where the verifier's verdicts leave the core: the verdict verify() returns
// (accept, reject, defer) and the later decisions (release, drop, revoke) queued for
// Verifier::takeDecisions(), each followed by the same decision for the candidate's copies
// (core/copies.h says which).
// It decides nothing: the stages (core/stage.h) and the store's settling (core/verifier.cpp,
// core/revocation.cpp, core/global_release.cpp) say what the verdict is and why; the emitter
// writes it out.
#pragma once

#include "rover_loop_fusion/core/copies.h"
#include "rover_loop_fusion/core/decision.h"
#include "rover_loop_fusion/core/stage.h"
#include "rover_loop_fusion/core/types.h"

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <map>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

class VerdictEmitter {
 public:
  using Clock = std::chrono::steady_clock;
  explicit VerdictEmitter(Copies& copies) : copies_(copies) {}

  /// The verdict of verify(): the last stage's outcome with the numbers of the passage.
  Verdict verdict(const Passage& p, const StageOutcome& out) const;

  // ---- the verdict of verify() (the numbers measured on the way to it, and the time since t0)
  Verdict accept(const LoopCandidate& c, std::string detail, const Verdict& measured, Clock::time_point t0,
                 Reason reason = Reason::kAccepted) const;
  Verdict reject(Reason reason, const LoopCandidate& c, std::string detail, const Verdict& measured,
                 Clock::time_point t0) const;
  /// A deferred verdict; the candidate must have been held (Copies::held()).
  Verdict defer(const LoopCandidate& c, std::string detail, const Verdict& measured, Clock::time_point t0) const;
  /// A check's outcome as a verdict: accepted if it passed, else rejected for its reason.
  Verdict outcome(const Check& check, const LoopCandidate& c, const Verdict& measured, Clock::time_point t0) const;

  // ---- later decisions (takeDecisions())
  /// A held candidate accepted (the verifier committed it already).
  void release(const LoopCandidate& c, std::string detail);
  /// A held candidate rejected for good (reason kUnconfirmed).
  void drop(const LoopCandidate& c, std::string detail);
  /// An accepted loop removed again (reason kRevoked): never accepted again (Copies::revoke()).
  void revoke(const LoopCandidate& loop, std::string detail);

  /// The decisions not yet taken, oldest first.
  std::vector<LoopDecision> take();

 private:
  void decide(LoopDecision::Kind kind, const LoopCandidate& c, Verdict verdict);
  Copies& copies_;
  std::vector<LoopDecision> decisions_;  ///< not yet taken
};

}  // namespace core
}  // namespace rover_loop_fusion
