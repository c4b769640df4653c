// The pluginlib interface every loop verifier implements (base class
// rover_loop_fusion::LoopVerifier, see plugins.xml). The loop_fusion adapter and
// rover_verifier_node load one by type name and drive it with the same calls.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <ros/node_handle.h>

#include <string>
#include <vector>

namespace rover_loop_fusion {

/// What the host does with a loop between sequences that nothing connects yet (the first
/// relocalisation into a loaded map, the first loop between two sessions): there is no
/// trajectory prior to test it against, and it is the loop that moves a whole session.
/// Set on the host (~relocalisation), never in the verifier's YAML.
enum class Relocalisation {
  kReject,            ///< reject it (default, fail closed): the sessions stay apart
  kAcceptUnverified,  ///< use it unverified, as upstream loop_fusion does
  // Planned: confirm it with k mutually consistent candidates (with deferred loops).
};
const char* toString(Relocalisation policy);  ///< "reject", "accept_unverified"
bool parseRelocalisation(const std::string& text, Relocalisation* policy);

/// What the host process tells a verifier about itself.
struct HostInfo {
  /// 4-DoF (VIO) or 6-DoF (VO) pose graph; `mode: auto` follows this.
  bool uses_imu = true;
  /// true: keyframe poses arrive after the host's own first-loop sequence shift
  /// (loop_fusion); false: raw per-session VIO poses (rover_verifier_node), the verifier
  /// shifts them itself.
  bool shifts_sequences = true;
  /// The host's ~relocalisation policy.
  Relocalisation relocalisation = Relocalisation::kReject;
};

class LoopVerifier {
 public:
  virtual ~LoopVerifier() = default;

  /// Reads the plugin's parameters from `<nh namespace>/<name>/` and gets it ready.
  /// Returns false (and error() says why) when the parameters are unusable.
  bool initialize(const std::string& name, ros::NodeHandle& nh, const HostInfo& host = HostInfo()) {
    name_ = name;
    host_ = host;
    private_nh_ = ros::NodeHandle(nh, name);
    error_.clear();
    initialized_ = onInitialize();
    return initialized_;
  }

  virtual core::Status addKeyframe(int64_t index, double stamp, int sequence,
                                   const Eigen::Vector3d& t, const Eigen::Quaterniond& q) = 0;
  virtual core::Verdict verify(const core::LoopCandidate& candidate) = 0;
  virtual core::Status commit(const core::LoopCandidate& candidate) = 0;
  /// The verifier's current trajectory estimate; empty if it keeps none.
  virtual std::vector<core::TrajectoryPoint> trajectory() const { return {}; }

  const std::string& name() const { return name_; }
  bool initialized() const { return initialized_; }
  const std::string& error() const { return error_; }

 protected:
  LoopVerifier() = default;
  /// Called by initialize(); read parameters from privateNodeHandle(), set error() and return
  /// false on unusable ones.
  virtual bool onInitialize() = 0;
  ros::NodeHandle& privateNodeHandle() { return private_nh_; }
  const HostInfo& host() const { return host_; }
  void setError(const std::string& e) { error_ = e; }

 private:
  std::string name_;
  HostInfo host_;
  ros::NodeHandle private_nh_;
  std::string error_;
  bool initialized_ = false;
};

}  // namespace rover_loop_fusion
