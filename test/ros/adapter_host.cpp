// A stand-in for the patched loop_fusion_node, for tests of what happens at start-up
// (test_adapter.cpp runs it as a child process): ros::init, then the adapter calls in the
// order the patch makes them (setIMUFlag -> initialize, addKeyFrame -> addKeyframe /
// verifyKeyframeLoop). Prints one line per step so the test can tell how far it got; a verifier that
// cannot start must stop the process inside initialize().
//
// With --end-like-loop-fusion: a verifier that holds every candidate, and the end of upstream
// loop_fusion's main: ros::shutdown(), then it returns while a thread is still joinable
// (std::terminate, abort).
#include "rover_loop_fusion/ros/loop_fusion_adapter.h"
#include "rover_loop_fusion/ros/loop_verifier.h"

#include <ros/ros.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>

namespace {

class HoldEverything : public rover_loop_fusion::LoopVerifier {
 public:
  rover_loop_fusion::core::Status addKeyframe(int64_t, double, int, const Eigen::Vector3d&,
                                              const Eigen::Quaterniond&) override {
    return rover_loop_fusion::core::Status::Ok();
  }
  rover_loop_fusion::core::Verdict verify(const rover_loop_fusion::core::LoopCandidate& c) override {
    return rover_loop_fusion::core::Verdict::Defer(c, "held by the test host");
  }
  rover_loop_fusion::core::Status commit(const rover_loop_fusion::core::LoopCandidate&) override {
    return rover_loop_fusion::core::Status::Ok();
  }

 protected:
  bool onInitialize() override { return true; }
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "loop_fusion");
  const bool end_like_loop_fusion = argc > 1 && std::string(argv[1]) == "--end-like-loop-fusion";
  ros::NodeHandle n("~");  // loop_fusion: posegraph.registerPub(n)
  rover_loop_fusion::LoopFusionAdapter rover;
  const bool verifying =
      end_like_loop_fusion
          ? rover.initializeWithVerifier(true, std::unique_ptr<rover_loop_fusion::LoopVerifier>(new HoldEverything),
                                         "test/HoldEverything")
          : rover.initialize(true);
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
  if (!end_like_loop_fusion) return 0;
  std::thread process([] {  // loop_fusion's process(): runs until the process ends
    for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
  });
  ros::shutdown();  // loop_fusion's command() on 's' (and roscpp on Ctrl-C) before main returns
  std::printf("host: returning from main with a joinable thread\n");
  std::fflush(stdout);
  return 0;  // ~thread of a joinable thread: std::terminate, as loop_fusion's main after 's' or Ctrl-C
}
