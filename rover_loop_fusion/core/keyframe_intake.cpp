// Keyframe intake of the pose graph (KeyframeGraph::addKeyframe): the checks of a new keyframe
// (index, sequence, finite pose, unit quaternion), the plausibility of its step from the
// previous keyframe of its sequence (max_keyframe_jump, max_stamp_jump), the stamp faults told
// apart from a jump (a repeated message, a stopped clock, keyframes stamped late, also on a
// stopped clock) and the recovery from a jump (jump_confirmations: a relocation starts a new
// segment, or a new clock; first keyframes fewer than the run that contradicts them are
// discredited); then its
// estimate, drift moments and odometry edges. Also the segments' union-find (root, componentOf):
// odometry joins keyframes of one segment, loops join segments.
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <string>

namespace rover_loop_fusion {
namespace core {

std::string KeyframeGraph::Impl::implausibleStep(const Keyframe& a, const Keyframe& b) const {
  std::ostringstream s;
  s.precision(17);
  const double jump = (b.vio.t - a.vio.t).norm();
  if (!(jump <= cfg.input.max_keyframe_jump)) {
    s.precision(6);
    s << "position jumps " << jump << " m from keyframe " << a.index << " (max_keyframe_jump "
      << cfg.input.max_keyframe_jump << " m)";
    s.precision(17);
  }
  const double dt = b.stamp - a.stamp;
  if (!(dt > 0.0) || !(dt <= cfg.input.max_stamp_jump)) {
    if (!s.str().empty()) s << "; ";
    if (!(dt > 0.0))
      s << "out of order: stamp " << b.stamp << " not after the previous keyframe's " << a.stamp << " in sequence " << a.sequence;
    else
      s << "stamp " << b.stamp << " is " << dt << " s after keyframe " << a.index << "'s (max_stamp_jump "
        << cfg.input.max_stamp_jump << " s)";
  }
  return s.str();
}

namespace {

/// The checks of a keyframe by itself: index, sequence, a finite and plausible pose, a unit quaternion.
Status checkKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t, const Eigen::Quaterniond& q,
                     double quaternion_tolerance, const std::string& who) {
  if (index < 0) return Status::Error(who + "negative index");
  if (sequence < 0) return Status::Error(who + "negative sequence");
  if (!t.allFinite()) return Status::Error(who + "position is not finite");
  if (!(t.cwiseAbs().maxCoeff() <= kMaxCoordinate)) {
    std::ostringstream s;
    s << who << "position (" << t.x() << ", " << t.y() << ", " << t.z() << ") beyond " << kMaxCoordinate
      << " m from the origin: not a VIO pose";
    return Status::Error(s.str());
  }
  if (!std::isfinite(stamp)) return Status::Error(who + "stamp is not finite");
  if (!unitQuaternion(q, quaternion_tolerance)) return Status::Error(who + "orientation is not a unit quaternion");
  return Status::Ok();
}

bool samePose(const Pose& a, const Pose& b) { return a.t == b.t && a.q.coeffs() == b.q.coeffs(); }

}  // namespace

Status KeyframeGraph::addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                              const Eigen::Quaterniond& q, const Eigen::Matrix4d* step_covariance) {
  Impl& m = *impl_;
  const std::string who = "keyframe " + describeIndex(index) + ": ";
  const Status checked = checkKeyframe(index, stamp, sequence, t, q, config_.input.quaternion_tolerance, who);
  if (!checked) return checked;
  const Impl::Keyframe* prev = nullptr;  // the previous keyframe of this sequence
  if (!m.kfs.empty()) {
    const Impl::Keyframe& last = m.kfs.back();
    if (index == last.index) return Status::Error(who + "duplicate index");
    if (index < last.index) return Status::Error(who + "index older than the newest keyframe " + describeIndex(last.index));
    if (sequence < last.sequence)
      return Status::Error(who + "sequence " + std::to_string(sequence) + " after sequence " + std::to_string(last.sequence));
    if (sequence == last.sequence) prev = &last;
  }

  Impl::Keyframe kf;
  kf.index = index;
  kf.stamp = stamp;
  kf.sequence = sequence;
  kf.segment = prev ? prev->segment : sequence;
  kf.vio = Pose(t, q.normalized());
  if (config_.host.anchor_incoming_keyframes) {
    auto shift = m.seq_shift.find(sequence);
    if (shift != m.seq_shift.end()) kf.vio = m.applyCorrection(shift->second, kf.vio);
  }
  m.setYawPitchRoll(kf);

  Status status = Status::Ok();
  if (prev && sequence == 0) {
    // A loaded map (held fixed): loop_fusion saves its keyframes by index, sessions one after
    // another, so stamps need not increase. Kept; said once.
    if (!(stamp > prev->stamp) && !m.warned_loaded_map_stamps) {
      m.warned_loaded_map_stamps = true;
      std::ostringstream s;
      s.precision(17);
      s << who << "stamp " << stamp << " not after the previous keyframe's " << prev->stamp
        << " in sequence 0 (a loaded map, held fixed, may be saved out of time order): kept; stamps of "
           "sequence 0 are not checked further";
      status = Status::Warning(s.str());
    }
  } else if (prev) {
    // A live sequence: a keyframe far from the previous one or stamped implausibly is refused,
    // unless it is the last of `jump_confirmations` consecutive keyframes that each follow the
    // one before plausibly: then the VIO really relocated (a new segment) or the clock jumped.
    // Three stamp faults are told apart from a jump first (one stamp policy for every host):
    // a repeated message, a clock that stopped, and keyframes stamped late.
    std::string implausible = m.implausibleStep(*prev, kf);
    if (m.stampFaults(kf, *prev, who, &implausible, &status)) return status;
    if (!implausible.empty() && m.confirmJump(kf, *prev, who, implausible, &status)) return status;
  }
  m.suspect.run = 0;
  m.appendKeyframe(kf, prev, step_covariance, who, &status);
  return status;
}

