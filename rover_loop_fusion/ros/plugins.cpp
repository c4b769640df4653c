// The two verifier plugins:
//   rover_loop_fusion/TrajectoryPriorVerifier  ROVER: the trajectory-prior test (core::Verifier)
//   rover_loop_fusion/AcceptAllVerifier        accepts every candidate, as upstream
//                                              loop_fusion does (the A side of an A/B test)
#include "rover_loop_fusion/core/parameters.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/ros/verifier_host.h"

#include <pluginlib/class_list_macros.hpp>
#include <ros/console.h>

#include <cmath>
#include <memory>
#include <sstream>

namespace rover_loop_fusion {

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
  std::vector<core::LoopDecision> takeDecisions() override { return verifier_->takeDecisions(); }
  bool estimate(int64_t index, core::Pose* pose) const override { return verifier_->estimate(index, pose); }
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
                  "loop_fusion, which shifts sessions itself, true in rover_verifier_node; accept_without_prior, "
                  "confirm_without_prior: from the host's ~relocalisation). Remove it from the YAML.",
                  privateNodeHandle().resolveName(key).c_str());
    load.config.host.anchor_incoming_keyframes = !host().shifts_sequences;
    load.config.host.accept_without_prior = host().relocalisation == Relocalisation::kAcceptUnverified;
    load.config.host.confirm_without_prior = host().relocalisation == Relocalisation::kConfirm;
    verifier_.reset(new core::Verifier(load.config));
    ROS_INFO("[rover] %s: trajectory-prior verifier, decision parameters: %s", privateNodeHandle().getNamespace().c_str(),
             core::describe(verifier_->config()).c_str());
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
    return core::Verdict::Accept(c, "accept_all: no verification (upstream loop_fusion behaviour)");
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
