// A stand-in for the patched loop_fusion_node, for tests of what happens at start-up
// (test_adapter.cpp runs it as a child process): ros::init, then the adapter calls in the
// order the patch makes them (setIMUFlag -> initialize, addKeyFrame -> addKeyframe /
// verifyKeyframeLoop). Prints one line per step so the test can tell how far it got; a verifier that
// cannot start must stop the process inside initialize().
#include "rover_loop_fusion/ros/loop_fusion_adapter.h"

#include <ros/ros.h>

#include <cstdio>

int main(int argc, char** argv) {
  ros::init(argc, argv, "loop_fusion");
  ros::NodeHandle n("~");  // loop_fusion: posegraph.registerPub(n)
  rover_loop_fusion::LoopFusionAdapter rover;
  const bool verifying = rover.initialize(true);
  std::printf("host: initialize returned %s\n", verifying ? "true" : "false");
  std::fflush(stdout);
  for (int i = 0; i < 60; ++i)
    rover.addKeyframe(i, 1.0 + i, 1, Eigen::Vector3d(0.5 * i, 0.0, 0.0), Eigen::Matrix3d::Identity());
  // findConnection found a loop 59 -> 2 (the keyframe's has_loop, loop_index, loop_info)
  bool has_loop = true;
  int loop_index = 2;
  rover_loop_fusion::LoopFusionAdapter::LoopInfo loop_info;
  loop_info << 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0;
  const bool used = rover.verifyKeyframeLoop(59, 40, has_loop, loop_index, loop_info);
  std::printf("host: verifyLoop returned %s\n", used ? "true" : "false");
  return 0;
}
