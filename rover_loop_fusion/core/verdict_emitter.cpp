#include "rover_loop_fusion/core/verdict_emitter.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

const char* toString(LoopDecision::Kind kind) {
  switch (kind) {
    case LoopDecision::Kind::kRelease: return "release";
    case LoopDecision::Kind::kDrop: return "drop";
    case LoopDecision::Kind::kRevoke: return "revoke";
  }
  return "drop";
}

namespace {

/// `decided` with the numbers measured on the way to it (`measured`) and the time taken.
Verdict withNumbers(Verdict decided, const Verdict& measured, VerdictEmitter::Clock::time_point t0) {
  decided.score = measured.score;
  decided.threshold = measured.threshold;
  decided.d2 = measured.d2;
  decided.gate = measured.gate;
  decided.converged = measured.converged;
  decided.iterations = measured.iterations;
  decided.window_size = measured.window_size;
  decided.innovation = measured.innovation;
  decided.path_length = measured.path_length;
  decided.solve_ms = measured.solve_ms;
  decided.elapsed_ms =
      std::chrono::duration<double, std::milli>(VerdictEmitter::Clock::now() - t0).count();
  return decided;
}

}  // namespace

Verdict VerdictEmitter::accept(const LoopCandidate& c, std::string detail, const Verdict& measured,
                               Clock::time_point t0, Reason reason) const {
  return withNumbers(Verdict::Accept(c, std::move(detail), reason), measured, t0);
}

Verdict VerdictEmitter::reject(Reason reason, const LoopCandidate& c, std::string detail, const Verdict& measured,
                               Clock::time_point t0) const {
  return withNumbers(Verdict::Reject(reason, c, std::move(detail)), measured, t0);
}

Verdict VerdictEmitter::defer(const LoopCandidate& c, std::string detail, const Verdict& measured,
                              Clock::time_point t0) const {
  return withNumbers(Verdict::Defer(c, std::move(detail)), measured, t0);
}

Verdict VerdictEmitter::outcome(const Check& check, const LoopCandidate& c, const Verdict& measured,
                                Clock::time_point t0) const {
  return check.passed ? accept(c, check.detail, measured, t0) : reject(check.reason, c, check.detail, measured, t0);
}

bool VerdictEmitter::copy(const LoopCandidate& c, bool in_graph, Clock::time_point t0, Verdict* copy) {
  const PairKey key(c.query_index, c.match_index);
  std::ostringstream pair;
  pair << c.query_index << " -> " << c.match_index;
  if (in_graph) {
    *copy = reject(Reason::kInvalidInput, c,
                   "loop " + pair.str() + " is already in the graph: a copy of an accepted loop is "
                                          "counted once, not accepted again",
                   Verdict(), t0);
    return true;
  }
  const auto held = held_pairs_.find(key);
  if (held != held_pairs_.end()) {
    held->second.copies.push_back(c);
    *copy = defer(c, "a copy of held candidate " + pair.str() + ": counted once, decided with it (" +
                         held->second.at_verify.detail + ")",
                  held->second.at_verify, t0);
    return true;
  }
  const auto rejected = rejected_.find(key);
  if (rejected != rejected_.end()) {
    *copy = reject(rejected->second.reason, c,
                   "a copy of candidate " + pair.str() + ", rejected earlier: counted once (" +
                       rejected->second.detail + ")",
                   rejected->second, t0);
    return true;
  }
  return false;
}

void VerdictEmitter::verified(const LoopCandidate& c, const Verdict& v) {
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

void VerdictEmitter::held(const LoopCandidate& c) {
  held_pairs_.emplace(PairKey(c.query_index, c.match_index), HeldPair());
}

void VerdictEmitter::release(const LoopCandidate& c, std::string detail) {
  decide(LoopDecision::Kind::kRelease, c, Verdict::Accept(c, std::move(detail)));
}

void VerdictEmitter::drop(const LoopCandidate& c, std::string detail) {
  decide(LoopDecision::Kind::kDrop, c, Verdict::Reject(Reason::kUnconfirmed, c, std::move(detail)));
}

void VerdictEmitter::revoke(const LoopCandidate& loop, std::string detail) {
  revoked_.insert({loop.query_index, loop.match_index});
  decide(LoopDecision::Kind::kRevoke, loop, Verdict::Reject(Reason::kRevoked, loop, std::move(detail)));
}

bool VerdictEmitter::revoked(const LoopCandidate& c) const {
  return revoked_.count({c.query_index, c.match_index}) > 0;
}

std::vector<LoopDecision> VerdictEmitter::take() {
  std::vector<LoopDecision> out;
  out.swap(decisions_);
  return out;
}

size_t VerdictEmitter::heldCopies() const {
  size_t copies = 0;
  for (const auto& h : held_pairs_) copies += h.second.copies.size();
  return copies;
}

void VerdictEmitter::decide(LoopDecision::Kind kind, const LoopCandidate& c, Verdict verdict) {
  LoopDecision d;
  d.kind = kind;
  d.candidate = c;
  d.verdict = std::move(verdict);
  decisions_.push_back(d);
  // Its copies get the same decision, right after it.
  const PairKey key(c.query_index, c.match_index);
  std::vector<LoopCandidate> copies;
  if (kind == LoopDecision::Kind::kRevoke) {
    const auto released = released_copies_.find(key);
    if (released == released_copies_.end()) return;
    copies.swap(released->second);
    released_copies_.erase(released);
  } else {
    const auto held = held_pairs_.find(key);
    if (held == held_pairs_.end()) return;
    copies.swap(held->second.copies);
    if (kind == LoopDecision::Kind::kDrop) {
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
  }
  for (const LoopCandidate& copy : copies) {
    LoopDecision e = d;
    e.candidate = copy;
    e.verdict.query_index = copy.query_index;
    e.verdict.match_index = copy.match_index;
    decisions_.push_back(e);
  }
}

}  // namespace core
}  // namespace rover_loop_fusion
