#include "rover_loop_fusion/core/stage_prior.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

StageOutcome PriorStage::run(const Passage& p) const {
  const int qseq = graph_.sequenceAt(p.qpos), mseq = graph_.sequenceAt(p.mpos);
  if (!graph_.connected(p.qpos, p.mpos)) {
    std::ostringstream s;
    if (qseq == mseq)
      s << "keyframes " << p.c.match_index << " and " << p.c.query_index << " of sequence " << qseq
        << " lie on either side of a keyframe jump accepted as a relocation, which no loop ties yet: "
           "no trajectory prior; ";
    else
      s << "sequences " << mseq << " and " << qseq << " are not connected: no trajectory prior; ";
    if (host_.confirm_without_prior) {
      s << "held until " << hold_.confirm_count << " candidates between them agree (confirm_without_prior)";
      return StageOutcome::Hold(HoldKind::kNoPrior, s.str());
    }
    s << (host_.accept_without_prior ? "accepted by policy (accept_without_prior)"
                                     : "rejected by policy (accept_without_prior=false)");
    if (host_.accept_without_prior) return StageOutcome::Accept(s.str(), Reason::kNoTrajectoryPrior);
    return StageOutcome::Reject(Reason::kNoTrajectoryPrior, s.str());
  }
  if (qseq == 0 && mseq == 0)
    return StageOutcome::Reject(Reason::kInvalidInput,
                                "both keyframes are in sequence 0 (a loaded map, held fixed): nothing to verify");
  return StageOutcome::Next();
}

}  // namespace core
}  // namespace rover_loop_fusion