bool KeyframeGraph::Impl::stampFaults(const Keyframe& kf, const Keyframe& prev, const std::string& who,
                                      std::string* implausible, Status* status) {
  bool still_stopped = false;  // stamped like the keyframe before a late one: the clock is still stopped
  const bool step_ok = (kf.vio.t - prev.vio.t).norm() <= cfg.input.max_keyframe_jump;
  if (!implausible->empty() && step_ok && kf.stamp == prev.stamp) {
    if (samePose(kf.vio, prev.vio)) {
      *status = Status::Error(who + "duplicate: a repeat of keyframe " + describeIndex(prev.index) +
                              " (same stamp, same pose): refused");
      return true;
    }
    // The clock stopped (a stalled driver): the pose still moves plausibly. Stamps only name
    // keyframes here, so it is kept; never taken as a new clock.
    implausible->clear();
    if (!clock_stopped) {
      std::ostringstream w;
      w.precision(17);
      w << who << "stamp " << kf.stamp << " equal to the previous keyframe's (" << describeIndex(prev.index)
        << "): the clock stopped advancing; kept, as every keyframe after it with that stamp and a plausible pose "
           "(said once; a host that names keyframes by stamp cannot tell them apart)";
      *status = Status::Warning(w.str());
    }
    clock_stopped = true;
  } else if (!implausible->empty() && step_ok && kf.stamp < prev.stamp && kfs.size() >= 2) {
    lateStamps(kf, prev, who, implausible, status, &still_stopped);
  }
  if (still_stopped) clock_stopped = true;
  else if (implausible->empty() && kf.stamp != prev.stamp) clock_stopped = false;
  return false;
}

