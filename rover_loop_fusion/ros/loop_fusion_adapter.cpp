#include "rover_loop_fusion/ros/loop_fusion_adapter.h"

#include "rover_loop_fusion/LoopCandidate.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/ros/verdict_output.h"
#include "rover_loop_fusion/ros/verifier_loader.h"

#include <Eigen/Geometry>
#include <ros/console.h>
#include <ros/init.h>
#include <ros/this_node.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <mutex>
#include <unordered_map>
#include <vector>

namespace rover_loop_fusion {

namespace {

const char kFallbackVerifierType[] = "fallback:accept_all";

/// The adapter's own parameters (the plugin reads its own from ~<verifier_name>/).
struct AdapterParams {
  std::string verifier_type = kTrajectoryPriorVerifierType;
  std::string verifier_name = "rover";
  bool fallback_to_accept_all = false;
  std::string verdict_log;
  std::string marker_frame = "world";
  bool publish_markers = true;
};

std::string join(const std::vector<std::string>& parts, const char* sep) {
  std::string out;
  for (const std::string& p : parts) out += (out.empty() ? "" : sep) + p;
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

}  // namespace

struct LoopFusionAdapter::Impl {
  enum class Mode { kUninitialized, kVerifying, kFallback, kFailed };
  struct KeyframeInfo {
    double stamp = 0.0;
    Eigen::Vector3d position = Eigen::Vector3d::Zero();  // VIO position as handed in
  };
  mutable std::mutex mutex;
  Mode mode = Mode::kUninitialized;
  std::string failure;  // why kFallback / kFailed
  std::string verifier_type;
  AdapterParams params;
  std::unique_ptr<ros::NodeHandle> nh;
  VerifierPtr verifier;
  VerdictOutput output;
  bool output_ready = false;
  ros::Publisher candidate_pub;  // ~loop_candidates: every candidate, before it is verified
  std::unordered_map<int64_t, KeyframeInfo> keyframes;
  size_t verdicts = 0;

  /// start() that never throws: an exception leaves the adapter failed (loops rejected).
  bool safeStart(bool use_imu, VerifierPtr injected, const std::string& injected_type);
  bool start(bool use_imu, VerifierPtr injected, const std::string& injected_type);
  [[noreturn]] void fatal(const std::string& message);
  void publishCandidate(const core::LoopCandidate& c, const LoopInfo& loop_info);
  void publish(const core::Verdict& v, const core::LoopCandidate& c, const std::string& type);
  bool findPosition(const std::vector<core::TrajectoryPoint>& trajectory, int64_t index,
                    Eigen::Vector3d* position) const;
};

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

  std::vector<std::string> errors;
  ParamReader r(*nh, &errors);
  r.text("verifier_type", &params.verifier_type);
  r.text("verifier_name", &params.verifier_name);
  r.boolean("fallback_to_accept_all", &params.fallback_to_accept_all);
  r.text("verdict_log", &params.verdict_log);
  r.text("marker_frame", &params.marker_frame);
  r.boolean("publish_markers", &params.publish_markers);
  if (!validVerifierName(params.verifier_name))
    r.error("verifier_name", "must be a plain name such as rover (got '" + params.verifier_name + "')");
  if (params.marker_frame.empty()) r.error("marker_frame", "must not be empty");
  if (!errors.empty()) fatal(join(errors, "; "));

  VerdictOutput::Options o;
  o.frame_id = params.marker_frame;
  o.markers = params.publish_markers;
  o.csv_path = params.verdict_log;
  std::string output_error;
  if (!output.initialize(*nh, o, &output_error))
    fatal("parameter " + nh->resolveName("verdict_log") + ": " + output_error);
  output_ready = true;
  candidate_pub = nh->advertise<LoopCandidate>("loop_candidates", 100);

