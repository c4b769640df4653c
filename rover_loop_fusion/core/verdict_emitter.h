// The one place where the verifier's verdicts leave the core: the verdict verify() returns
// (accept, reject, defer) and the later decisions (release, drop, revoke) queued for
// Verifier::takeDecisions(). It also keeps what copies of a candidate get (core/verifier.h,
// "Copies"): the verdict of a held candidate at verify and its copies, which get its later
// decision right after it; what a rejected or dropped candidate's copies get; the copies of a
// released loop, revoked with it; and the loops revoked, never accepted again.
// It decides nothing: the stages (core/verifier.cpp, core/revocation.cpp,
// core/global_release.cpp) say what the verdict is and why; the emitter writes it out.
#pragma once

#include "rover_loop_fusion/core/decision.h"
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

  // ---- the verdict of verify() (the numbers measured on the way to it, and the time since t0)
  Verdict accept(const LoopCandidate& c, std::string detail, const Verdict& measured, Clock::time_point t0,
                 Reason reason = Reason::kAccepted) const;
  Verdict reject(Reason reason, const LoopCandidate& c, std::string detail, const Verdict& measured,
                 Clock::time_point t0) const;
  /// A deferred verdict; the candidate must have been marked held().
  Verdict defer(const LoopCandidate& c, std::string detail, const Verdict& measured, Clock::time_point t0) const;
  /// A check's outcome as a verdict: accepted if it passed, else rejected for its reason.
  Verdict outcome(const Check& check, const LoopCandidate& c, const Verdict& measured, Clock::time_point t0) const;

  /// A copy of a held or rejected candidate, or (`in_graph`) of a loop in the graph: its
  /// verdict in *copy, true; false if `c` is no copy.
  bool copy(const LoopCandidate& c, bool in_graph, Clock::time_point t0, Verdict* copy);
  /// verify() returned `v` for `c`: what its later copies get.
  void verified(const LoopCandidate& c, const Verdict& v);

  // ---- later decisions (takeDecisions())
  /// `c` is held now: its copies wait for its decision.
  void held(const LoopCandidate& c);
  /// A held candidate accepted (the verifier committed it already).
  void release(const LoopCandidate& c, std::string detail);
  /// A held candidate rejected for good (reason kUnconfirmed).
  void drop(const LoopCandidate& c, std::string detail);
  /// An accepted loop removed again (reason kRevoked): never accepted again (revoked()).
  void revoke(const LoopCandidate& loop, std::string detail);
  bool revoked(const LoopCandidate& c) const;

  /// The decisions not yet taken, oldest first.
  std::vector<LoopDecision> take();
  /// Copies waiting for a held candidate's decision.
  size_t heldCopies() const;

 private:
  void decide(LoopDecision::Kind kind, const LoopCandidate& c, Verdict verdict);
  using PairKey = std::pair<int64_t, int64_t>;  ///< (query, match)
  /// A held candidate's verdict at verify and its copies, which get its decision.
  struct HeldPair {
    Verdict at_verify;
    std::vector<LoopCandidate> copies;
  };
  std::vector<LoopDecision> decisions_;  ///< not yet taken
  std::set<PairKey> revoked_;            ///< revoked loops: never again
  std::map<PairKey, HeldPair> held_pairs_;
  std::map<PairKey, std::vector<LoopCandidate>> released_copies_;  ///< revoked with their loop
  std::map<PairKey, Verdict> rejected_;  ///< rejected or dropped: what a copy gets
};

}  // namespace core
}  // namespace rover_loop_fusion
