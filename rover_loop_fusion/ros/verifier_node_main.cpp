// rover_verifier_node: see rover_loop_fusion/ros/verifier_node.h and docs/ros-api.md.
#include "rover_loop_fusion/ros/verifier_node.h"

#include <ros/ros.h>

int main(int argc, char** argv) {
  ros::init(argc, argv, "rover_verifier");
  ros::NodeHandle nh, pnh("~");
  rover_loop_fusion::VerifierNode node(nh, pnh);
  std::string error;
  if (!node.start(&error)) {
    ROS_FATAL("[rover] %s cannot start: %s", ros::this_node::getName().c_str(), error.c_str());
    return 1;
  }
  ros::spin();
  node.finish();
  return 0;
}
