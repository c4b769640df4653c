// The pose graph itself (core/pose_graph.h): keyframe lookup, keyframe states and poses
// (4-DoF: yaw + t; 6-DoF: q + t) and rigid corrections between them, the Ceres cost of an
// edge, loops (checks, loop_fusion's first-loop anchoring of a sequence, removal), the
// estimate X, the innovation of a candidate and odometry path lengths. The rest of
// KeyframeGraph, by concern (the state they share: core/pose_graph_impl.h):
// keyframe_intake.cpp, trial_solve.cpp, condensed_trial.cpp, graph_uncertainty.cpp,
// batch_solve.cpp.
#include "rover_loop_fusion/core/pose_graph.h"

#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/geometry.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

bool KeyframeGraph::Impl::find(int64_t index, size_t* pos) const {
  auto it = std::lower_bound(kfs.begin(), kfs.end(), index,
                             [](const Keyframe& k, int64_t i) { return k.index < i; });
  if (it == kfs.end() || it->index != index) return false;
  *pos = static_cast<size_t>(it - kfs.begin());
  return true;
}

KeyframeState KeyframeGraph::Impl::stateFromPose(const Pose& p) const {
  KeyframeState s;
  for (int k = 0; k < 3; ++k) s.t[k] = p.t[k];
  s.yaw = rotationToYawPitchRoll(p.q.toRotationMatrix())[0];
  const Eigen::Quaterniond q = p.q.normalized();
  s.q[0] = q.w();
  s.q[1] = q.x();
  s.q[2] = q.y();
  s.q[3] = q.z();
  return s;
}

Pose KeyframeGraph::Impl::poseFromState(const KeyframeState& s, const Keyframe& kf) const {
  Pose p;
  p.t = Eigen::Vector3d(s.t[0], s.t[1], s.t[2]);
  if (fourDof()) {
    p.q = Eigen::Quaterniond(yawPitchRollToRotation(s.yaw, kf.pitch, kf.roll));
  } else {
    p.q = Eigen::Quaterniond(s.q[0], s.q[1], s.q[2], s.q[3]).normalized();
  }
  return p;
}

Eigen::Matrix3d KeyframeGraph::Impl::rotationOf(const KeyframeState& s, const Keyframe& kf) const {
  return poseFromState(s, kf).q.toRotationMatrix();
}

Correction KeyframeGraph::Impl::correctionBetween(const KeyframeState& before, const KeyframeState& after,
                                              const Keyframe& kf) const {
  Correction c;
  if (fourDof()) {
    c.yaw = wrapAngle(after.yaw - before.yaw);
    c.R = yawPitchRollToRotation(c.yaw, 0, 0);
  } else {
    c.R = rotationOf(after, kf) * rotationOf(before, kf).transpose();
  }
  const Eigen::Vector3d tb(before.t[0], before.t[1], before.t[2]);
  const Eigen::Vector3d ta(after.t[0], after.t[1], after.t[2]);
  c.t = ta - c.R * tb;
  return c;
}

KeyframeState KeyframeGraph::Impl::applyCorrection(const Correction& c, const KeyframeState& s,
                                               const Keyframe& kf) const {
  KeyframeState o = s;
  const Eigen::Vector3d t = c.R * Eigen::Vector3d(s.t[0], s.t[1], s.t[2]) + c.t;
  for (int k = 0; k < 3; ++k) o.t[k] = t[k];
  if (fourDof()) {
    o.yaw = wrapAngle(s.yaw + c.yaw);
  } else {
    const Eigen::Quaterniond q(c.R * rotationOf(s, kf));
    o.q[0] = q.w();
    o.q[1] = q.x();
    o.q[2] = q.y();
    o.q[3] = q.z();
    o.yaw = rotationToYawPitchRoll(q.toRotationMatrix())[0];
  }
  return o;
}

void KeyframeGraph::Impl::setYaw(KeyframeState& s, double yaw) const {
  if (!fourDof()) {
    const Eigen::Quaterniond q = (Eigen::AngleAxisd(wrapAngle(yaw - s.yaw), Eigen::Vector3d::UnitZ()) *
                                  Eigen::Quaterniond(s.q[0], s.q[1], s.q[2], s.q[3]))
                                     .normalized();
    s.q[0] = q.w();
    s.q[1] = q.x();
    s.q[2] = q.y();
    s.q[3] = q.z();
  }
  s.yaw = yaw;
}

