#include "rover_loop_fusion/core/stage_input.h"

namespace rover_loop_fusion {
namespace core {

StageOutcome InputStage::run(Passage* p) const {
  std::string bad = graph_.checkLoop(p->c, &p->qpos, &p->mpos);
  if (!bad.empty()) return StageOutcome::Reject(Reason::kInvalidInput, std::move(bad));
  p->in_graph = graph_.hasLoop(p->c.query_index, p->c.match_index);
  return StageOutcome::Next();
}

}  // namespace core
}  // namespace rover_loop_fusion