void KeyframeGraph::Impl::lateStamps(const Keyframe& kf, const Keyframe& prev, const std::string& who,
                                     std::string* implausible, Status* status, bool* still_stopped) {
  // Stamped before the previous keyframe but plausibly after an earlier one, and every
  // keyframe between them stamped after it: their stamps were the wrong ones (messages
  // stamped late, up to jump_confirmations - 1 in a row; as many in a row had the evidence
  // of a new clock, and coming back from it needs the same; more than one only when their
  // stamps stand out). Kept; the late keyframes keep their stamps as their names. The earlier
  // keyframe may carry this stamp when the clock stopped (a stamp frozen, and one message of
  // the stretch stamped late).
  const double stamp = kf.stamp;
  const size_t last = kfs.size() - 1;
  const int most = std::max(1, cfg.input.jump_confirmations - 1);
  for (int late = 1; late <= most && static_cast<size_t>(late) <= last; ++late) {
    const Keyframe& late_kf = kfs[last - late + 1];
    const Keyframe& before = kfs[last - late];
    if (late_kf.sequence != kf.sequence || late_kf.segment != prev.segment || !(late_kf.stamp > stamp)) break;
    if (before.sequence != kf.sequence || before.segment != prev.segment) break;
    if (before.stamp > stamp) continue;  // late too: look further back
    const bool stopped = before.stamp == stamp &&
                         (kf.vio.t - before.vio.t).norm() <= cfg.input.max_keyframe_jump &&
                         !samePose(kf.vio, before.vio);
    if (!stopped && !implausibleStep(before, kf).empty()) break;
    if (late >= 2) {
      // Several wrong stamps explain a keyframe only when they stand out: each further ahead
      // of it than it is after the keyframe before them (two messages stamped 1000 s late).
      // Otherwise the new keyframe's stamp is the wrong one (stamped between two earlier
      // keyframes): refused.
      double ahead = std::numeric_limits<double>::infinity();
      for (size_t p = last - late + 1; p <= last; ++p) ahead = std::min(ahead, kfs[p].stamp - stamp);
      if (!(ahead > stamp - before.stamp)) break;
    }
    std::ostringstream w;
    w.precision(17);
    const std::string first = describeIndex(kfs[last - late + 1].index), newest = describeIndex(prev.index);
    const std::string named = late == 1 ? "keyframe " + newest : "keyframes " + first + " .. " + newest;
    w << who << "stamp " << stamp << " before keyframe " << newest << "'s (" << prev.stamp << ") but "
      << (stopped ? "equal to" : "plausibly after") << " keyframe " << describeIndex(before.index) << "'s ("
      << before.stamp << (stopped ? ", the clock stopped" : "") << "): " << named << "'s "
      << (late == 1 ? "stamp was" : "stamps were") << " wrong (stamped late); kept";
    *status = Status::Warning(w.str());
    implausible->clear();
    *still_stopped = stopped;
    break;
  }
}

bool KeyframeGraph::Impl::confirmJump(Keyframe& kf, const Keyframe& prev, const std::string& who,
                                      const std::string& implausible, Status* status) {
  const int sequence = kf.sequence;
  const bool follows = suspect.run > 0 && suspect.keyframe.sequence == sequence &&
                       implausibleStep(suspect.keyframe, kf).empty();
  const int run = follows ? suspect.run + 1 : 1;
  if (run < cfg.input.jump_confirmations) {
    suspect.run = run;
    suspect.keyframe = kf;
    const int more = cfg.input.jump_confirmations - run;
    *status = Status::Error(who + implausible + ": refused; " + std::to_string(more) + " more consecutive " +
                            (more == 1 ? "keyframe" : "keyframes") +
                            " consistent with it would be taken as a relocation (jump_confirmations)");
    return true;
  }
  const bool relocated = !((kf.vio.t - prev.vio.t).norm() <= cfg.input.max_keyframe_jump);
  // The keyframes before the jump are the first of their sequence and fewer than the run
  // that agrees with each other and not with them (one bad first pose, or a few that agree
  // with each other): the run outvotes them (the first poses of a session need the same
  // evidence as any jump). They are discredited, and the sequence goes on from the run.
  const size_t prev_pos = kfs.size() - 1;
  size_t first_pos = prev_pos;
  while (first_pos > 0 && kfs[first_pos - 1].sequence == sequence) --first_pos;
  const size_t before_jump = prev_pos - first_pos + 1;
  bool lone_first = relocated && before_jump < static_cast<size_t>(run);
  for (size_t p = first_pos; lone_first && p <= prev_pos; ++p)
    if (kfs[p].segment != prev.segment || loop_ends.count(p) != 0 || discredited.count(p) != 0) lone_first = false;
  if (relocated) kf.segment = next_segment--;
  const std::string bad = before_jump == 1 ? "keyframe " + describeIndex(kfs[first_pos].index)
                                           : "keyframes " + describeIndex(kfs[first_pos].index) + " .. " +
                                                 describeIndex(kfs[prev_pos].index);
  const std::string one = before_jump == 1 ? "it" : "them";
  if (lone_first) {
    std::ostringstream why;
    why << run << " keyframes after " << one << " agree with each other and not with " << one << " ("
        << implausible << "): " << (before_jump == 1 ? "a bad first pose" : "bad first poses") << " of sequence "
        << sequence;
    for (size_t p = first_pos; p <= prev_pos; ++p) discredited[p] = why.str();
  }
  clock_stopped = false;
  const std::string seq = std::to_string(sequence);
  const std::string what =
      lone_first ? bad + ", the first of sequence " + seq +
                       (before_jump == 1 ? ", is discredited: a bad first pose; loops that name it are refused"
                                         : ", are discredited: bad first poses; loops that name them are refused") +
                       ", and sequence " + seq + " goes on from here"
      : relocated ? "the VIO relocated: a new segment of sequence " + seq +
                        " starts here, without odometry to the keyframes before; loops across the jump have no "
                        "trajectory prior until one ties the two"
                  : "a new clock";
  *status = Status::Warning(who + implausible + ": accepted after " + std::to_string(run) +
                            " consecutive keyframes agreed (" + what + ")");
  return false;
}

