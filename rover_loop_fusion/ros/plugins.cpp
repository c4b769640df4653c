// The two verifier plugins:
//   rover_loop_fusion/TrajectoryPriorVerifier  ROVER: the trajectory-prior test (core::Verifier)
//   rover_loop_fusion/AcceptAllVerifier        accepts every candidate, as upstream
//                                              loop_fusion does (the A side of an A/B test)
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/ros/verifier_host.h"

#include <pluginlib/class_list_macros.hpp>
#include <ros/console.h>

#include <cmath>
#include <memory>
#include <sstream>

namespace rover_loop_fusion {

namespace {

/// Every decision parameter as name=value, in the YAML's names and units (one line for the
/// start-up log). To be replaced by the core's describe(config) once it has one.
std::string describe(const core::VerifierConfig& c) {
  std::ostringstream s;
  s << "mode=" << core::toString(c.mode) << " alignment=" << core::toString(c.alignment)
    << " threshold=" << c.threshold << " threshold_per_metre=" << c.threshold_per_metre
    << " max_threshold=" << c.max_threshold << " max_innovation=" << c.max_innovation
    << " max_innovation_per_metre=" << c.max_innovation_per_metre
    << " accept_without_prior=" << (c.accept_without_prior ? "true" : "false")
    << " max_iterations=" << c.max_iterations << " time_budget_ms=" << c.time_budget_ms
    << " function_tolerance=" << c.function_tolerance << " odometry_neighbours=" << c.odometry_neighbours
    << " loop_huber=" << c.loop_huber << " robust_candidate=" << (c.robust_candidate ? "true" : "false")
    << " window_margin=" << c.window_margin << " max_relative_translation=" << c.max_relative_translation
    << " max_relative_yaw_deg=" << c.max_relative_yaw * 180.0 / M_PI
    << " quaternion_tolerance=" << c.quaternion_tolerance
    << " anchor_incoming_keyframes=" << (c.anchor_incoming_keyframes ? "true" : "false");
  return s.str();
}

}  // namespace

class TrajectoryPriorVerifier : public LoopVerifier {
 public:
  core::Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                           const Eigen::Quaterniond& q) override {
    return verifier_->addKeyframe(index, stamp, sequence, t, q);
  }
  core::Verdict verify(const core::LoopCandidate& c) override {
    core::Verdict v = verifier_->verify(c);
    if (v.reason == core::Reason::kNoTrajectoryPrior)
      v.detail += std::string("; host policy relocalisation: ") + toString(host().relocalisation);
    return v;
  }
  core::Status commit(const core::LoopCandidate& c) override { return verifier_->commit(c); }
  std::vector<core::TrajectoryPoint> trajectory() const override { return verifier_->trajectory(); }

 protected:
  bool onInitialize() override {
    ConfigLoad load = loadVerifierConfig(privateNodeHandle(), host().uses_imu);
    for (const std::string& w : load.warnings) ROS_WARN("[rover] %s", w.c_str());
    if (!load.ok()) {
      std::string all;
      for (const std::string& e : load.errors) all += (all.empty() ? "" : "; ") + e;
      setError(all);
      return false;
    }
    // Set from the host, never from a YAML (a wrong anchor_incoming_keyframes shifts every
    // session twice under loop_fusion, or never in the node).
    for (const std::string& key : hostDerivedVerifierParameters())
      if (privateNodeHandle().hasParam(key))
        ROS_ERROR("[rover] parameter %s is ignored: the host sets it (anchor_incoming_keyframes: false under "
                  "loop_fusion, which shifts sessions itself, true in rover_verifier_node; accept_without_prior: "
                  "from the host's ~relocalisation). Remove it from the YAML.",
                  privateNodeHandle().resolveName(key).c_str());
    load.config.anchor_incoming_keyframes = !host().shifts_sequences;
    load.config.accept_without_prior = host().relocalisation == Relocalisation::kAcceptUnverified;
    verifier_.reset(new core::Verifier(load.config));
    ROS_INFO("[rover] %s: trajectory-prior verifier, decision parameters: %s", privateNodeHandle().getNamespace().c_str(),
             describe(verifier_->config()).c_str());
    return true;
  }

 private:
  std::unique_ptr<core::Verifier> verifier_;
};

class AcceptAllVerifier : public LoopVerifier {
 public:
  core::Status addKeyframe(int64_t, double, int, const Eigen::Vector3d&,
                           const Eigen::Quaterniond&) override {
    return core::Status::Ok();
  }
  core::Verdict verify(const core::LoopCandidate& c) override {
    core::Verdict v;
    v.query_index = c.query_index;
    v.match_index = c.match_index;
    v.accepted = true;
    v.reason = core::Reason::kAccepted;
    v.detail = "accept_all: no verification (upstream loop_fusion behaviour)";
    return v;
  }
  core::Status commit(const core::LoopCandidate&) override { return core::Status::Ok(); }

 protected:
  bool onInitialize() override {
    ROS_INFO("[rover] %s: accept-all verifier: every loop candidate is used, as upstream loop_fusion does",
             name().c_str());
    return true;
  }
};

}  // namespace rover_loop_fusion

PLUGINLIB_EXPORT_CLASS(rover_loop_fusion::TrajectoryPriorVerifier, rover_loop_fusion::LoopVerifier)
PLUGINLIB_EXPORT_CLASS(rover_loop_fusion::AcceptAllVerifier, rover_loop_fusion::LoopVerifier)