Pose KeyframeGraph::Impl::applyCorrection(const Correction& c, const Pose& p) const {
  return Pose(c.R * p.t + c.t, Eigen::Quaterniond(c.R * p.q.toRotationMatrix()));
}

void KeyframeGraph::Impl::setYawPitchRoll(Keyframe& kf) const {
  const Eigen::Vector3d ypr = rotationToYawPitchRoll(kf.vio.q.toRotationMatrix());
  kf.yaw = ypr[0];
  kf.pitch = ypr[1];
  kf.roll = ypr[2];
}

std::shared_ptr<ceres::CostFunction> KeyframeGraph::Impl::edgeCost(const Eigen::Vector3d& t_ij,
                                                               double yaw_ij,
                                                               const Eigen::Quaterniond& q_ij, const Keyframe& from,
                                                               double yaw_weight, const Matrix6d* information) const {
  if (fourDof()) {
    Eigen::Matrix4d L = Eigen::Matrix4d::Identity();
    if (information) sqrtInformation<4>(information->topLeftCorner<4, 4>(), &L);
    return std::make_shared<FourDofEdgeCost>(t_ij, yaw_ij, from.pitch, from.roll, yaw_weight, &L);
  }
  Matrix6d L = Matrix6d::Identity();
  if (information) sqrtInformation<6>(*information, &L);
  return std::shared_ptr<ceres::CostFunction>(
      SixDofEdgeError::create(t_ij, q_ij, kSixDofTranslationSigma, kSixDofRotationSigma, &L));
}

KeyframeGraph::Impl::OdometryEdge KeyframeGraph::Impl::odometryEdge(size_t from, size_t to) const {
  const Keyframe& a = kfs[from];
  const Keyframe& b = kfs[to];
  OdometryEdge e;
  e.from = from;
  e.to = to;
  Eigen::Map<Eigen::Vector3d>(e.t) = a.vio.q.conjugate() * (b.vio.t - a.vio.t);
  if (fourDof()) {
    e.r[0] = wrapAngle(b.yaw - a.yaw);
    e.r[1] = a.pitch;
    e.r[2] = a.roll;
    e.r[3] = 0.0;
  } else {
    Eigen::Map<Eigen::Vector4d>(e.r) = (a.vio.q.conjugate() * b.vio.q).coeffs();
  }
  return e;
}

std::shared_ptr<ceres::CostFunction> KeyframeGraph::Impl::odometryCost(const OdometryEdge& e) const {
  const Eigen::Vector3d t(e.t[0], e.t[1], e.t[2]);
  // 4-DoF: the older keyframe's pitch and roll as stored, not as kfs holds them now.
  if (fourDof()) return std::make_shared<FourDofEdgeCost>(t, e.r[0], e.r[1], e.r[2], 1.0);
  Eigen::Quaterniond q;
  q.coeffs() = Eigen::Map<const Eigen::Vector4d>(e.r);
  return edgeCost(t, 0.0, q, kfs[e.from], 1.0, nullptr);  // 6-DoF: the keyframe is not read
}

void KeyframeGraph::Impl::setLoopCost(Edge& e) const {
  const LoopCandidate& c = e.loop;
  e.cost = edgeCost(c.relative_t, c.relative_yaw, c.relative_q.normalized(), kfs[e.from], kLoopYawWeight,
                    e.information.get());
}

