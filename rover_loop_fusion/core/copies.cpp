#include "rover_loop_fusion/core/copies.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

StageOutcome Copies::run(Passage* p) {
  const LoopCandidate& c = p->c;
  const PairKey key(c.query_index, c.match_index);
  std::ostringstream pair;
  pair << c.query_index << " -> " << c.match_index;
  StageOutcome out;
  if (p->in_graph) {
    p->measured = Verdict();
    out = StageOutcome::Reject(Reason::kInvalidInput, "loop " + pair.str() +
                                                          " is already in the graph: a copy of an accepted loop is "
                                                          "counted once, not accepted again");
  } else if (held_pairs_.count(key)) {
    HeldPair& held = held_pairs_[key];
    held.copies.push_back(c);
    p->measured = held.at_verify;
    out.kind = StageOutcome::Kind::kDefer;
    out.reason = Reason::kDeferred;
    out.detail = "a copy of held candidate " + pair.str() + ": counted once, decided with it (" +
                 held.at_verify.detail + ")";
  } else if (rejected_.count(key)) {
    const Verdict& rejected = rejected_[key];
    p->measured = rejected;
    out = StageOutcome::Reject(rejected.reason, "a copy of candidate " + pair.str() + ", rejected earlier: counted once (" +
                                                    rejected.detail + ")");
  } else if (revoked_.count(key)) {
    return StageOutcome::Reject(Reason::kUnconfirmed, "this loop was revoked earlier: it is not accepted again");
  } else {
    return StageOutcome::Next();
  }
  out.copy = true;
  return out;
}

void Copies::verified(const LoopCandidate& c, const Verdict& v) {
  const PairKey key(c.query_index, c.match_index);
  if (v.deferred) {
    // Held: its copies get its numbers. Decided already inside this verify() (a group it
    // completed was settled at once): a drop's copies get its numbers too.
    const auto held = held_pairs_.find(key);
    const auto rejected = rejected_.find(key);
    if (held != held_pairs_.end()) {
      held->second.at_verify = v;
    } else if (rejected != rejected_.end()) {
      Verdict r = v;
      r.deferred = false;
      r.accepted = false;
      r.reason = rejected->second.reason;
      r.detail = rejected->second.detail;
      rejected->second = r;
    }
  } else if (!v.accepted && v.reason != Reason::kInvalidInput) {
    // invalid_input is re-derived for a copy (a keyframe may have arrived since).
    rejected_[key] = v;
  }
}

void Copies::held(const LoopCandidate& c) { held_pairs_.emplace(PairKey(c.query_index, c.match_index), HeldPair()); }

void Copies::revoke(const LoopCandidate& loop) { revoked_.insert({loop.query_index, loop.match_index}); }

size_t Copies::waiting() const {
  size_t copies = 0;
  for (const auto& h : held_pairs_) copies += h.second.copies.size();
  return copies;
}

std::vector<LoopCandidate> Copies::decided(const LoopDecision& d) {
  const PairKey key(d.candidate.query_index, d.candidate.match_index);
  std::vector<LoopCandidate> copies;
  if (d.kind == LoopDecision::Kind::kRevoke) {
    const auto released = released_copies_.find(key);
    if (released == released_copies_.end()) return copies;
    copies.swap(released->second);
    released_copies_.erase(released);
    return copies;
  }
  const auto held = held_pairs_.find(key);
  if (held == held_pairs_.end()) return copies;
  copies.swap(held->second.copies);
  if (d.kind == LoopDecision::Kind::kDrop) {
    Verdict r = held->second.at_verify;  // its numbers at verify, the drop's outcome
    r.deferred = false;
    r.accepted = false;
    r.reason = d.verdict.reason;
    r.detail = d.verdict.detail;
    rejected_[key] = r;
  } else if (!copies.empty()) {
    released_copies_[key] = copies;
  }
  held_pairs_.erase(held);
  return copies;
}

}  // namespace core
}  // namespace rover_loop_fusion
