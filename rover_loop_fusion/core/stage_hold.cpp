#include "rover_loop_fusion/core/stage_hold.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

bool contradictsTheGraph(Reason reason) {
  return reason == Reason::kInnovationAboveBound || reason == Reason::kScoreAboveThreshold ||
         reason == Reason::kInconsistentWithDrift;
}

StageOutcome HoldStage::run(const Passage& p, const StageOutcome& failed) const {
  if (!failed.holdable || !contradictsTheGraph(failed.reason)) return failed;
  if (hold_.revoke_group > 0) {
    HeldCandidate h;
    h.candidate = p.c;
    h.query_pos = p.qpos;
    h.match_pos = p.mpos;
    const std::vector<LoopCandidate> against = loops_.contradicted(h, static_cast<size_t>(hold_.confirm_stretch));
    if (!against.empty()) {
      std::ostringstream s;
      s << failed.detail << "; it contradicts " << against.size() << " accepted loop(s) of its stretch (";
      for (size_t i = 0; i < against.size() && i < 3; ++i)
        s << (i ? ", " : "") << against[i].query_index << "->" << against[i].match_index;
      s << (against.size() > 3 ? ", ..." : "") << "): held as a rival until revoke_group=" << hold_.revoke_group
        << " agree";
      return StageOutcome::Hold(HoldKind::kRival, s.str());
    }
  }
  if (global_.global_check && decision_ == Decision::kRevisit)
    return StageOutcome::Hold(HoldKind::kGlobal, failed.detail + "; held for the global pass (global_check)");
  return failed;
}

}  // namespace core
}  // namespace rover_loop_fusion
