// Loading, starting and calling a verifier plugin: shared by the loop_fusion adapter and
// rover_verifier_node, so that both accept the same type names, report the same errors and
// never let an exception of a plugin escape.
#pragma once

#include "rover_loop_fusion/ros/loop_verifier.h"

#include <ros/node_handle.h>

#include <functional>
#include <memory>
#include <string>

namespace rover_loop_fusion {

/// A verifier instance. For plugins the deleter keeps pluginlib's class loader alive until
/// the instance is gone (the loader must outlive what it created).
typedef std::unique_ptr<LoopVerifier, std::function<void(LoopVerifier*)>> VerifierPtr;

extern const char kTrajectoryPriorVerifierType[];  ///< "rover_loop_fusion/TrajectoryPriorVerifier"
extern const char kAcceptAllVerifierType[];        ///< "rover_loop_fusion/AcceptAllVerifier"

/// The plugin type for a configured name: the short names `rover` and `accept_all` (as in the
/// launch files' verifier:= argument) or a full pluginlib type, returned unchanged.
std::string resolveVerifierType(const std::string& type_or_alias);

/// Creates an instance of the plugin `type` (after resolveVerifierType) with pluginlib. On
/// failure returns null and sets *error, naming the parameter `type_param` it came from and
/// listing the available types. Never throws.
VerifierPtr loadVerifierPlugin(const std::string& type, const std::string& type_param, std::string* error);

/// Calls verifier.initialize(name, nh, host) and catches what it throws. On failure returns
/// false and sets *error to "<type>: <why>".
bool initializeVerifier(LoopVerifier& verifier, const std::string& type, const std::string& name,
                        ros::NodeHandle& nh, const HostInfo& host, std::string* error);

/// An invalid_input rejection of c that says why.
core::Verdict rejection(const core::LoopCandidate& c, const std::string& detail);

/// One decision on c: verifier.verify(c) and, if it accepts, verifier.commit(c). A refused
/// commit turns the verdict into an invalid_input rejection; an exception from the plugin
/// gives a rejection and a ROS_ERROR naming `type`. Never throws.
core::Verdict verifyAndCommit(LoopVerifier& verifier, const std::string& type, const core::LoopCandidate& c);

/// A verifier_name must be a plain graph-resource name (the plugin's parameter namespace).
bool validVerifierName(const std::string& name);

}  // namespace rover_loop_fusion
