// The copies of a candidate (core/verifier.h, "Copies"): the stage of verify() that answers a
// copy of a held, rejected or committed candidate, and a loop revoked earlier, before anything
// is tested again; and what the later copies of a candidate get: a held candidate's verdict at
// verify and its copies, which get its decision right after it (VerdictEmitter asks decided());
// what a rejected or dropped candidate's copies get; the copies of a released loop, revoked with
// it; the loops revoked, never accepted again.
#pragma once

#include "rover_loop_fusion/core/stage.h"
#include "rover_loop_fusion/core/types.h"

#include <cstddef>
#include <cstdint>
#include <map>
#include <set>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

class Copies {
 public:
  /// The stage: a copy's verdict (Passage::measured: the first candidate's numbers), a revoked
  /// loop's rejection, or next.
  StageOutcome run(Passage* p);
  /// verify() returned `v` for `c` (no copy): what its later copies get.
  void verified(const LoopCandidate& c, const Verdict& v);
  /// `c` is held now: its copies wait for its decision.
  void held(const LoopCandidate& c);
  /// Decision `d` was made: the copies that get it right after it (each gets the same decision).
  std::vector<LoopCandidate> decided(const LoopDecision& d);
  /// An accepted loop removed again: never accepted again.
  void revoke(const LoopCandidate& loop);
  /// Copies waiting for a held candidate's decision.
  size_t waiting() const;

 private:
  using PairKey = std::pair<int64_t, int64_t>;  ///< (query, match)
  /// A held candidate's verdict at verify and its copies, which get its decision.
  struct HeldPair {
    Verdict at_verify;
    std::vector<LoopCandidate> copies;
  };
  std::set<PairKey> revoked_;  ///< revoked loops: never again
  std::map<PairKey, HeldPair> held_pairs_;
  std::map<PairKey, std::vector<LoopCandidate>> released_copies_;  ///< revoked with their loop
  std::map<PairKey, Verdict> rejected_;  ///< rejected or dropped: what a copy gets
};

}  // namespace core
}  // namespace rover_loop_fusion
