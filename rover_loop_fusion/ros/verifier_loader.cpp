#include "rover_loop_fusion/ros/verifier_loader.h"

#include <pluginlib/class_loader.hpp>
#include <ros/console.h>
#include <ros/names.h>

#include <algorithm>
#include <vector>

namespace rover_loop_fusion {

const char kTrajectoryPriorVerifierType[] = "rover_loop_fusion/TrajectoryPriorVerifier";
const char kAcceptAllVerifierType[] = "rover_loop_fusion/AcceptAllVerifier";

std::string resolveVerifierType(const std::string& type_or_alias) {
  if (type_or_alias == "rover") return kTrajectoryPriorVerifierType;
  if (type_or_alias == "accept_all") return kAcceptAllVerifierType;
  return type_or_alias;
}

VerifierPtr loadVerifierPlugin(const std::string& type_or_alias, const std::string& type_param,
                               std::string* error) {
  typedef pluginlib::ClassLoader<LoopVerifier> Loader;
  const std::string type = resolveVerifierType(type_or_alias);
  try {
    std::shared_ptr<Loader> loader =
        std::make_shared<Loader>("rover_loop_fusion", "rover_loop_fusion::LoopVerifier");
    if (!loader->isClassAvailable(type)) {
      std::vector<std::string> known = loader->getDeclaredClasses();
      std::sort(known.begin(), known.end());
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      *error = "parameter " + type_param + ": unknown verifier type '" + type_or_alias + "' (available: " + list +
               "; or rover, accept_all)";
      return VerifierPtr();
    }
    auto instance = loader->createUniqueInstance(type);
    if (!instance) {
      *error = "parameter " + type_param + ": pluginlib returned no instance of '" + type + "'";
      return VerifierPtr();
    }
    auto deleter = instance.get_deleter();
    LoopVerifier* raw = instance.release();
    // The deleter holds the loader: it is destroyed after the instance it created.
    return VerifierPtr(raw, [loader, deleter](LoopVerifier* p) { deleter(p); });
  } catch (const std::exception& e) {
    *error = "parameter " + type_param + ": cannot load verifier plugin '" + type + "': " + e.what();
  } catch (...) {
    *error = "parameter " + type_param + ": cannot load verifier plugin '" + type + "'";
  }
  return VerifierPtr();
}

bool initializeVerifier(LoopVerifier& verifier, const std::string& type, const std::string& name,
                        ros::NodeHandle& nh, const HostInfo& host, std::string* error) {
  try {
    if (verifier.initialize(name, nh, host)) return true;
    *error = type + ": " + verifier.error();
  } catch (const std::exception& e) {
    *error = type + ": initialize threw: " + e.what();
  } catch (...) {
    *error = type + ": initialize threw";
  }
  return false;
}

core::Verdict rejection(const core::LoopCandidate& c, const std::string& detail) {
  core::Verdict v;
  v.query_index = c.query_index;
  v.match_index = c.match_index;
  v.accepted = false;
  v.reason = core::Reason::kInvalidInput;
  v.detail = detail;
  return v;
}

core::Verdict verifyAndCommit(LoopVerifier& verifier, const std::string& type, const core::LoopCandidate& c) {
  const long q = static_cast<long>(c.query_index), m = static_cast<long>(c.match_index);
  try {
    core::Verdict v = verifier.verify(c);
    if (v.accepted) {
      const core::Status s = verifier.commit(c);
      if (!s.ok) {
        v.accepted = false;
        v.reason = core::Reason::kInvalidInput;
        v.detail += "; but the verifier refused to commit it: " + s.message;
      }
    }
    return v;
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] verifier %s threw on loop %ld -> %ld: %s", type.c_str(), q, m, e.what());
    return rejection(c, std::string("the verifier threw an exception: ") + e.what());
  } catch (...) {
    ROS_ERROR("[rover] verifier %s threw on loop %ld -> %ld", type.c_str(), q, m);
    return rejection(c, "the verifier threw an exception");
  }
}

bool validVerifierName(const std::string& name) {
  std::string why;
  return !name.empty() && ros::names::validate(name, why) && name.find('/') == std::string::npos && name[0] != '~';
}

}  // namespace rover_loop_fusion
