// The uncertainty of the pose graph (decision chi2), in x, y, z, yaw: the drift model's prefix
// moments per segment (core/drift.h), the covariance of a loop, of a chain of odometry and of
// one keyframe relative to another through the condensed graph (core/condensed_trial.cpp), the
// innovation of a candidate, and X := the weighted least-squares estimate of a component with
// its accepted loops (updateEstimate).
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/geometry.h"

#include <algorithm>
#include <vector>

namespace rover_loop_fusion {
namespace core {

void KeyframeGraph::Impl::extendChain(size_t pos) {
  auto it = chains.find(kfs[pos].segment);
  if (it == chains.end()) {
    it = chains.emplace(kfs[pos].segment, SequenceChain()).first;
    it->second.start = pos;
  }
  ++it->second.count;
  if (moments_used) momentsOf(it->second);
  if (unit_used) unitOf(it->second);
}

Eigen::Matrix4d KeyframeGraph::Impl::SegmentSteps::stepCovariance(size_t j) const {
  if (unit_) return unit_cov_;
  const size_t pos = start_ + j;
  const auto given = m_.step_covariance.find(pos);
  if (given != m_.step_covariance.end()) return given->second;
  return m_.drift.stepCovariance(j > 0 ? (m_.kfs[pos].vio.t - m_.kfs[pos - 1].vio.t).norm() : 0.0);
}

KeyframeGraph::Impl::ChainMomentsView KeyframeGraph::Impl::momentsOf(SequenceChain& ch) const {
  moments_used = true;
  const SegmentSteps steps(*this, ch.start, false);
  ch.moments.extend(steps, ch.count);
  return ChainMomentsView{ch.moments, steps};
}

KeyframeGraph::Impl::ChainMomentsView KeyframeGraph::Impl::unitOf(SequenceChain& ch) const {
  unit_used = true;
  const SegmentSteps steps(*this, ch.start, true);
  ch.unit.extend(steps, ch.count);
  return ChainMomentsView{ch.unit, steps};
}

void KeyframeGraph::Impl::rebuildMoments(int sequence) {
  chain_edges.clear();  // the sequence's VIO poses moved
  for (auto& kv : chains) {
    if (kfs[kv.second.start].sequence != sequence) continue;
    kv.second.moments.clear();
    kv.second.unit.clear();
  }
}

Eigen::Matrix4d KeyframeGraph::Impl::loopCovariance() const {
  Eigen::Matrix4d C = Eigen::Matrix4d::Zero();
  C(0, 0) = C(1, 1) = C(2, 2) = cfg.drift.loop_sigma * cfg.drift.loop_sigma;
  C(3, 3) = cfg.drift.loop_sigma_yaw * cfg.drift.loop_sigma_yaw;
  return C;
}

// ---------------------------------------------------------------------------------------

bool KeyframeGraph::relativeCovariance(size_t match_pos, size_t query_pos, double variance_scale,
                                   Eigen::Matrix4d* covariance, int* anchors) const {
  const Impl& m = *impl_;
  if (match_pos >= m.kfs.size() || query_pos >= m.kfs.size()) return false;
  const int comp = m.componentOf(query_pos);
  if (m.componentOf(match_pos) != comp) return false;
  CondensedGraph cg;
  std::vector<size_t> a;
  Impl::CondenseOptions options;
  options.variance_scale = variance_scale;
  if (!m.condense(comp, {match_pos, query_pos}, options, &cg, &a)) return false;
  if (anchors) *anchors = static_cast<int>(a.size());
  const int gm = static_cast<int>(std::lower_bound(a.begin(), a.end(), match_pos) - a.begin());
  const int gq = static_cast<int>(std::lower_bound(a.begin(), a.end(), query_pos) - a.begin());
  const Impl::Keyframe& km = m.kfs[match_pos];
  const Eigen::Matrix3d Rm = yawPitchRollToRotation(m.x[match_pos].yaw, km.pitch, km.roll);
  // The match is the gauge: every other anchor free, sequence 0 too (the prior map's pose is
  // known, but not relative to this match).
  for (size_t i = 0; i < a.size(); ++i) cg.setFixed(static_cast<int>(i), false);
  return cg.marginal(gm, gq, Rm, covariance);
}

Eigen::Matrix4d KeyframeGraph::loopCovariance() const { return impl_->loopCovariance(); }

void KeyframeGraph::keepMoments(bool drift_weighted, bool unit_weight) {
  Impl& m = *impl_;
  for (auto& kv : m.chains) {
    if (drift_weighted) m.momentsOf(kv.second);
    if (unit_weight) m.unitOf(kv.second);
  }
  m.moments_used = m.moments_used || drift_weighted;
  m.unit_used = m.unit_used || unit_weight;
}

bool KeyframeGraph::chainCovariance(size_t from, size_t to, double variance_scale, Eigen::Matrix4d* cov) const {
  const Impl& m = *impl_;
  if (from > to || to >= m.kfs.size() || m.kfs[from].segment != m.kfs[to].segment) return false;
  if (from == to) {
    cov->setZero();
    return true;
  }
  Impl::SequenceChain& ch = m.chains.at(m.kfs[from].segment);
  // In from's own frame: the same whether rotated by X's yaw correction or not (VIO, like the moments).
  *cov = variance_scale * m.momentsOf(ch).relative(from - ch.start, to - ch.start, m.kfs[from].vio.q.toRotationMatrix());
  return true;
}

Eigen::Vector4d KeyframeGraph::innovationVector(const LoopCandidate& c, size_t qpos, size_t mpos) const {
  const Impl& m = *impl_;
  const KeyframeState& xm = m.x[mpos];
  const KeyframeState& xq = m.x[qpos];
  const Eigen::Matrix3d Rm = m.rotationOf(xm, m.kfs[mpos]);
  const Eigen::Vector3d d(xq.t[0] - xm.t[0], xq.t[1] - xm.t[1], xq.t[2] - xm.t[2]);
  Eigen::Vector4d nu;
  nu.head<3>() = c.relative_t - Rm.transpose() * d;
  nu[3] = wrapAngle(c.relative_yaw - (xq.yaw - xm.yaw));
  return nu;
}

Status KeyframeGraph::updateEstimate(size_t position, double variance_scale) {
  Impl& m = *impl_;
  if (position >= m.kfs.size()) return Status::Error("updateEstimate: unknown position");
  const int comp = m.componentOf(position);
  CondensedGraph cg;
  std::vector<size_t> a;
  Impl::CondenseOptions options;
  options.variance_scale = variance_scale;
  if (!m.condense(comp, {}, options, &cg, &a))
    return Status::Error("updateEstimate: a covariance of the condensed graph is unusable");
  if (a.empty()) {  // no loop left (a revocation): the odometry alone, as before the first loop
    for (size_t p = 0; p < m.kfs.size(); ++p)
      if (m.componentOf(p) == comp) m.x[p] = m.stateFromPose(m.kfs[p].vio);
    return Status::Ok();
  }
  bool any_fixed = false;
  for (size_t i = 0; i < a.size(); ++i) any_fixed = any_fixed || m.kfs[a[i]].sequence == 0;
  if (!any_fixed) cg.setFixed(0, true);  // the oldest loop end holds the gauge (loop_fusion too)
  bool ok = false;
  cg.solve(10, 1e-9, &ok);
  if (!ok) return Status::Error("updateEstimate: the condensed solve failed");
  m.spread(comp, a, cg);
  return Status::Ok();
}

}  // namespace core
}  // namespace rover_loop_fusion
