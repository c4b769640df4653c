// Reading the verifier's parameters from the ROS parameter server.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <ros/node_handle.h>

#include <string>
#include <vector>

namespace rover_loop_fusion {

struct ConfigLoad {
  core::VerifierConfig config;
  std::vector<std::string> errors;    ///< a parameter of the wrong type or value
  std::vector<std::string> warnings;  ///< e.g. an unknown key (a typo?) in the namespace
  bool ok() const { return errors.empty(); }
};

/// Reads every verifier parameter from `nh`'s namespace (see config/rover_indoor.yaml for the
/// list), falling back to the defaults for absent keys. A key with the wrong type or an
/// invalid value is an error that names the full parameter. `mode: auto` (the default)
/// means 4-DoF when the host uses an IMU, 6-DoF otherwise.
ConfigLoad loadVerifierConfig(const ros::NodeHandle& nh, bool host_uses_imu);

/// Names of all verifier parameters (for documentation checks and typo warnings).
const std::vector<std::string>& verifierParameterNames();

}  // namespace rover_loop_fusion
