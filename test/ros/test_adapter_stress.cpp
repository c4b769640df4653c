// Threading as in loop_fusion: the adapter is called from the keyframe thread (process() ->
// PoseGraph::addKeyFrame) while loop_fusion's optimisation thread solves the pose graph
// every few milliseconds under the keyframe-list mutex and ROS spinner threads deliver
// messages, including the verdicts and markers the adapter publishes. The test checks that
// every candidate gets exactly one verdict on the topic and one row in the CSV log (written on
// its own thread) and that the has_loop decisions match them. scripts/sanitize.sh tsan (part
// of scripts/test.sh) also runs it built with -DROVER_TSAN=ON: the ThreadSanitizer stress test
// of the adapter.
#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/ros/loop_fusion_adapter.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>
#include <ros/ros.h>
#include <visualization_msgs/MarkerArray.h>

#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <fstream>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

using namespace rover_loop_fusion;

namespace {

LoopFusionAdapter::LoopInfo loopInfo(const core::LoopCandidate& c) {
  LoopFusionAdapter::LoopInfo info;
  info << c.relative_t.x(), c.relative_t.y(), c.relative_t.z(), c.relative_q.w(), c.relative_q.x(),
      c.relative_q.y(), c.relative_q.z(), c.relative_yaw * 180.0 / M_PI;
  return info;
}

}  // namespace

TEST(AdapterStress, KeyframeThreadOptimisationThreadAndSpinners) {
  ros::NodeHandle pnh("~");
  std::mutex received_mutex;
  std::vector<LoopVerdict> received;
  std::atomic<int> markers(0);
  ros::Subscriber vs = pnh.subscribe<LoopVerdict>("loop_verdicts", 1000, [&](const LoopVerdict::ConstPtr& m) {
    std::lock_guard<std::mutex> lock(received_mutex);
    received.push_back(*m);
  });
  ros::Subscriber ms = pnh.subscribe<visualization_msgs::MarkerArray>(
      "loop_markers", 1000, [&](const visualization_msgs::MarkerArray::ConstPtr&) { ++markers; });
  ros::AsyncSpinner spinner(2);
  spinner.start();

  sim::LapsOptions o;
  o.laps = 3;
  const sim::Scene s = sim::makeLapsScene(o);
  // The CSV log's writer thread runs alongside as well.
  const std::string log = "/tmp/rover_adapter_stress_" + std::to_string(::getpid()) + ".csv";
  std::remove(log.c_str());
  pnh.setParam("verdict_log", log);
  std::unique_ptr<LoopFusionAdapter> adapter_owner(new LoopFusionAdapter);
  LoopFusionAdapter& adapter = *adapter_owner;
  ASSERT_TRUE(adapter.initialize(true));
  pnh.deleteParam("verdict_log");
  // Wait for our subscribers to be connected before the first verdict.
  for (int i = 0; i < 100 && (vs.getNumPublishers() == 0 || ms.getNumPublishers() == 0); ++i)
    ros::Duration(0.05).sleep();
  ASSERT_GT(vs.getNumPublishers(), 0u);

  // loop_fusion's keyframe list and its mutex (m_keyframelist), shared by the two threads.
  std::mutex keyframelist;
  core::KeyframeGraph graph;  // the optimisation thread's view: keyframes + used loops
  std::atomic<bool> done(false);
  std::atomic<int> optimisations(0), solves_with_loops(0), mirror_errors(0);
  std::vector<char> has_loop(s.keyframes.size(), 0);

  std::thread optimisation([&] {
    while (!done) {
      {
        std::lock_guard<std::mutex> lock(keyframelist);
        if (graph.loopCount() > 0 && graph.solveLikeLoopFusion(5).ok) ++solves_with_loops;
      }
      ++optimisations;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  std::thread process([&] {
    size_t next = 0;
    for (const sim::SimKeyframe& kf : s.keyframes) {
      adapter.addKeyframe(static_cast<int>(kf.index), kf.stamp, 1, kf.vio.t, kf.vio.q.toRotationMatrix());
      {
        std::lock_guard<std::mutex> lock(keyframelist);
        if (!graph.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok) ++mirror_errors;
      }
      for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
        const core::LoopCandidate& c = s.candidates[next].candidate;
        const bool use = adapter.verifyLoop(static_cast<int>(c.query_index), static_cast<int>(c.match_index), loopInfo(c));
        has_loop[c.query_index] = use;
        std::lock_guard<std::mutex> lock(keyframelist);
        if (use && !graph.addLoop(c).ok) ++mirror_errors;
      }
    }
  });
  process.join();
  done = true;
  optimisation.join();

  for (int i = 0; i < 200; ++i) {
    {
      std::lock_guard<std::mutex> lock(received_mutex);
      if (received.size() >= s.candidates.size()) break;
    }
    ros::Duration(0.05).sleep();
  }
  spinner.stop();
  std::lock_guard<std::mutex> lock(received_mutex);
  ASSERT_EQ(received.size(), s.candidates.size());
  EXPECT_EQ(adapter.verdictCount(), s.candidates.size());
  int accepted = 0;
  for (const LoopVerdict& v : received) {
    EXPECT_EQ(static_cast<bool>(has_loop[v.query_index]), v.accepted) << v.query_index;
    accepted += v.accepted;
  }
  EXPECT_GT(accepted, 0);
  EXPECT_LT(accepted, static_cast<int>(s.candidates.size()));
  EXPECT_GT(markers.load(), 0);
  EXPECT_GT(optimisations.load(), 10);
  EXPECT_GT(solves_with_loops.load(), 0);
  EXPECT_EQ(mirror_errors.load(), 0);
  adapter_owner.reset();  // flushes the verdict log
  std::ifstream in(log);
  size_t rows = 0;
  for (std::string line; std::getline(in, line);) ++rows;
  EXPECT_EQ(rows, s.candidates.size() + 1) << "header + one row per verdict in " << log;
  std::remove(log.c_str());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "loop_fusion");
  return RUN_ALL_TESTS();
}
