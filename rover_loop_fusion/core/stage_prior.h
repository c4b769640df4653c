// The stage of verify() after the copies: does a trajectory prior tie the candidate's keyframes
// together (KeyframeGraph::connected)? Without one, the host's policy decides (host:
// accept_without_prior, confirm_without_prior: held until hold.confirm_count agree). Both in
// sequence 0 (a loaded map, held fixed): nothing to verify.
#pragma once

#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/stage.h"

namespace rover_loop_fusion {
namespace core {

class PriorStage {
 public:
  PriorStage(const HostPolicy& host, const HoldConfig& hold, const KeyframeGraph& graph)
      : host_(host), hold_(hold), graph_(graph) {}
  StageOutcome run(const Passage& p) const;

 private:
  const HostPolicy& host_;
  const HoldConfig& hold_;  ///< confirm_count, named in the text of a hold
  const KeyframeGraph& graph_;
};

}  // namespace core
}  // namespace rover_loop_fusion