std::string KeyframeGraph::Impl::checkLoop(const LoopCandidate& c, size_t* qpos, size_t* mpos) const {
  if (c.query_index < 0 || c.match_index < 0) return "negative keyframe index";
  if (c.query_index == c.match_index) return "loop from keyframe " + describeIndex(c.query_index) + " to itself";
  if (!find(c.query_index, qpos)) return "unknown query keyframe " + describeIndex(c.query_index);
  if (!find(c.match_index, mpos)) return "unknown match keyframe " + describeIndex(c.match_index);
  for (size_t pos : {*qpos, *mpos}) {
    auto bad = discredited.find(pos);
    if (bad != discredited.end()) return "keyframe " + describeIndex(kfs[pos].index) + " was discredited: " + bad->second;
  }
  if (c.match_index > c.query_index)
    return "match keyframe " + describeIndex(c.match_index) + " is newer than query keyframe " +
           describeIndex(c.query_index);
  if (!c.relative_t.allFinite() || !std::isfinite(c.relative_yaw))
    return "relative pose is not finite";
  if (!unitQuaternion(c.relative_q, cfg.input.quaternion_tolerance))
    return "relative rotation is not a unit quaternion";
  if (c.relative_t.norm() > cfg.input.max_relative_translation) {
    std::ostringstream s;
    s << "relative translation " << c.relative_t.norm() << " m exceeds max_relative_translation "
      << cfg.input.max_relative_translation << " m";
    return s.str();
  }
  // The yaw as handed in is what the loop edge uses: checked unwrapped (20 pi is not 0).
  if (!(std::abs(c.relative_yaw) <= cfg.input.max_relative_yaw)) {
    std::ostringstream s;
    s << "relative yaw " << c.relative_yaw * 180.0 / M_PI << " deg exceeds max_relative_yaw "
      << cfg.input.max_relative_yaw * 180.0 / M_PI << " deg";
    return s.str();
  }
  return std::string();
}

double KeyframeGraph::Impl::innovation(const LoopCandidate& c, size_t qpos, size_t mpos) const {
  const Pose q = poseFromState(x[qpos], kfs[qpos]);
  const Pose m = poseFromState(x[mpos], kfs[mpos]);
  return (m.q.conjugate() * (q.t - m.t) - c.relative_t).norm();
}

bool KeyframeGraph::Impl::loopEndBefore(size_t pos, size_t* end) const {
  const auto it = loop_ends.lower_bound(pos);
  if (it == loop_ends.begin()) return false;
  *end = std::prev(it)->first;
  return kfs[*end].segment == kfs[pos].segment;  // a segment's keyframes are contiguous
}

bool KeyframeGraph::Impl::loopEndAfter(size_t pos, size_t* end) const {
  const auto it = loop_ends.upper_bound(pos);
  if (it == loop_ends.end()) return false;
  *end = it->first;
  return kfs[*end].segment == kfs[pos].segment;
}

double KeyframeGraph::Impl::pathLength(size_t from, size_t to) const {
  if (from == to) return 0.0;
  if (places_stale) rebuildPlaces();
  // Along the segment, if they share one (a stretch of odometry with no loop taken).
  double best = kfs[from].segment == kfs[to].segment ? std::abs(arc[to] - arc[from])
                                                     : std::numeric_limits<double>::infinity();
  // Else (or shorter) through the loops: from one of from's nearest loop ends (itself if it is
  // one) to one of to's.
  auto ends = [&](size_t p) {
    std::vector<std::pair<size_t, double>> out;
    size_t e = 0;
    if (loop_ends.count(p)) {
      out.emplace_back(p, 0.0);
    } else {
      if (loopEndBefore(p, &e)) out.emplace_back(e, arc[p] - arc[e]);
      if (loopEndAfter(p, &e)) out.emplace_back(e, arc[e] - arc[p]);
    }
    return out;
  };
  const auto sources = ends(from);
  if (sources.empty()) return best;
  return places.shortest(sources, ends(to), best);
}

void KeyframeGraph::Impl::addPlaceStretches(size_t pos) const {
  size_t e = 0;
  if (loopEndBefore(pos, &e)) places.addStretch(e, pos, arc[pos] - arc[e]);
  if (loopEndAfter(pos, &e)) places.addStretch(pos, e, arc[e] - arc[pos]);
}

void KeyframeGraph::Impl::rebuildPlaces() const {
  places.clear();
  for (auto it = loop_ends.begin(); it != loop_ends.end(); ++it) {
    if (it != loop_ends.begin()) {
      const size_t before = std::prev(it)->first;
      if (kfs[before].segment == kfs[it->first].segment)
        places.addStretch(before, it->first, arc[it->first] - arc[before]);
    }
    for (const LoopEnd& e : it->second)
      if (e.is_from) places.join(it->first, e.other);
  }
  places_stale = false;
}

void KeyframeGraph::Impl::indexLoop(size_t from, size_t to) {
  for (size_t end : {from, to}) {
    // A new loop end splits the stretch it lies on; the whole stretch stays in `places` (a
    // real path, never shorter than its two parts).
    if (!places_stale && loop_ends.count(end) == 0) addPlaceStretches(end);
    loop_ends[end].push_back(end == from ? LoopEnd{to, true} : LoopEnd{from, false});
  }
  if (!places_stale) places.join(from, to);
}

