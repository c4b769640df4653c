// The cycle test of two loops of one revisit: q_a -> m_a -> m_b -> q_b -> q_a through the two
// loops and the odometry between the matches and between the queries must close within the
// chi-square gate (gate_probability, 4 dof) of its covariance: the loops' (loop_sigma) and the
// short odometry legs' (the drift model, or the steps' own covariances, times the drift scale).
// What groups held candidates into a revisit (core/held_candidates.h) and finds the accepted
// loops a candidate contradicts (revocation, decision revisit).
#pragma once

#include "rover_loop_fusion/core/held_candidates.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/types.h"

namespace rover_loop_fusion {
namespace core {

/// 1 consistent, 0 not, -1 unknown (the odometry between them is not one chain). The odometry
/// factors are the relative poses of X, or of the VIO poses (`from_vio`: what the chain
/// covariance describes, and what false loops already accepted have not bent).
int cycleTest(const KeyframeGraph& graph, const VerifierConfig& config, double drift_scale, const HeldCandidate& a,
              const HeldCandidate& b, bool from_vio = false, double* residual_m = nullptr);

}  // namespace core
}  // namespace rover_loop_fusion
