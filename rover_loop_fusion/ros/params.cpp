#include "rover_loop_fusion/ros/params.h"

#include <ros/param.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace rover_loop_fusion {

ParamReader::ParamReader(const ros::NodeHandle& nh, std::vector<std::string>* errors)
    : nh_(nh), errors_(errors) {}

void ParamReader::number(const std::string& key, double* value) {
  XmlRpc::XmlRpcValue v;
  if (!nh_.getParam(key, v)) return;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble) *value = static_cast<double>(v);
  else if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) *value = static_cast<int>(v);
  else wrongType(key, "a number");
}

void ParamReader::integer(const std::string& key, int* value) {
  XmlRpc::XmlRpcValue v;
  if (!nh_.getParam(key, v)) return;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeInt) *value = static_cast<int>(v);
  else wrongType(key, "an integer");
}

void ParamReader::boolean(const std::string& key, bool* value) {
  XmlRpc::XmlRpcValue v;
  if (!nh_.getParam(key, v)) return;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeBoolean) *value = static_cast<bool>(v);
  else wrongType(key, "true or false");
}

void ParamReader::text(const std::string& key, std::string* value) {
  XmlRpc::XmlRpcValue v;
  if (!nh_.getParam(key, v)) return;
  if (v.getType() == XmlRpc::XmlRpcValue::TypeString) *value = static_cast<std::string>(v);
  else wrongType(key, "a string");
}

void ParamReader::error(const std::string& key, const std::string& what) {
  errors_->push_back("parameter " + nh_.resolveName(key) + " " + what);
}

void ParamReader::wrongType(const std::string& key, const char* expected) {
  error(key, std::string("must be ") + expected);
}

const std::vector<std::string>& verifierParameterNames() {
  static const std::vector<std::string> names = {
      "mode", "alignment", "threshold", "threshold_per_metre", "max_threshold", "max_innovation", "max_innovation_per_metre", "accept_without_prior", "max_iterations",
      "time_budget_ms", "function_tolerance", "odometry_neighbours", "loop_huber",
      "robust_candidate", "window_margin", "max_relative_translation", "max_relative_yaw_deg",
      "quaternion_tolerance", "anchor_incoming_keyframes"};
  return names;
}

ConfigLoad loadVerifierConfig(const ros::NodeHandle& nh, bool host_uses_imu) {
  ConfigLoad out;
  core::VerifierConfig& c = out.config;
  ParamReader r(nh, &out.errors);

  std::string mode = "auto";
  r.text("mode", &mode);
  if (mode == "auto") c.mode = host_uses_imu ? core::Mode::kFourDof : core::Mode::kSixDof;
  else if (!core::parseMode(mode, &c.mode)) r.error("mode", "must be auto, 4dof or 6dof (got '" + mode + "')");
  std::string alignment = "se3";
  r.text("alignment", &alignment);
  if (!core::parseAlignment(alignment, &c.alignment))
    r.error("alignment", "must be se3 or sim3 (got '" + alignment + "')");

  r.number("threshold", &c.threshold);
  r.number("threshold_per_metre", &c.threshold_per_metre);
  r.number("max_threshold", &c.max_threshold);
  r.number("max_innovation", &c.max_innovation);
  r.number("max_innovation_per_metre", &c.max_innovation_per_metre);
  r.boolean("accept_without_prior", &c.accept_without_prior);
  r.integer("max_iterations", &c.max_iterations);
  r.number("time_budget_ms", &c.time_budget_ms);
  r.number("function_tolerance", &c.function_tolerance);
  r.integer("odometry_neighbours", &c.odometry_neighbours);
  r.number("loop_huber", &c.loop_huber);
  r.boolean("robust_candidate", &c.robust_candidate);
  r.integer("window_margin", &c.window_margin);
  r.number("max_relative_translation", &c.max_relative_translation);
  double yaw_deg = c.max_relative_yaw * 180.0 / M_PI;
  r.number("max_relative_yaw_deg", &yaw_deg);
  c.max_relative_yaw = yaw_deg * M_PI / 180.0;
  r.number("quaternion_tolerance", &c.quaternion_tolerance);
  r.boolean("anchor_incoming_keyframes", &c.anchor_incoming_keyframes);

  const std::string invalid = c.validate();
  if (!invalid.empty()) out.errors.push_back("in " + nh.getNamespace() + ": " + invalid);

  // Unknown keys directly in this namespace are most likely typos.
  std::vector<std::string> all;
  if (ros::param::getParamNames(all)) {
    const std::string prefix = nh.getNamespace() + "/";
    const std::vector<std::string>& known = verifierParameterNames();
    for (const std::string& p : all) {
      if (p.compare(0, prefix.size(), prefix) != 0) continue;
      const std::string key = p.substr(prefix.size());
      if (key.find('/') != std::string::npos) continue;
      if (std::find(known.begin(), known.end(), key) == known.end())
        out.warnings.push_back("unknown parameter " + p + " (ignored; a typo?)");
    }
  }
  return out;
}

}  // namespace rover_loop_fusion
