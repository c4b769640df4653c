// loop_fusion's own batch solve of the pose graph (KeyframeGraph::solveLikeLoopFusion), as
// optimize4DoF / optimize6DoF: every keyframe from the earliest loop's match on, initialised
// from the VIO poses, committed loops with the Huber loss, no time budget. What rover_replay
// and rover_verifier_node report as the trajectory loop_fusion would give.
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include <algorithm>

namespace rover_loop_fusion {
namespace core {

BatchSolveResult KeyframeGraph::solveLikeLoopFusion(int max_iterations) const {
  Impl& m = *impl_;
  BatchSolveResult r;
  r.poses.resize(m.kfs.size());
  for (size_t p = 0; p < m.kfs.size(); ++p) r.poses[p] = m.kfs[p].vio;
  if (m.loops.empty()) {
    r.ok = true;
    r.message = "no loops: the VIO trajectory";
    return r;
  }
  size_t first = m.kfs.size();
  for (const Impl::Edge& e : m.loops) first = std::min(first, e.from);
  Impl::Trial tr;
  m.buildTrial(tr, first, kEverySegment, true, {}, nullptr);
  const SolveSummary o = m.solve(tr, max_iterations, 0.0, Clock::now());
  r.iterations = o.iterations;
  r.solve_ms = o.solve_ms;
  r.free_keyframes = static_cast<int>(tr.positions.size());
  r.message = o.message;
  r.ok = o.finite;
  if (!r.ok) return r;
  for (size_t i = 0; i < tr.positions.size(); ++i)
    r.poses[tr.positions[i]] = m.poseFromState(tr.states[i], m.kfs[tr.positions[i]]);
  return r;
}

}  // namespace core
}  // namespace rover_loop_fusion
