#include "rover_loop_fusion/ros/loop_fusion_adapter.h"

#include "rover_loop_fusion/LoopCandidate.h"
#include "rover_loop_fusion/ros/conversions.h"
#include "rover_loop_fusion/ros/guarded.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/verifier_host.h"

#include <Eigen/Geometry>
#include <ros/console.h>
#include <ros/init.h>
#include <ros/this_node.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <mutex>
#include <map>
#include <set>
#include <string>
#include <unordered_map>
#include <utility>

namespace rover_loop_fusion {

namespace {

const char kFallbackVerifierType[] = "fallback:accept_all";
/// Queue of ~loop_verdicts and ~loop_candidates per subscriber: roscpp drops silently beyond
/// it, so it is far more than a subscriber can fall behind by in a run (one message per
/// loop candidate).
const int kQueueSize = 100000;

std::string join(const std::vector<std::string>& parts) {
  std::string out;
  for (const std::string& p : parts) out += (out.empty() ? "" : "; ") + p;
  return out;
}

/// Ends the host process after a configuration error (ROS_FATAL has said which parameter to
/// fix). Not exit(): loop_fusion's static destructors would run (~PoseGraph detaches a thread
/// that setIMUFlag has not started yet, which throws); not ros::shutdown(): loop_fusion's
/// main would go on and return with joinable threads (std::terminate). See design notes.
[[noreturn]] void stopProcess() {
  std::fflush(stdout);
  std::fflush(stderr);
  std::_Exit(EXIT_FAILURE);
}

// loop_fusion ends by std::terminate: its main returns with its threads still joinable (after
// the 's' save and after Ctrl-C alike: exit status -6), so no destructor runs. The adapters that
// verify register here; a terminate handler lets each finish() (the final verdicts of held
// candidates, the CSV log flushed) before the previous handler (abort) runs.
std::mutex g_live_mutex;
std::set<LoopFusionAdapter*> g_live;
std::terminate_handler g_previous_terminate = nullptr;
std::once_flag g_terminate_installed;

[[noreturn]] void finishOnTerminate() {
  std::vector<LoopFusionAdapter*> live;
  {
    std::unique_lock<std::mutex> lock(g_live_mutex, std::try_to_lock);
    if (lock.owns_lock()) live.assign(g_live.begin(), g_live.end());
  }
  for (LoopFusionAdapter* a : live) a->finish();
  std::fflush(stdout);
  std::fflush(stderr);
  if (g_previous_terminate) g_previous_terminate();
  std::abort();
}

void registerLive(LoopFusionAdapter* adapter) {
  std::call_once(g_terminate_installed, [] { g_previous_terminate = std::set_terminate(finishOnTerminate); });
  std::lock_guard<std::mutex> lock(g_live_mutex);
  g_live.insert(adapter);
}

void unregisterLive(LoopFusionAdapter* adapter) {
  std::lock_guard<std::mutex> lock(g_live_mutex);
  g_live.erase(adapter);
}

/// A keyframe without a loop, as KeyFrame's constructor leaves it.
void dropLoop(bool& has_loop, int& loop_index, LoopFusionAdapter::LoopInfo& loop_info) {
  has_loop = false;
  loop_index = -1;
  loop_info.setZero();
}

}  // namespace

struct LoopFusionAdapter::Impl {
  enum class Mode { kUninitialized, kVerifying, kFallback, kFailed, kFinished };
  struct KeyframeInfo {
    double stamp = 0.0;
    Eigen::Vector3d position = Eigen::Vector3d::Zero();  // VIO position as handed in
  };
  mutable std::mutex mutex;
  Mode mode = Mode::kUninitialized;
  std::string failure;  // why kFallback / kFailed
  std::unique_ptr<ros::NodeHandle> nh;
  std::unique_ptr<VerifierHost> host;
  ros::Publisher candidate_pub;  // ~loop_candidates: every candidate, before it is verified
  std::unordered_map<int64_t, KeyframeInfo> keyframes;
  RepeatedWarning refused_keyframes;
  /// What the verifier says of a keyframe it took (a stopped clock, a VIO relocation, a global
  /// pass stopped at global_budget_ms): as the standalone node logs it.
  RepeatedWarning keyframe_warnings;
  size_t verdicts = 0;
  /// Held candidates: what findConnection found, to hand back to loop_fusion on a release.
  struct Held {
    std::array<double, 8> loop_info;
    int inliers;
  };
  std::map<std::pair<int64_t, int64_t>, Held> held;
  /// Released and revoked loops not yet taken by loop_fusion (takeLaterLoops).
  std::vector<LoopFusionAdapter::LaterLoop> later;

