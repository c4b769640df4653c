// rover_verifier_node: see rover_loop_fusion/ros/verifier_node.h and docs/ros-api.md.
#include "rover_loop_fusion/ros/verifier_node.h"

#include <ros/ros.h>

#include <atomic>
#include <csignal>

namespace {

std::atomic<bool> g_stop(false);

/// SIGINT/SIGTERM (roslaunch, Ctrl-C): only sets a flag (async-signal-safe); the node then
/// finishes the verification under way and shuts down cleanly (VerifierNode::spin).
void onSignal(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "rover_verifier", ros::init_options::NoSigintHandler);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  int status = 1;
  {
    ros::NodeHandle nh, pnh("~");
    rover_loop_fusion::VerifierNode node(nh, pnh);
    std::string error;
    if (node.start(&error)) {
      status = node.spin(g_stop);
    } else {
      ROS_FATAL("[rover] %s cannot start: %s", ros::this_node::getName().c_str(), error.c_str());
    }
  }
  ros::shutdown();
  return status;
}
