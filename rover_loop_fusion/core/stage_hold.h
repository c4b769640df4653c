// The stage of verify() after the decision: a candidate the rule rejected for contradicting the
// graph may be held instead. As a rival (revoke_group > 0) if it contradicts accepted loops of
// its stretch (hold.confirm_stretch): a confirmed group of rivals may revoke them
// (core/revocation.cpp). Else for the global pass (global_check, decision revisit;
// core/global_release.cpp). Otherwise the rejection stands.
#pragma once

#include "rover_loop_fusion/core/accepted_loops.h"
#include "rover_loop_fusion/core/stage.h"

namespace rover_loop_fusion {
namespace core {

class HoldStage {
 public:
  HoldStage(const HoldConfig& hold, const GlobalConfig& global, Decision decision, const AcceptedLoops& loops)
      : hold_(hold), global_(global), decision_(decision), loops_(loops) {}
  /// `failed`: the rule's rejection; held (as kRival or kGlobal) or left as it is.
  StageOutcome run(const Passage& p, const StageOutcome& failed) const;

 private:
  const HoldConfig& hold_;
  const GlobalConfig& global_;
  const Decision decision_;
  const AcceptedLoops& loops_;
};

/// The rejections a later test may overturn: the candidate contradicts the graph as it is.
bool contradictsTheGraph(Reason reason);

}  // namespace core
}  // namespace rover_loop_fusion