  /// start() that never throws: an exception leaves the adapter failed (loops rejected).
  bool safeStart(bool use_imu, VerifierPtr injected, const std::string& injected_type);
  bool start(bool use_imu, VerifierPtr injected, const std::string& injected_type);
  [[noreturn]] void fatal(const std::string& message);
  double stamp(int64_t index) const {
    auto k = keyframes.find(index);
    return k == keyframes.end() ? 0.0 : k->second.stamp;
  }
  bool vioPosition(int64_t index, Eigen::Vector3d* position) const {
    auto k = keyframes.find(index);
    if (k == keyframes.end()) return false;
    *position = k->second.position;
    return true;
  }
  /// Logs and publishes a verdict (with the candidate's stamps and a marker).
  void publish(const core::Verdict& v, VerdictContext ctx);
  /// After every addKeyframe and verify: the verifier's later decisions become verdicts, and
  /// releases and revocations LaterLoops for loop_fusion. Call with `mutex` held.
  void collectDecisions();
};

void LoopFusionAdapter::Impl::publish(const core::Verdict& v, VerdictContext ctx) {
  ctx.query_stamp = stamp(v.query_index);
  ctx.match_stamp = stamp(v.match_index);
  const std::string described = "loop " + std::to_string(v.query_index) + " -> " + std::to_string(v.match_index) +
                                " (stamps " + stampText(ctx.query_stamp) + " -> " + stampText(ctx.match_stamp) + ")";
  if (host->publish(v, ctx, described, [&](int64_t i, Eigen::Vector3d* p) { return vioPosition(i, p); }))
    ++verdicts;
}

void LoopFusionAdapter::Impl::collectDecisions() {
  if (mode != Mode::kVerifying) return;
  for (const core::LoopDecision& d : host->takeDecisions()) {
    const core::LoopCandidate& c = d.candidate;
    const std::pair<int64_t, int64_t> key(c.query_index, c.match_index);
    core::Verdict v = d.verdict;
    VerdictContext ctx;
    ctx.verifier = host->verifierType();
    ctx.decision = core::toString(d.kind);
    ctx.inliers = c.inliers;
    auto h = held.find(key);
    if (d.kind != core::LoopDecision::Kind::kDrop) {
      LoopFusionAdapter::LaterLoop l;
      l.use = d.kind == core::LoopDecision::Kind::kRelease;
      l.index = static_cast<int>(c.query_index);
      l.match_index = static_cast<int>(c.match_index);
      l.inliers = l.use ? c.inliers : -1;
      for (int i = 0; i < 8; ++i) l.loop_info[i] = 0.0;
      if (l.use && h != held.end()) {
        // Exactly what findConnection stored on the keyframe.
        for (int i = 0; i < 8; ++i) l.loop_info[i] = h->second.loop_info[i];
        l.inliers = h->second.inliers;
      } else if (l.use) {
        // Not held here (cannot happen with the shipped plugins): from the candidate.
        const double info[8] = {c.relative_t.x(), c.relative_t.y(), c.relative_t.z(), c.relative_q.w(),
                                c.relative_q.x(), c.relative_q.y(), c.relative_q.z(), c.relative_yaw * 180.0 / M_PI};
        for (int i = 0; i < 8; ++i) l.loop_info[i] = info[i];
      }
      if (keyframes.count(c.query_index) && keyframes.count(c.match_index)) {
        later.push_back(l);
      } else {
        // loop_fusion has no such keyframe: it cannot use (or still hold) the loop.
        ROS_ERROR("[rover] the verifier's %s of loop %ld -> %ld names a keyframe loop_fusion never registered: "
                  "not applied", ctx.decision.c_str(), static_cast<long>(c.query_index),
                  static_cast<long>(c.match_index));
      }
    }
    if (h != held.end()) {
      ctx.inliers = h->second.inliers;
      held.erase(h);
    }
    publish(v, ctx);
  }
}

void LoopFusionAdapter::Impl::fatal(const std::string& message) {
  mode = Mode::kFailed;
  failure = message;
  ROS_FATAL("[rover] the loop verifier cannot start: %s. Stopping %s.", message.c_str(),
            ros::this_node::getName().c_str());
  stopProcess();
}

bool LoopFusionAdapter::Impl::start(bool use_imu, VerifierPtr injected, const std::string& injected_type) {
  std::lock_guard<std::mutex> lock(mutex);
  if (mode != Mode::kUninitialized) {
    ROS_WARN("[rover] LoopFusionAdapter::initialize called again: ignored");
    return mode == Mode::kVerifying;
  }
  if (!ros::isInitialized()) {
    // Nothing to log through; fail closed.
    std::fprintf(stderr, "[rover] LoopFusionAdapter::initialize called before ros::init: every loop is rejected\n");
    mode = Mode::kFailed;
    failure = "initialize() was called before ros::init";
    return false;
  }
  nh.reset(new ros::NodeHandle("~"));
  host.reset(new VerifierHost(*nh, "marker_frame"));
  bool fallback_to_accept_all = false;
  host->reader().boolean("fallback_to_accept_all", &fallback_to_accept_all);
  HostInfo info;
  info.uses_imu = use_imu;
  info.shifts_sequences = true;  // loop_fusion hands poses after its w_r_vio/w_t_vio shift
  const VerifierHost::Start s = host->start(info, kQueueSize, std::move(injected), injected_type);
  // Errors in the host's own parameters always stop: the fallback is about the plugin.
  if (!s.errors.empty()) fatal(join(s.errors));
  candidate_pub = nh->advertise<LoopCandidate>("loop_candidates", kQueueSize);
  if (s.verifier_error.empty()) {
    mode = Mode::kVerifying;
    return true;
  }
  if (fallback_to_accept_all) {
    mode = Mode::kFallback;
    failure = s.verifier_error;
    ROS_ERROR("[rover] the loop verifier cannot start: %s. %s is true: every loop candidate is "
              "ACCEPTED WITHOUT VERIFICATION (upstream loop_fusion behaviour).",
              s.verifier_error.c_str(), host->resolve("fallback_to_accept_all").c_str());
    return false;
  }
  fatal(s.verifier_error + ". Fix that parameter, or set " + host->resolve("fallback_to_accept_all") +
        ": true to run without verification");
}

LoopFusionAdapter::LoopFusionAdapter() : impl_(new Impl) {}

LoopFusionAdapter::~LoopFusionAdapter() {
  unregisterLive(this);
  finish();
}

void LoopFusionAdapter::finish() {
  Impl& m = *impl_;
  guarded("LoopFusionAdapter::finish (held candidates may lack their final verdict)", [&] {
    std::lock_guard<std::mutex> lock(m.mutex);
    if (m.mode != Impl::Mode::kVerifying) {
      if (m.mode != Impl::Mode::kUninitialized) m.mode = Impl::Mode::kFinished;
      return;
    }
    m.collectDecisions();  // what the verifier decided last
    // The host kept the verdicts of the held candidates: each gets its final one (a drop).
    const std::vector<core::LoopDecision> dropped =
        m.host->dropHeld("still held when loop_fusion ended: not confirmed, never used");
    const size_t held = dropped.size();
    for (const core::LoopDecision& d : dropped) {
      VerdictContext ctx;
      ctx.verifier = m.host->verifierType();
      ctx.decision = core::toString(d.kind);
      ctx.inliers = d.candidate.inliers;
      m.publish(d.verdict, ctx);
    }
    m.held.clear();
    m.failure = "loop_fusion ended (LoopFusionAdapter::finish)";
    m.mode = Impl::Mode::kFinished;
    // After ros::shutdown() (loop_fusion's 's' command, Ctrl-C) rosconsole prints nothing: say
    // it on stderr then, as the abort that follows flushes nothing.
    enum class Level { kInfo, kWarn, kError };
    auto tell = [](Level level, const std::string& text) {
      if (ros::ok()) {
        if (level == Level::kError)
          ROS_ERROR("%s", text.c_str());
        else if (level == Level::kWarn)
          ROS_WARN("%s", text.c_str());
        else
          ROS_INFO("%s", text.c_str());
        return;
      }
      std::fflush(stdout);  // what loop_fusion printed before comes first
      std::fprintf(stderr, "[%s] %s\n", level == Level::kError ? "ERROR" : level == Level::kWarn ? " WARN" : " INFO",
                   text.c_str());
      std::fflush(stderr);
    };
    // What the rate-limited warnings held back since their last summary.
    for (RepeatedWarning* w : {&m.refused_keyframes, &m.keyframe_warnings}) {
      const std::string summary = w->takeSummary();
      if (!summary.empty()) tell(Level::kWarn, summary);
    }
    if (held > 0)
      tell(Level::kInfo, "[rover] loop_fusion ends: " + std::to_string(held) +
                      " candidates still held got their final verdict (unconfirmed, drop)");
    // loop_fusion ends by std::terminate: the writer thread must have the rows before abort().
    const size_t unwritten = m.host->flushLog(2.0);
    if (unwritten > 0)
      tell(Level::kError,
           "[rover] loop_fusion ends: " + std::to_string(unwritten) + " verdict rows not written to the log yet");
  });
}

bool LoopFusionAdapter::Impl::safeStart(bool use_imu, VerifierPtr injected, const std::string& type) {
  bool verifying = false;
  if (guarded("LoopFusionAdapter::initialize (every loop is rejected)",
              [&] { verifying = start(use_imu, std::move(injected), type); }))
    return verifying;
  std::lock_guard<std::mutex> lock(mutex);
  mode = Mode::kFailed;
  failure = "initialize() failed with an exception";
  return false;
}

bool LoopFusionAdapter::initialize(bool use_imu) {
  const bool verifying = impl_->safeStart(use_imu, VerifierPtr(), "");
  if (verifying) registerLive(this);
  return verifying;
}

bool LoopFusionAdapter::initializeWithVerifier(bool use_imu, std::unique_ptr<LoopVerifier> verifier,
                                               const std::string& verifier_type) {
  const bool verifying = impl_->safeStart(
      use_imu, VerifierPtr(verifier.release(), std::default_delete<LoopVerifier>()), verifier_type);
  if (verifying) registerLive(this);
  return verifying;
}

void LoopFusionAdapter::addKeyframe(int index, double stamp, int sequence, const Eigen::Vector3d& P,
                                    const Eigen::Matrix3d& R) {
  Impl& m = *impl_;
  guarded("keyframe " + std::to_string(index) + " (loops that involve it are rejected)", [&] {
    std::lock_guard<std::mutex> lock(m.mutex);
    Impl::KeyframeInfo& kf = m.keyframes[index];
    kf.stamp = stamp;
    kf.position = P;
    if (m.mode != Impl::Mode::kVerifying) return;
    const core::Status s = m.host->verifier()->addKeyframe(index, stamp, sequence, P, Eigen::Quaterniond(R));
    if (!s.ok)
      m.refused_keyframes.warn("keyframe " + std::to_string(index) + " not added to the verifier (" + s.message +
                               "); loops that involve it are rejected");
    else if (s.warning())
      m.keyframe_warnings.warn(keyframeWarning(index, s.message));
    m.collectDecisions();
  });
}

bool LoopFusionAdapter::verifyLoop(int query_index, int match_index, const LoopInfo& loop_info, int inliers) {
  Impl& m = *impl_;
  bool accepted = false;  // fail closed: only a committed loop is handed back as usable
  const std::string what = "loop " + std::to_string(query_index) + " -> " + std::to_string(match_index);
  guarded("verifyLoop: " + what, [&] {
    std::lock_guard<std::mutex> lock(m.mutex);
    const core::LoopCandidate c = core::candidateFromLoopInfo(query_index, match_index, loop_info.data(), inliers);
    VerdictContext ctx;
    ctx.inliers = c.inliers;
    ctx.query_stamp = m.stamp(query_index);
    ctx.match_stamp = m.stamp(match_index);
    if (m.candidate_pub) {
      // Before the verdict: a recording of /vins_estimator/keyframe_pose and ~loop_candidates
      // can be replayed through rover_verifier_node with other parameters.
      guarded("publishing loop candidate " + what, [&] {
        m.candidate_pub.publish(toCandidateMsg(c, ctx.query_stamp, ctx.match_stamp, m.host->params().frame_id));
      });
    }
    core::Verdict v;
    ctx.verifier = m.host ? m.host->verifierType() : "";
    switch (m.mode) {
      case Impl::Mode::kUninitialized:
        ROS_ERROR_THROTTLE(10.0, "[rover] %s rejected: LoopFusionAdapter::initialize was never called (is the "
                           "patch complete?)", what.c_str());
        return;
      case Impl::Mode::kFailed:
      case Impl::Mode::kFinished:
        v = rejection(c, "verifier not running: " + m.failure);
        break;
      case Impl::Mode::kFallback:
        ctx.verifier = kFallbackVerifierType;
        v.query_index = c.query_index;
        v.match_index = c.match_index;
        v.accepted = true;
        v.reason = core::Reason::kAccepted;
        v.detail = "not verified (fallback_to_accept_all; the verifier could not start: " + m.failure + ")";
        break;
      case Impl::Mode::kVerifying:
        v = m.host->decide(c);
        break;
    }
    accepted = v.accepted;
    if (!m.host) return;
    if (v.deferred) {
      Impl::Held& h = m.held[std::make_pair(c.query_index, c.match_index)];
      for (int i = 0; i < 8; ++i) h.loop_info[i] = loop_info(i);
      h.inliers = inliers;
    }
    m.publish(v, ctx);
    m.collectDecisions();
  });
  return accepted;
}

std::vector<LoopFusionAdapter::LaterLoop> LoopFusionAdapter::takeLaterLoops() {
  std::vector<LaterLoop> out;
  guarded("takeLaterLoops (released or revoked loops lost)", [&] {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    out.swap(impl_->later);
  });
  return out;
}

bool LoopFusionAdapter::verifyKeyframeLoop(int index, int inliers, bool& has_loop, int& loop_index,
                                           LoopInfo& loop_info) {
  const bool use = has_loop && verifyLoop(index, loop_index, loop_info, inliers);
  if (!use) dropLoop(has_loop, loop_index, loop_info);
  return use;
}

bool LoopFusionAdapter::commitStoredLoop(int query_index, int match_index, const LoopInfo& loop_info) {
  Impl& m = *impl_;
  bool kept = false;
  guarded("commitStoredLoop(" + std::to_string(query_index) + ", " + std::to_string(match_index) + ")", [&] {
    std::lock_guard<std::mutex> lock(m.mutex);
    if (m.mode != Impl::Mode::kVerifying) {
      kept = m.mode == Impl::Mode::kFallback;
      return;
    }
    const core::LoopCandidate c = core::candidateFromLoopInfo(query_index, match_index, loop_info.data(), -1);
    const core::Status s = m.host->verifier()->commit(c);
    if (!s.ok)
      ROS_WARN("[rover] stored loop %d -> %d of the loaded pose graph refused by the verifier (%s): dropped, "
               "loop_fusion does not use it either", query_index,
               match_index, s.message.c_str());
    kept = s.ok;
  });
  return kept;
}

void LoopFusionAdapter::keepStoredLoop(int index, bool& has_loop, int& loop_index, LoopInfo& loop_info) {
  if (!has_loop) return;
  if (!commitStoredLoop(index, loop_index, loop_info)) dropLoop(has_loop, loop_index, loop_info);
}

bool LoopFusionAdapter::verifying() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->mode == Impl::Mode::kVerifying;
}

size_t LoopFusionAdapter::verdictCount() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->verdicts;
}

size_t LoopFusionAdapter::heldCount() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->host ? impl_->host->heldCount() : 0;  // the host keeps the held candidates' verdicts
}

}  // namespace rover_loop_fusion