  std::string plugin_error;
  if (injected) {
    verifier = std::move(injected);
    verifier_type = injected_type;
  } else {
    verifier_type = resolveVerifierType(params.verifier_type);
    verifier = loadVerifierPlugin(params.verifier_type, nh->resolveName("verifier_type"), &plugin_error);
  }
  if (verifier) {
    HostInfo host;
    host.uses_imu = use_imu;
    host.shifts_sequences = true;  // loop_fusion hands poses after its w_r_vio/w_t_vio shift
    initializeVerifier(*verifier, verifier_type, params.verifier_name, *nh, host, &plugin_error);
  }
  if (plugin_error.empty()) {
    mode = Mode::kVerifying;
    ROS_INFO("[rover] verifying loop candidates with %s (parameters in %s)%s%s", verifier_type.c_str(),
             nh->resolveName(params.verifier_name).c_str(),
             params.verdict_log.empty() ? "" : ", verdict log ", params.verdict_log.c_str());
    return true;
  }
  verifier.reset();
  if (params.fallback_to_accept_all) {
    mode = Mode::kFallback;
    failure = plugin_error;
    ROS_ERROR("[rover] the loop verifier cannot start: %s. %s is true: every loop candidate is "
              "ACCEPTED WITHOUT VERIFICATION (upstream loop_fusion behaviour).",
              plugin_error.c_str(), nh->resolveName("fallback_to_accept_all").c_str());
    return false;
  }
  fatal(plugin_error + ". Fix that parameter, or set " + nh->resolveName("fallback_to_accept_all") +
        ": true to run without verification");
}

bool LoopFusionAdapter::Impl::findPosition(const std::vector<core::TrajectoryPoint>& trajectory,
                                           int64_t index, Eigen::Vector3d* position) const {
  if (findTrajectoryPosition(trajectory, index, position)) return true;
  auto kf = keyframes.find(index);
  if (kf == keyframes.end()) return false;
  *position = kf->second.position;
  return true;
}

void LoopFusionAdapter::Impl::publishCandidate(const core::LoopCandidate& c, const LoopInfo& loop_info) {
  // Named by stamp (index -1): loop_fusion's keyframe indices count only the keyframe poses it
  // turned into keyframes, whereas rover_verifier_node numbers every pose it receives.
  LoopCandidate m;
  auto q = keyframes.find(c.query_index), k = keyframes.find(c.match_index);
  if (q != keyframes.end()) m.query_stamp = ros::Time(std::max(0.0, q->second.stamp));
  if (k != keyframes.end()) m.match_stamp = ros::Time(std::max(0.0, k->second.stamp));
  m.header.stamp = m.query_stamp;
  m.header.frame_id = params.marker_frame;
  m.query_index = -1;
  m.match_index = -1;
  m.relative_pose.position.x = loop_info(0);
  m.relative_pose.position.y = loop_info(1);
  m.relative_pose.position.z = loop_info(2);
  m.relative_pose.orientation.w = loop_info(3);
  m.relative_pose.orientation.x = loop_info(4);
  m.relative_pose.orientation.y = loop_info(5);
  m.relative_pose.orientation.z = loop_info(6);
  m.relative_yaw = loop_info(7) * M_PI / 180.0;
  m.inliers = c.inliers;
  candidate_pub.publish(m);
}

void LoopFusionAdapter::Impl::publish(const core::Verdict& v, const core::LoopCandidate& c,
                                      const std::string& type) {
  if (v.accepted)
    ROS_INFO("[rover] loop %ld -> %ld accepted: %s", static_cast<long>(c.query_index),
             static_cast<long>(c.match_index), v.detail.c_str());
  else
    ROS_INFO("[rover] loop %ld -> %ld REJECTED (%s): %s", static_cast<long>(c.query_index),
             static_cast<long>(c.match_index), core::toString(v.reason), v.detail.c_str());
  if (!output_ready) return;
  VerdictContext ctx;
  ctx.inliers = c.inliers;
  ctx.verifier = type;
  auto q = keyframes.find(c.query_index), m = keyframes.find(c.match_index);
  if (q != keyframes.end()) ctx.query_stamp = q->second.stamp;
  if (m != keyframes.end()) ctx.match_stamp = m->second.stamp;
  if (params.publish_markers) {
    // Markers at the verifier's current estimate (after the commit of an accepted loop),
    // the keyframes' VIO positions for verifiers that keep no trajectory.
    std::vector<core::TrajectoryPoint> trajectory;
    if (mode == Mode::kVerifying && verifier) trajectory = verifier->trajectory();
    ctx.have_positions = findPosition(trajectory, c.query_index, &ctx.query_position) &&
                         findPosition(trajectory, c.match_index, &ctx.match_position);
  }
  output.publish(v, ctx);
  ++verdicts;
}

LoopFusionAdapter::LoopFusionAdapter() : impl_(new Impl) {}

LoopFusionAdapter::~LoopFusionAdapter() = default;

bool LoopFusionAdapter::Impl::safeStart(bool use_imu, VerifierPtr injected, const std::string& injected_type) {
  try {
    return start(use_imu, std::move(injected), injected_type);
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] LoopFusionAdapter::initialize: %s; every loop is rejected", e.what());
  } catch (...) {
    ROS_ERROR("[rover] LoopFusionAdapter::initialize: unknown exception; every loop is rejected");
  }
  std::lock_guard<std::mutex> lock(mutex);
  mode = Mode::kFailed;
  failure = "initialize() failed with an exception";
  return false;
}

bool LoopFusionAdapter::initialize(bool use_imu) { return impl_->safeStart(use_imu, VerifierPtr(), ""); }

