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

/// Reads typed parameters of one namespace: a present key of the wrong type is an error
/// ("parameter /full/name must be ...") appended to `errors`; an absent key leaves the value.
class ParamReader {
 public:
  ParamReader(const ros::NodeHandle& nh, std::vector<std::string>* errors);
  void number(const std::string& key, double* value);  ///< int or double
  void integer(const std::string& key, int* value);
  void boolean(const std::string& key, bool* value);
  void text(const std::string& key, std::string* value);
  /// Records an error about `key` (full parameter name + `what`).
  void error(const std::string& key, const std::string& what);

 private:
  void wrongType(const std::string& key, const char* expected);
  const ros::NodeHandle& nh_;
  std::vector<std::string>* errors_;
};

/// Reads every verifier parameter (the table of core/parameters.h; config/rover_template.yaml
/// lists them) from `nh`'s namespace, falling back to the defaults for absent keys. A key with
/// the wrong type or out of its range is an error that names the full parameter; a key that is
/// not in the table is a warning (a typo?). `mode: auto` (the default) means 4-DoF when the host
/// uses an IMU, 6-DoF otherwise.
ConfigLoad loadVerifierConfig(const ros::NodeHandle& nh, bool host_uses_imu);

/// Names of all verifier parameters, from the table (for documentation checks and typo warnings).
const std::vector<std::string>& verifierParameterNames();

}  // namespace rover_loop_fusion
