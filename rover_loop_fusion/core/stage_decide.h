// The stage of verify() that decides a candidate with a trajectory prior: the decision rule
// (core/decision_rule.h: the innovation gate, the trial and its score; or chi2's test in units
// of drift) and, decision revisit with revisit_extend, the extension of a revisit by its
// accepted loops (a candidate the rule rejected whose cycles with them close). Accepts (the
// rule's work kept in Passage::decided), holds (the rule says as what) or rejects for the
// failed test (which the hold stage may hold instead).
#pragma once

#include "rover_loop_fusion/core/accepted_loops.h"
#include "rover_loop_fusion/core/decision_rule.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/stage.h"

#include <string>

namespace rover_loop_fusion {
namespace core {

class DecideStage {
 public:
  /// `config`: what the rule's trial reads (runTrial) and the extension's revisit settings.
  DecideStage(const VerifierConfig& config, KeyframeGraph& graph, DecisionRule& rule, const AcceptedLoops& loops)
      : config_(config), graph_(graph), rule_(rule), loops_(loops) {}
  StageOutcome run(Passage* p) const;

 private:
  /// Whether a candidate the rule rejected for `failed` extends accepted loops of its revisit;
  /// if so, its trial is in p->decided (run here if the gate stopped it before one), *detail
  /// says why.
  bool extends(Passage* p, const Check& failed, std::string* detail) const;

  const VerifierConfig& config_;
  KeyframeGraph& graph_;
  DecisionRule& rule_;
  const AcceptedLoops& loops_;
};

}  // namespace core
}  // namespace rover_loop_fusion
