// The first stage of verify(): is the candidate input the graph can take (both keyframes
// known, a finite relative pose, no self-loop: KeyframeGraph::checkLoop)? Finds its keyframes
// and whether the very loop is in the graph already (what the copies stage needs).
#pragma once

#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/stage.h"

namespace rover_loop_fusion {
namespace core {

class InputStage {
 public:
  explicit InputStage(const KeyframeGraph& graph) : graph_(graph) {}
  /// Rejected as invalid_input, or next with Passage::qpos, mpos and in_graph.
  StageOutcome run(Passage* p) const;

 private:
  const KeyframeGraph& graph_;
};

}  // namespace core
}  // namespace rover_loop_fusion