void KeyframeGraph::Impl::unindexLoop(size_t from, size_t to) {
  auto drop = [&](size_t at, LoopEnd end) {
    const auto it = loop_ends.find(at);
    if (it == loop_ends.end()) return;
    std::vector<LoopEnd>& v = it->second;
    const auto e = std::find_if(v.begin(), v.end(), [&](const LoopEnd& x) {
      return x.other == end.other && x.is_from == end.is_from;
    });
    if (e != v.end()) v.erase(e);
    if (v.empty()) loop_ends.erase(it);
  };
  drop(from, {to, true});
  drop(to, {from, false});
  places_stale = true;  // the loop may have been all that made two ends one place
}

void KeyframeGraph::Impl::anchorSequence(const LoopCandidate& c, size_t qpos, size_t mpos) {
  const Keyframe& old_kf = kfs[mpos];
  const Keyframe& cur = kfs[qpos];
  const Eigen::Matrix3d w_R_old = old_kf.vio.q.toRotationMatrix();
  const Eigen::Vector3d w_P_cur = w_R_old * c.relative_t + old_kf.vio.t;
  const Eigen::Matrix3d w_R_cur = w_R_old * c.relative_q.normalized().toRotationMatrix();
  const Eigen::Matrix3d vio_R_cur = cur.vio.q.toRotationMatrix();
  Correction shift;
  if (fourDof()) {
    shift.yaw = wrapAngle(rotationToYawPitchRoll(w_R_cur)[0] - cur.yaw);
    shift.R = yawPitchRollToRotation(shift.yaw, 0, 0);
  } else {
    shift.R = w_R_cur * vio_R_cur.transpose();
  }
  // As loop_fusion: shift_t = w_P_cur - w_R_cur * vio_R_cur^T * vio_P_cur.
  shift.t = w_P_cur - w_R_cur * vio_R_cur.transpose() * cur.vio.t;
  const int seq = cur.sequence;
  for (size_t p = 0; p < kfs.size(); ++p) {
    if (kfs[p].sequence != seq) continue;
    kfs[p].vio = applyCorrection(shift, kfs[p].vio);
    setYawPitchRoll(kfs[p]);
    x[p] = applyCorrection(shift, x[p], kfs[p]);
  }
  seq_shift[seq] = shift;
  seq_anchored[seq] = true;
  rebuildMoments(seq);
}

// ---------------------------------------------------------------------------------------

KeyframeGraph::KeyframeGraph(const VerifierConfig& config) : config_(config), impl_(new Impl(config_)) {}

KeyframeGraph::~KeyframeGraph() = default;

size_t KeyframeGraph::keyframeCount() const { return impl_->kfs.size(); }

bool KeyframeGraph::hasKeyframe(int64_t index) const {
  size_t pos;
  return impl_->find(index, &pos);
}

bool KeyframeGraph::find(int64_t index, size_t* position) const { return impl_->find(index, position); }

int KeyframeGraph::sequenceAt(size_t position) const { return impl_->kfs[position].sequence; }

std::string KeyframeGraph::checkLoop(const LoopCandidate& c, size_t* qpos, size_t* mpos) const {
  return impl_->checkLoop(c, qpos, mpos);
}

bool KeyframeGraph::hasLoop(int64_t query_index, int64_t match_index) const {
  const Impl& m = *impl_;
  size_t qpos = 0, mpos = 0;
  if (!m.find(query_index, &qpos) || !m.find(match_index, &mpos)) return false;
  const auto ends = m.loop_ends.find(mpos);
  return ends != m.loop_ends.end() &&
         std::any_of(ends->second.begin(), ends->second.end(),
                     [&](const Impl::LoopEnd& e) { return e.is_from && e.other == qpos; });
}

