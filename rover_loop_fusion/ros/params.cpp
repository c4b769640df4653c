#include "rover_loop_fusion/ros/params.h"

#include "rover_loop_fusion/core/parameters.h"

#include <ros/param.h>
#include <xmlrpcpp/XmlRpcValue.h>

#include <algorithm>

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
  else if (v.getType() == XmlRpc::XmlRpcValue::TypeDouble) {
    std::string got = core::formatNumber(static_cast<double>(v));
    if (got.find_first_of(".en") == std::string::npos) got += ".0";  // (a floating-point value, as written)
    error(key, "must be an integer (got " + got + ", not an integer: write it without a point or exponent)");
  }
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
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const core::Parameter& p : core::verifierParameters()) n.push_back(p.name);
    return n;
  }();
  return names;
}

ConfigLoad loadVerifierConfig(const ros::NodeHandle& nh, bool host_uses_imu) {
  ConfigLoad out;
  // Every key of the parameter table (core/parameters.h): type and range checked by its row.
  for (const core::Parameter& p : core::verifierParameters()) {
    XmlRpc::XmlRpcValue v;
    if (!nh.getParam(p.name, v)) continue;
    core::ParameterValue value;
    switch (v.getType()) {
      case XmlRpc::XmlRpcValue::TypeInt: value = core::ParameterValue::Number(static_cast<int>(v), true); break;
      case XmlRpc::XmlRpcValue::TypeDouble: value = core::ParameterValue::Number(static_cast<double>(v), false); break;
      case XmlRpc::XmlRpcValue::TypeBoolean: value = core::ParameterValue::Boolean(static_cast<bool>(v)); break;
      case XmlRpc::XmlRpcValue::TypeString: value = core::ParameterValue::Text(static_cast<std::string>(v)); break;
      default: value = core::ParameterValue::Text("<" + v.toXml() + ">"); break;  // a list or a map: wrong type
    }
    std::string why;
    if (!core::assignParameter(p, value, &out.config, &why, host_uses_imu))
      out.errors.push_back("parameter " + nh.resolveName(p.name) + why.substr(p.name.size()));
  }
  // `mode: auto` is the default here (the host decides), not the core's 4dof.
  if (!nh.hasParam("mode")) out.config.mode = host_uses_imu ? core::Mode::kFourDof : core::Mode::kSixDof;
  const std::string invalid = out.config.validate();  // the rows' ranges again: a safety net
  if (!invalid.empty() && out.errors.empty()) out.errors.push_back("in " + nh.getNamespace() + ": " + invalid);

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