bool LoopFusionAdapter::initializeWithVerifier(bool use_imu, std::unique_ptr<LoopVerifier> verifier,
                                               const std::string& verifier_type) {
  return impl_->safeStart(use_imu, VerifierPtr(verifier.release(), std::default_delete<LoopVerifier>()),
                          verifier_type);
}

void LoopFusionAdapter::addKeyframe(int index, double stamp, int sequence, const Eigen::Vector3d& P,
                                    const Eigen::Matrix3d& R) {
  try {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    Impl::KeyframeInfo& kf = impl_->keyframes[index];
    kf.stamp = stamp;
    kf.position = P;
    if (impl_->mode != Impl::Mode::kVerifying) return;
    const core::Status s = impl_->verifier->addKeyframe(index, stamp, sequence, P, Eigen::Quaterniond(R));
    if (!s.ok)
      ROS_WARN("[rover] keyframe %d not added to the verifier (%s); loops that involve it are rejected",
               index, s.message.c_str());
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] addKeyframe(%d): %s; loops that involve it are rejected", index, e.what());
  } catch (...) {
    ROS_ERROR("[rover] addKeyframe(%d): unknown exception; loops that involve it are rejected", index);
  }
}

bool LoopFusionAdapter::verifyLoop(int query_index, int match_index, const LoopInfo& loop_info, int inliers) {
  bool accepted = false;  // fail closed: only a committed loop is handed back as usable
  try {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    Impl& m = *impl_;
    const core::LoopCandidate c = core::candidateFromLoopInfo(query_index, match_index, loop_info.data(), inliers);
    if (m.candidate_pub) {
      // Before the verdict: a recording of /vins_estimator/keyframe_pose and ~loop_candidates
      // can be replayed through rover_verifier_node with other parameters.
      try {
        m.publishCandidate(c, loop_info);
      } catch (const std::exception& e) {
        ROS_ERROR("[rover] publishing loop candidate %d -> %d failed: %s", query_index, match_index, e.what());
      } catch (...) {
        ROS_ERROR("[rover] publishing loop candidate %d -> %d failed", query_index, match_index);
      }
    }
    core::Verdict v;
    std::string type = m.verifier_type;
    switch (m.mode) {
      case Impl::Mode::kUninitialized:
        ROS_ERROR_THROTTLE(10.0, "[rover] loop %d -> %d rejected: LoopFusionAdapter::initialize was never "
                           "called (is the patch complete?)", query_index, match_index);
        return false;
      case Impl::Mode::kFailed:
        v = rejection(c, "verifier not running: " + m.failure);
        break;
      case Impl::Mode::kFallback:
        type = kFallbackVerifierType;
        v.query_index = c.query_index;
        v.match_index = c.match_index;
        v.accepted = true;
        v.reason = core::Reason::kAccepted;
        v.detail = "not verified (fallback_to_accept_all; the verifier could not start: " + m.failure + ")";
        accepted = true;
        break;
      case Impl::Mode::kVerifying:
        v = verifyAndCommit(*m.verifier, type, c);
        accepted = v.accepted;
        break;
    }
    try {
      m.publish(v, c, type);
    } catch (const std::exception& e) {
      ROS_ERROR("[rover] publishing the verdict on loop %d -> %d failed: %s", query_index, match_index, e.what());
    } catch (...) {
      ROS_ERROR("[rover] publishing the verdict on loop %d -> %d failed", query_index, match_index);
    }
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] verifyLoop(%d, %d): %s", query_index, match_index, e.what());
  } catch (...) {
    ROS_ERROR("[rover] verifyLoop(%d, %d): unknown exception", query_index, match_index);
  }
  return accepted;
}

bool LoopFusionAdapter::commitStoredLoop(int query_index, int match_index, const LoopInfo& loop_info) {
  try {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    if (impl_->mode != Impl::Mode::kVerifying) return impl_->mode == Impl::Mode::kFallback;
    const core::LoopCandidate c = core::candidateFromLoopInfo(query_index, match_index, loop_info.data(), -1);
    const core::Status s = impl_->verifier->commit(c);
    if (!s.ok) {
      ROS_WARN("[rover] stored loop %d -> %d of the loaded pose graph not added to the verifier: %s",
               query_index, match_index, s.message.c_str());
      return false;
    }
    return true;
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] commitStoredLoop(%d, %d): %s", query_index, match_index, e.what());
  } catch (...) {
    ROS_ERROR("[rover] commitStoredLoop(%d, %d): unknown exception", query_index, match_index);
  }
  return false;
}

bool LoopFusionAdapter::verifying() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->mode == Impl::Mode::kVerifying;
}

size_t LoopFusionAdapter::verdictCount() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->verdicts;
}

}  // namespace rover_loop_fusion
