#include "rover_loop_fusion/core/stage_decide.h"

#include "rover_loop_fusion/core/decision.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

StageOutcome DecideStage::run(Passage* p) const {
  const RuleOutcome out = rule_.decide(p->c, p->qpos, p->mpos, p->t0, &p->measured, &p->decided);
  std::string extended;
  if (!out.check.passed && !extends(p, out.check, &extended)) {
    StageOutcome failed = StageOutcome::Reject(out.check.reason, out.check.detail);
    failed.holdable = true;
    return failed;
  }
  if (out.hold) return StageOutcome::Hold(out.kind, out.check.detail, out.d2);
  // Only a loop the prior confirmed teaches the drift calibration; an extension's innovation is
  // the drift the prior ruled out, or a false row's offset.
  p->decided.calibrates = out.check.passed;
  StageOutcome accepted = StageOutcome::Accept(out.check.passed ? out.check.detail : extended);
  accepted.keep_decided = true;
  return accepted;
}

bool DecideStage::extends(Passage* p, const Check& failed, std::string* detail) const {
  const RevisitConfig& revisit = config_.revisit;
  if (config_.decision != Decision::kRevisit || revisit.revisit_extend <= 0) return false;
  if (failed.reason != Reason::kInnovationAboveBound && failed.reason != Reason::kScoreAboveThreshold) return false;
  // Both legs short (matches within the stretch too): what X made of the accepted loops plays no part.
  const AcceptedLoops::StretchLoops loops = loops_.stretchLoops(
      loops_.heldFor(p->c), static_cast<size_t>(revisit.revisit_stretch), true, revisit.revisit_extend_residual);
  if (!loops.contradict.empty() || loops.agree.size() < static_cast<size_t>(revisit.revisit_extend)) return false;
  const int agree = static_cast<int>(loops.agree.size());
  const LoopCandidate& example = loops.agree.front();
  std::ostringstream s;
  s.precision(3);
  s << std::fixed << failed.detail << "; extends " << agree << " accepted loop(s) of its revisit (e.g. "
    << example.query_index << "->" << example.match_index
    << "): their cycles along the VIO odometry close within revisit_extend_residual, none contradicts it";
  if (failed.reason == Reason::kInnovationAboveBound) {  // the gate stopped it before its trial
    runTrial(config_, graph_, p->c, p->qpos, p->mpos, -1, p->t0, &p->measured, &p->decided.solution);
    if (!p->measured.converged) return false;  // no answer from the trial: fail closed
    s << "; its trial converged (score " << p->measured.score << " m)";
  }
  *detail = s.str();
  return true;
}

}  // namespace core
}  // namespace rover_loop_fusion
