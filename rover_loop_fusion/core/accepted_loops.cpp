#include "rover_loop_fusion/core/accepted_loops.h"

#include "rover_loop_fusion/core/cycle_test.h"

#include <map>
#include <sstream>
#include <utility>

namespace rover_loop_fusion {
namespace core {

HeldCandidate AcceptedLoops::heldFor(const LoopCandidate& c) const {
  HeldCandidate h;
  h.candidate = c;
  graph_.find(c.query_index, &h.query_pos);
  graph_.find(c.match_index, &h.match_pos);
  h.query_segment = graph_.segmentAt(h.query_pos);
  h.match_segment = graph_.segmentAt(h.match_pos);
  h.arrived = graph_.keyframeCount();
  h.revision = graph_.revision();
  return h;
}

AcceptedLoops::StretchLoops AcceptedLoops::stretchLoops(const HeldCandidate& h, size_t window, bool near_matches,
                                                        double max_residual) const {
  const size_t first = h.query_pos > window ? h.query_pos - window : 0;
  StretchLoops out;
  for (const LoopCandidate& l : graph_.loopsWithQueryIn(first, h.query_pos + window)) {
    const HeldCandidate a = heldFor(l);
    if ((near_matches && keyframeDistance(a.match_pos, h.match_pos) > window) ||
        graph_.segmentAt(a.query_pos) != graph_.segmentAt(h.query_pos))
      continue;
    // Along the VIO odometry: the accepted loops (false ones among them) have bent X.
    double residual = 0.0;
    const int r = cycleTest(graph_, config_, rule_.driftScale(), a, h, true, &residual);
    if (r == 0 || (r == 1 && !(residual <= max_residual)))
      out.contradict.push_back(l);
    else if (r == 1)
      out.agree.push_back(l);
  }
  return out;
}

std::vector<LoopCandidate> AcceptedLoops::contradicted(const HeldCandidate& h, size_t window, bool near_matches) const {
  return stretchLoops(h, window, near_matches).contradict;
}

bool AcceptedLoops::consistent(const HeldCandidate& a, const HeldCandidate& b) const {
  return cycleTest(graph_, config_, rule_.driftScale(), a, b) == 1;
}

std::vector<LoopCandidate> AcceptedLoops::rivalTargets(const HeldGroup& group) const {
  std::map<std::pair<int64_t, int64_t>, std::pair<LoopCandidate, size_t>> votes;
  for (const HeldCandidate& h : group)
    for (const LoopCandidate& l : contradicted(h, static_cast<size_t>(config_.hold.confirm_stretch))) {
      auto& v = votes[{l.query_index, l.match_index}];
      v.first = l;
      ++v.second;
    }
  std::vector<LoopCandidate> loops;
  for (const auto& kv : votes)
    if (2 * kv.second.second > group.size()) loops.push_back(kv.second.first);
  return loops;
}

bool AcceptedLoops::judge(const HeldGroup& group, std::string* why) {
  // A hypothesis that contradicts accepted loops of its stretch is not released: the accepted
  // loops passed alone or with their own revisit, and a look-alike row contradicts them. Only
  // loops whose matches lie within the stretch too: where a revisit's matches jump across the
  // start of a loop run (lap 3's first loops match lap 1's start, lap 2's last its end), the
  // VIO odometry between the matches is a whole lap, whose drift the model underrates; found
  // inside loop_fusion, where it kept a third lap from closing (docs/vins-fusion.md).
  size_t contradicting = 0;
  LoopCandidate example;
  for (const HeldCandidate& h : group) {
    const std::vector<LoopCandidate> against = contradicted(h, static_cast<size_t>(config_.revisit.revisit_stretch), true);
    if (!against.empty()) {
      ++contradicting;
      example = against.front();
    }
  }
  if (2 * contradicting > group.size()) {
    std::ostringstream s;
    s << "revisit hypothesis of " << group.size() << ": " << contradicting
      << " of its members contradict accepted loops of their stretch (e.g. " << example.query_index << "->"
      << example.match_index << ")";
    *why = s.str();
    return false;
  }
  return rule_.judge(group, why);
}

}  // namespace core
}  // namespace rover_loop_fusion