void KeyframeGraph::Impl::appendKeyframe(const Keyframe& kf, const Keyframe* prev,
                                         const Eigen::Matrix4d* given_covariance, const std::string& who,
                                         Status* status) {
  // X of the new keyframe: its VIO pose carried by the current drift correction of the
  // previous keyframe of the same sequence (loop_fusion's r_drift / t_drift).
  KeyframeState s = stateFromPose(kf.vio);
  const size_t pos = kfs.size();
  if (prev) {
    const Correction drift = correctionBetween(stateFromPose(prev->vio), x.back(), *prev);
    s = applyCorrection(drift, s, kf);
  }
  const bool continues = prev && prev->segment == kf.segment;
  arc.push_back(continues ? arc.back() + (kf.vio.t - prev->vio.t).norm() : 0.0);
  kfs.push_back(kf);  // (prev is not used below: push_back may move it)
  x.push_back(s);
  root(kf.segment);
  if (given_covariance) {
    const Eigen::Matrix4d& C = *given_covariance;
    const Eigen::LLT<Eigen::Matrix4d> llt(0.5 * (C + C.transpose()));
    if (C.allFinite() && (C - C.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * (1.0 + C.cwiseAbs().maxCoeff()) &&
        llt.info() == Eigen::Success) {
      step_covariance[pos] = C;
    } else {
      const std::string ignored = who + "its step covariance is not finite, symmetric and positive definite: the drift "
                                        "model's is used instead";
      *status = status->message.empty() ? Status::Warning(ignored) : Status::Warning(status->message + "; " + ignored);
    }
  }
  extendChain(pos);
  const int n = std::max(0, cfg.trial.odometry_neighbours);
  for (int j = n; j >= 1; --j) {
    if (pos < static_cast<size_t>(j)) continue;
    const size_t from = pos - j;
    if (kfs[from].segment != kf.segment) continue;
    odometry.push_back(odometryEdge(from, pos));
  }
}

// ---- segments (union-find) ---------------------------------------------------------------

int KeyframeGraph::Impl::root(int segment) {
  auto it = seg_parent.find(segment);
  if (it == seg_parent.end()) {
    seg_parent[segment] = segment;
    return segment;
  }
  if (it->second == segment) return segment;
  const int r = root(it->second);
  seg_parent[segment] = r;
  return r;
}

int KeyframeGraph::Impl::componentOf(size_t pos) const {
  int s = kfs[pos].segment;
  for (auto it = seg_parent.find(s); it != seg_parent.end() && it->second != s; it = seg_parent.find(s))
    s = it->second;
  return s;
}

}  // namespace core
}  // namespace rover_loop_fusion