Status KeyframeGraph::addLoop(const LoopCandidate& c) {
  Impl& m = *impl_;
  size_t qpos = 0, mpos = 0;
  const std::string bad = m.checkLoop(c, &qpos, &mpos);
  if (!bad.empty()) return Status::Error(bad);
  if (hasLoop(c.query_index, c.match_index))
    return Status::Error("loop " + describeIndex(c.query_index) + " -> " + describeIndex(c.match_index) +
                         " is already in the graph");
  const int qseq = m.kfs[qpos].sequence, mseq = m.kfs[mpos].sequence;
  // loop_fusion: old_kf->sequence != cur_kf->sequence && sequence_loop[cur_kf->sequence] == 0
  if (qseq != mseq && !m.seq_anchored[qseq]) m.anchorSequence(c, qpos, mpos);
  Impl::Edge e;
  e.from = mpos;
  e.to = qpos;
  e.loop = c;
  m.setLoopCost(e);
  m.loops.push_back(std::move(e));
  m.indexLoop(mpos, qpos);
  m.seg_parent[m.root(m.kfs[qpos].segment)] = m.root(m.kfs[mpos].segment);
  ++m.revision;
  return Status::Ok();
}

size_t KeyframeGraph::loopCount() const { return impl_->loops.size(); }

bool KeyframeGraph::connected(size_t a, size_t b) const {
  return impl_->root(impl_->kfs[a].segment) == impl_->root(impl_->kfs[b].segment);
}

uint64_t KeyframeGraph::revision() const { return impl_->revision; }

bool KeyframeGraph::estimate(int64_t index, Pose* pose) const {
  size_t pos;
  if (!impl_->find(index, &pos)) return false;
  *pose = impl_->poseFromState(impl_->x[pos], impl_->kfs[pos]);
  return true;
}

std::vector<TrajectoryPoint> KeyframeGraph::trajectory() const {
  const Impl& m = *impl_;
  std::vector<TrajectoryPoint> out(m.kfs.size());
  for (size_t p = 0; p < m.kfs.size(); ++p) {
    out[p].index = m.kfs[p].index;
    out[p].stamp = m.kfs[p].stamp;
    out[p].sequence = m.kfs[p].sequence;
    out[p].vio = m.kfs[p].vio;
    out[p].estimate = m.poseFromState(m.x[p], m.kfs[p]);
  }
  return out;
}

double KeyframeGraph::innovation(const LoopCandidate& c, size_t qpos, size_t mpos) const {
  return impl_->innovation(c, qpos, mpos);
}

double KeyframeGraph::pathLength(size_t from, size_t to) const { return impl_->pathLength(from, to); }

void KeyframeGraph::keepPathLengths() {
  if (impl_->places_stale) impl_->rebuildPlaces();
}

int KeyframeGraph::segmentAt(size_t position) const { return impl_->kfs[position].segment; }

bool KeyframeGraph::vioAt(size_t position, Pose* pose) const {
  if (position >= impl_->kfs.size()) return false;
  *pose = impl_->kfs[position].vio;
  return true;
}

bool KeyframeGraph::estimateAt(size_t position, Pose* pose) const {
  if (position >= impl_->kfs.size()) return false;
  *pose = impl_->poseFromState(impl_->x[position], impl_->kfs[position]);
  return true;
}

Status KeyframeGraph::removeLoop(int64_t query_index, int64_t match_index) {
  Impl& m = *impl_;
  size_t qpos = 0, mpos = 0;
  if (!m.find(query_index, &qpos) || !m.find(match_index, &mpos))
    return Status::Error("removeLoop: unknown keyframe");
  for (auto it = m.loops.begin(); it != m.loops.end(); ++it) {
    if (it->from == mpos && it->to == qpos) {
      m.loops.erase(it);
      m.unindexLoop(mpos, qpos);
      ++m.revision;
      return Status::Ok();
    }
  }
  return Status::Error("removeLoop: no loop " + describeIndex(query_index) + " -> " + describeIndex(match_index));
}

std::vector<LoopCandidate> KeyframeGraph::loopsWithQueryIn(size_t first, size_t last) const {
  std::vector<LoopCandidate> out;
  for (const Impl::Edge& e : impl_->loops)
    if (e.to >= first && e.to <= last) out.push_back(e.loop);
  return out;
}

std::vector<KeyframeState> KeyframeGraph::estimates() const { return impl_->x; }

bool KeyframeGraph::restoreEstimates(const std::vector<KeyframeState>& states) {
  if (states.size() != impl_->x.size()) return false;
  impl_->x = states;
  return true;
}

}  // namespace core
}  // namespace rover_loop_fusion
