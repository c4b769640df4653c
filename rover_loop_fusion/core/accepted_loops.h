// What the accepted loops of a stretch say about held candidates, against the graph as it is
// now: the cycle test of two candidates, the accepted loops of a candidate's stretch that agree
// with it or contradict it, the loops a group of rivals contradicts, and the joint test of a
// revisit hypothesis. The questions the store of held candidates asks while it works out what is
// due (HoldTests), and those revocation and the revisit extension ask; it changes nothing but
// what the decision rule's joint test solves.
#pragma once

#include "rover_loop_fusion/core/decision_rule.h"
#include "rover_loop_fusion/core/held_candidates.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/types.h"

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace core {

class AcceptedLoops : public HoldTests {
 public:
  /// Reads the graph and the rule it is given (which it must not outlive).
  AcceptedLoops(const VerifierConfig& config, const KeyframeGraph& graph, DecisionRule& rule)
      : config_(config), graph_(graph), rule_(rule) {}

  /// `c` as a held candidate: its positions, segments, arrival and revision now.
  HeldCandidate heldFor(const LoopCandidate& c) const;
  /// The accepted loops of the stretch of `h` (queries within `window` keyframes, of h's query
  /// segment) that the cycle test (along the VIO odometry) finds consistent with h within
  /// `max_residual` metres of translation (agree), and those it finds inconsistent or off by more
  /// (contradict); loops whose cycle is not one chain in neither. With `near_matches`, only
  /// loops whose match also lies within `window` keyframes of h's: the cycle test's odometry
  /// legs are then both short, as its covariance assumes.
  struct StretchLoops {
    std::vector<LoopCandidate> agree, contradict;
  };
  StretchLoops stretchLoops(const HeldCandidate& h, size_t window, bool near_matches,
                            double max_residual = std::numeric_limits<double>::infinity()) const;
  /// The accepted loops of that stretch that the cycle test finds inconsistent with h.
  std::vector<LoopCandidate> contradicted(const HeldCandidate& h, size_t window, bool near_matches = false) const;

  // HoldTests
  bool consistent(const HeldCandidate& a, const HeldCandidate& b) const override;
  /// Those of its stretch that most of its members are inconsistent with.
  std::vector<LoopCandidate> rivalTargets(const HeldGroup& group) const override;
  /// It must not contradict the accepted loops of its stretch, and must pass the rule's test
  /// against the prior.
  bool judge(const HeldGroup& group, std::string* why) override;
  double misfit(const HeldGroup& group) override { return rule_.misfit(group); }

 private:
  const VerifierConfig& config_;
  const KeyframeGraph& graph_;
  DecisionRule& rule_;
};

}  // namespace core
}  // namespace rover_loop_fusion
