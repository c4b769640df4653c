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

Verdict VerdictEmitter::verdict(const Passage& p, const StageOutcome& out) const {
  switch (out.kind) {
    case StageOutcome::Kind::kAccept: return accept(p.c, out.detail, p.measured, p.t0, out.reason);
    case StageOutcome::Kind::kDefer: return defer(p.c, out.detail, p.measured, p.t0);
    case StageOutcome::Kind::kReject:
    case StageOutcome::Kind::kNext: break;
  }
  return reject(out.reason, p.c, out.detail, p.measured, p.t0);
}

void VerdictEmitter::release(const LoopCandidate& c, std::string detail) {
  decide(LoopDecision::Kind::kRelease, c, Verdict::Accept(c, std::move(detail)));
}

void VerdictEmitter::drop(const LoopCandidate& c, std::string detail) {
  decide(LoopDecision::Kind::kDrop, c, Verdict::Reject(Reason::kUnconfirmed, c, std::move(detail)));
}

void VerdictEmitter::revoke(const LoopCandidate& loop, std::string detail) {
  copies_.revoke(loop);
  decide(LoopDecision::Kind::kRevoke, loop, Verdict::Reject(Reason::kRevoked, loop, std::move(detail)));
}

std::vector<LoopDecision> VerdictEmitter::take() {
  std::vector<LoopDecision> out;
  out.swap(decisions_);
  return out;
}

void VerdictEmitter::decide(LoopDecision::Kind kind, const LoopCandidate& c, Verdict verdict) {
  LoopDecision d;
  d.kind = kind;
  d.candidate = c;
  d.verdict = std::move(verdict);
  decisions_.push_back(d);
  // Its copies get the same decision, right after it.
  const std::vector<LoopCandidate> copies = copies_.decided(d);
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
