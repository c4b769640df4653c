// The two verifier plugins:
//   rover_loop_fusion/TrajectoryPriorVerifier  ROVER: the trajectory-prior test (core::Verifier)
//   rover_loop_fusion/AcceptAllVerifier        accepts every candidate, as upstream
//                                              loop_fusion does (the A side of an A/B test)
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"

#include <pluginlib/class_list_macros.hpp>
#include <ros/console.h>

#include <memory>

namespace rover_loop_fusion {

class TrajectoryPriorVerifier : public LoopVerifier {
 public:
  core::Status addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                           const Eigen::Quaterniond& q) override {
    return verifier_->addKeyframe(index, stamp, sequence, t, q);
  }
  core::Verdict verify(const core::LoopCandidate& c) override { return verifier_->verify(c); }
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
    if (!host().shifts_sequences) load.config.anchor_incoming_keyframes = true;
    verifier_.reset(new core::Verifier(load.config));
    const core::VerifierConfig& c = verifier_->config();
    ROS_INFO("[rover] %s: trajectory-prior verifier, %s graph, %s alignment, threshold %.2f m, "
             "time budget %.0f ms, candidates without a prior %s",
             name().c_str(), core::toString(c.mode), core::toString(c.alignment), c.threshold,
             c.time_budget_ms, c.accept_without_prior ? "accepted" : "rejected");
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
