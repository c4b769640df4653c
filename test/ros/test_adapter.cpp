// The loop_fusion adapter, driven the way the patched VINS-Fusion loop_fusion drives it
// (patches/vins_fusion_loop_fusion.patch), without VINS-Fusion. Runs under rostest
// (test/ros/adapter.test) as the node `loop_fusion`, so ~ is /loop_fusion as in
// launch/vins_rover.launch, which adapter.test mirrors by loading config/rover_template.yaml, then rover_indoor.yaml
// into /loop_fusion/rover.
//
// FakePoseGraph below is PoseGraph::addKeyFrame / loadKeyFrame / setIMUFlag / savePoseGraph /
// loadPoseGraph of loop_fusion reduced to the state the patch touches (has_loop, loop_index,
// loop_info, earliest_loop_index, the sequence shift w_r_vio / w_t_vio, optimize_buf), with the
// adapter calls exactly where the patch makes them.
#include "rover_loop_fusion/LoopCandidate.h"
#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/verdict_csv.h"
#include "rover_loop_fusion/ros/loop_fusion_adapter.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <rosgraph_msgs/Log.h>
#include <visualization_msgs/MarkerArray.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

using namespace rover_loop_fusion;
using LoopInfo = LoopFusionAdapter::LoopInfo;
using visualization_msgs::Marker;
using visualization_msgs::MarkerArray;

namespace {

// What a test verifier that accepts everything returns.
core::Verdict acceptedVerdict(const core::LoopCandidate& c) {
  core::Verdict v;
  v.query_index = c.query_index;
  v.match_index = c.match_index;
  v.accepted = true;
  v.reason = core::Reason::kAccepted;
  return v;
}

const char kRover[] = "rover_loop_fusion/TrajectoryPriorVerifier";
const char kAcceptAll[] = "rover_loop_fusion/AcceptAllVerifier";

// ---- loop_fusion, reduced ------------------------------------------------------------------

/// The fields of loop_fusion's KeyFrame that the patch reads or writes.
struct FakeKeyFrame {
  int index = -1;
  double time_stamp = 0.0;
  int sequence = 1;
  Eigen::Vector3d vio_T_w_i = Eigen::Vector3d::Zero();
  Eigen::Matrix3d vio_R_w_i = Eigen::Matrix3d::Identity();
  bool has_loop = false;
  int loop_index = -1;
  LoopInfo loop_info = LoopInfo::Zero();
  int loop_inliers = -1;  // patch: the PnP inlier count findConnection keeps
};

/// Utility::R2ypr(R).x() of loop_fusion: yaw in degrees.
double yawDeg(const Eigen::Matrix3d& R) { return std::atan2(R(1, 0), R(0, 0)) * 180.0 / M_PI; }

/// Utility::ypr2R(Vector3d(yaw, 0, 0)).
Eigen::Matrix3d yawR(double yaw_deg) {
  return Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

/// What findConnection found: the old keyframe and loop_info.
struct Detection {
  int loop_index;
  LoopInfo loop_info;
  int inliers = -1;
};

class FakePoseGraph {
 public:
  rover_loop_fusion::LoopFusionAdapter rover;  // the patch's member
  bool use_imu = false;
  int global_index = 0;
  int sequence_cnt = 0;
  std::vector<int> sequence_loop{0};
  int earliest_loop_index = -1;
  Eigen::Vector3d w_t_vio = Eigen::Vector3d::Zero();
  Eigen::Matrix3d w_r_vio = Eigen::Matrix3d::Identity();
  std::vector<int> optimize_buf;
  std::map<int, FakeKeyFrame> keyframelist;

  /// Patch: setIMUFlag calls rover.initialize(use_imu).
  bool setIMUFlag(bool _use_imu) {
    use_imu = _use_imu;
    return rover.initialize(use_imu);
  }

  /// PoseGraph::addKeyFrame with flag_detect_loop; `detection` stands for detectLoop +
  /// a successful findConnection (nullptr: no loop detected). Returns the keyframe as stored.
  const FakeKeyFrame& addKeyFrame(FakeKeyFrame cur_kf, const Detection* detection) {
    if (sequence_cnt != cur_kf.sequence) {
      sequence_cnt++;
      sequence_loop.push_back(0);
      w_t_vio = Eigen::Vector3d::Zero();
      w_r_vio = Eigen::Matrix3d::Identity();
    }
    Eigen::Vector3d vio_P_cur = w_r_vio * cur_kf.vio_T_w_i + w_t_vio;
    Eigen::Matrix3d vio_R_cur = w_r_vio * cur_kf.vio_R_w_i;
    cur_kf.vio_T_w_i = vio_P_cur;
    cur_kf.vio_R_w_i = vio_R_cur;
    cur_kf.index = global_index;
    global_index++;
    // patch: register the keyframe
    rover.addKeyframe(cur_kf.index, cur_kf.time_stamp, cur_kf.sequence, vio_P_cur, vio_R_cur);
    int loop_index = detection ? detection->loop_index : -1;
    if (loop_index != -1) {
      const FakeKeyFrame& old_kf = keyframelist.at(loop_index);
      // findConnection(old_kf) succeeded: it sets has_loop, loop_index, loop_info (and, patched,
      // loop_inliers)
      cur_kf.has_loop = true;
      cur_kf.loop_index = old_kf.index;
      cur_kf.loop_info = detection->loop_info;
      cur_kf.loop_inliers = detection->inliers;
      // patch: the hook after findConnection; an accepted loop is used at once (useLoop)
      if (rover.verifyKeyframeLoop(cur_kf.index, cur_kf.loop_inliers, cur_kf.has_loop, cur_kf.loop_index,
                                   cur_kf.loop_info))
        useLoop(cur_kf, old_kf);
    }
    FakeKeyFrame& stored = keyframelist[cur_kf.index] = cur_kf;
    // patch: loops decided after their keyframe's verdict (keyframelist holds cur_kf now)
    for (const LoopFusionAdapter::LaterLoop& later : rover.takeLaterLoops()) {
      auto kf = keyframelist.find(later.index);
      auto old_kf = keyframelist.find(later.match_index);
      if (kf == keyframelist.end() || old_kf == keyframelist.end()) continue;
      later.apply(kf->second.has_loop, kf->second.loop_index, kf->second.loop_info, kf->second.loop_inliers);
      if (later.use) useLoop(kf->second, old_kf->second);
      optimize_buf.push_back(stored.index);
    }
    return stored;
  }

  /// Patch: PoseGraph::useLoop, what addKeyFrame does with a loop it uses (moved out of
  /// addKeyFrame), for the loop found at cur_kf and for a held loop released later (cur_kf may
  /// then be in keyframelist already, and of an older sequence).
  void useLoop(FakeKeyFrame& cur_kf, const FakeKeyFrame& old_kf) {
    if (earliest_loop_index > old_kf.index || earliest_loop_index == -1) earliest_loop_index = old_kf.index;
    const Eigen::Vector3d w_P_old = old_kf.vio_T_w_i;
    const Eigen::Matrix3d w_R_old = old_kf.vio_R_w_i;
    const Eigen::Vector3d vio_P_cur = cur_kf.vio_T_w_i;
    const Eigen::Matrix3d vio_R_cur = cur_kf.vio_R_w_i;
    const Eigen::Vector3d relative_t = cur_kf.loop_info.head<3>();
    const Eigen::Matrix3d relative_q =
        Eigen::Quaterniond(cur_kf.loop_info(3), cur_kf.loop_info(4), cur_kf.loop_info(5), cur_kf.loop_info(6))
            .toRotationMatrix();
    const Eigen::Vector3d w_P_cur = w_R_old * relative_t + w_P_old;
    const Eigen::Matrix3d w_R_cur = w_R_old * relative_q;
    Eigen::Matrix3d shift_r;
    if (use_imu) shift_r = yawR(yawDeg(w_R_cur) - yawDeg(vio_R_cur));
    else shift_r = w_R_cur * vio_R_cur.transpose();
    const Eigen::Vector3d shift_t = w_P_cur - w_R_cur * vio_R_cur.transpose() * vio_P_cur;
    if (old_kf.sequence != cur_kf.sequence && sequence_loop[cur_kf.sequence] == 0) {
      if (cur_kf.sequence == sequence_cnt) {
        w_r_vio = shift_r;
        w_t_vio = shift_t;
      }
      cur_kf.vio_T_w_i = shift_r * vio_P_cur + shift_t;
      cur_kf.vio_R_w_i = shift_r * vio_R_cur;
      for (auto& kf : keyframelist) {
        if (kf.second.sequence != cur_kf.sequence || &kf.second == &cur_kf) continue;
        kf.second.vio_T_w_i = shift_r * kf.second.vio_T_w_i + shift_t;
        kf.second.vio_R_w_i = shift_r * kf.second.vio_R_w_i;
      }
      sequence_loop[cur_kf.sequence] = 1;
    }
    optimize_buf.push_back(cur_kf.index);
  }

  /// PoseGraph::loadKeyFrame as loadPoseGraph calls it (flag_detect_loop = 0): keyframes of
  /// a saved graph, sequence 0, with their stored loops. Returns false if the keyframe's
  /// stored loop was dropped.
  bool loadKeyFrame(FakeKeyFrame cur_kf) {
    cur_kf.index = global_index;
    global_index++;
    cur_kf.sequence = 0;
    if (cur_kf.loop_index != -1)  // loadPoseGraph, before loadKeyFrame
      if (earliest_loop_index > cur_kf.loop_index || earliest_loop_index == -1) earliest_loop_index = cur_kf.loop_index;
    // patch: register the keyframe, keep its stored loop if the verifier takes it
    const bool had_loop = cur_kf.has_loop;
    rover.addKeyframe(cur_kf.index, cur_kf.time_stamp, cur_kf.sequence, cur_kf.vio_T_w_i, cur_kf.vio_R_w_i);
    rover.keepStoredLoop(cur_kf.index, cur_kf.has_loop, cur_kf.loop_index, cur_kf.loop_info);
    keyframelist[cur_kf.index] = cur_kf;
    return !had_loop || cur_kf.has_loop;
  }

  /// PoseGraph::savePoseGraph's pose_graph.txt: one line per keyframe with the fields and the
  /// format loop_fusion writes (no optimisation here: the pose-graph pose is the VIO pose; no
  /// keypoints).
  void savePoseGraph(const std::string& path) const {
    FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_TRUE(f) << path;
    for (const auto& entry : keyframelist) {
      const FakeKeyFrame& kf = entry.second;
      const Eigen::Quaterniond q(kf.vio_R_w_i);
      const Eigen::Vector3d& t = kf.vio_T_w_i;
      std::fprintf(f, " %d %f %f %f %f %f %f %f %f %f %f %f %f %f %f %f %d %f %f %f %f %f %f %f %f %d\n", kf.index,
                   kf.time_stamp, t.x(), t.y(), t.z(), t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z(), q.w(), q.x(),
                   q.y(), q.z(), kf.loop_index, kf.loop_info(0), kf.loop_info(1), kf.loop_info(2), kf.loop_info(3),
                   kf.loop_info(4), kf.loop_info(5), kf.loop_info(6), kf.loop_info(7), 0);
    }
    std::fclose(f);
  }

  /// PoseGraph::loadPoseGraph: reads pose_graph.txt as loop_fusion does; the load constructor of
  /// KeyFrame takes the pose-graph pose and has_loop = (loop_index != -1). Returns the
  /// keyframes read.
  int loadPoseGraph(const std::string& path) {
    FILE* f = std::fopen(path.c_str(), "r");
    if (!f) return -1;
    int index, loop_index, keypoints_num, n = 0;
    double stamp, vt[3], pt[3], vq[4], pq[4], li[8];
    while (std::fscanf(f, "%d %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %lf %d %lf %lf %lf %lf %lf %lf %lf %lf %d",
                       &index, &stamp, &vt[0], &vt[1], &vt[2], &pt[0], &pt[1], &pt[2], &vq[0], &vq[1], &vq[2], &vq[3],
                       &pq[0], &pq[1], &pq[2], &pq[3], &loop_index, &li[0], &li[1], &li[2], &li[3], &li[4], &li[5],
                       &li[6], &li[7], &keypoints_num) != EOF) {
      FakeKeyFrame kf;
      kf.index = index;
      kf.time_stamp = stamp;
      kf.vio_T_w_i = Eigen::Vector3d(pt[0], pt[1], pt[2]);
      kf.vio_R_w_i = Eigen::Quaterniond(pq[0], pq[1], pq[2], pq[3]).toRotationMatrix();
      kf.has_loop = loop_index != -1;
      kf.loop_index = loop_index;
      for (int i = 0; i < 8; ++i) kf.loop_info(i) = li[i];
      loadKeyFrame(kf);
      ++n;
    }
    std::fclose(f);
    return n;
  }
};

// ---- simulated input -----------------------------------------------------------------------

sim::Scene corridor(int laps) {
  sim::LapsOptions o;
  o.laps = laps;
  o.seed = 7;
  o.sigma_yaw = 0.004;
  return sim::makeLapsScene(o);
}

/// loop_fusion's loop_info layout, yaw in degrees.
LoopInfo loopInfo(const core::LoopCandidate& c) {
  LoopInfo info;
  info << c.relative_t.x(), c.relative_t.y(), c.relative_t.z(), c.relative_q.w(), c.relative_q.x(),
      c.relative_q.y(), c.relative_q.z(), c.relative_yaw * 180.0 / M_PI;
  return info;
}

FakeKeyFrame keyframe(const sim::SimKeyframe& s, int sequence, const core::Pose& frame = core::Pose()) {
  FakeKeyFrame kf;
  kf.time_stamp = s.stamp;
  kf.sequence = sequence;
  const core::Pose p = sim::compose(frame, s.vio);  // the pose in that session's VIO frame
  kf.vio_T_w_i = p.t;
  kf.vio_R_w_i = p.q.toRotationMatrix();
  return kf;
}

/// Candidates by query keyframe index.
std::map<int64_t, const sim::SimCandidate*> byQuery(const sim::Scene& s) {
  std::map<int64_t, const sim::SimCandidate*> m;
  for (const sim::SimCandidate& c : s.candidates) m.emplace(c.candidate.query_index, &c);
  return m;
}

/// The first false candidate and the first true one after it.
std::vector<const sim::SimCandidate*> falseThenTrue(const sim::Scene& s) {
  const sim::SimCandidate* f = nullptr;
  const sim::SimCandidate* t = nullptr;
  for (const sim::SimCandidate& c : s.candidates) {
    if (!f && !c.is_true) f = &c;
    else if (f && !t && c.is_true && c.candidate.query_index > f->candidate.query_index) t = &c;
  }
  return {f, t};
}

// ---- ROS plumbing --------------------------------------------------------------------------

/// Subscribes to ~loop_verdicts and ~loop_markers of this node (where the adapter publishes).
class Listener {
 public:
  Listener() : nh_("~") {
    verdict_sub_ = nh_.subscribe("loop_verdicts", 1000, &Listener::onVerdict, this);
    marker_sub_ = nh_.subscribe("loop_markers", 1000, &Listener::onMarkers, this);
  }
  /// Waits (bounded, no timing is asserted) until the adapter's publishers are connected.
  bool connect(bool markers = true) {
    return spinUntil([&] {
      return verdict_sub_.getNumPublishers() > 0 && (!markers || marker_sub_.getNumPublishers() > 0);
    });
  }
  bool waitFor(size_t verdicts, size_t markers) {
    return spinUntil([&] { return verdicts_.size() >= verdicts && markers_.size() >= markers; });
  }
  size_t markerPublishers() const { return marker_sub_.getNumPublishers(); }
  std::vector<LoopVerdict> verdicts_;
  std::vector<MarkerArray> markers_;

 private:
  template <typename F>
  static bool spinUntil(F done) {
    const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(60.0);
    while (!done()) {
      if (ros::WallTime::now() > give_up || !ros::ok()) return false;
      ros::spinOnce();
      ros::WallDuration(0.005).sleep();
    }
    ros::spinOnce();
    return true;
  }
  void onVerdict(const LoopVerdict& m) { verdicts_.push_back(m); }
  void onMarkers(const MarkerArray& m) { markers_.push_back(m); }
  ros::NodeHandle nh_;
  ros::Subscriber verdict_sub_, marker_sub_;
};

/// What this node logs, as it arrives on /rosout (from the node's own publisher).
class LogCapture {
 public:
  LogCapture() : nh_("~") { sub_ = nh_.subscribe("/rosout", 10000, &LogCapture::on, this); }
  bool connect() { return spinUntil([&] { return sub_.getNumPublishers() > 0; }); }
  /// The first message at `level` that contains every part, waiting for it (bounded); "" if none.
  std::string waitFor(uint8_t level, const std::vector<std::string>& parts) {
    std::string found;
    spinUntil([&] {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const rosgraph_msgs::Log& m : msgs_) {
        if (m.level != level) continue;
        bool all = true;
        for (const std::string& p : parts) all = all && m.msg.find(p) != std::string::npos;
        if (all) {
          found = m.msg;
          return true;
        }
      }
      return false;
    }, 20.0);
    return found;
  }
  size_t count(uint8_t level, const std::string& part) {
    ros::spinOnce();
    std::lock_guard<std::mutex> lock(mutex_);
    size_t n = 0;
    for (const rosgraph_msgs::Log& m : msgs_) n += m.level == level && m.msg.find(part) != std::string::npos;
    return n;
  }

 private:
  template <typename F>
  static bool spinUntil(F done, double seconds = 60.0) {
    const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(seconds);
    while (!done()) {
      if (ros::WallTime::now() > give_up || !ros::ok()) return false;
      ros::spinOnce();
      ros::WallDuration(0.005).sleep();
    }
    return true;
  }
  void on(const rosgraph_msgs::Log& m) {
    if (m.name != ros::this_node::getName()) return;
    std::lock_guard<std::mutex> lock(mutex_);
    msgs_.push_back(m);
  }
  ros::NodeHandle nh_;
  ros::Subscriber sub_;
  std::mutex mutex_;
  std::vector<rosgraph_msgs::Log> msgs_;
};

const char* const kAdapterParams[] = {"verifier_type", "verifier_name", "fallback_to_accept_all",
                                      "verdict_log", "marker_frame", "publish_markers", "relocalisation"};

class Adapter : public ::testing::Test {
 protected:
  void SetUp() override { clear(); }
  void TearDown() override { clear(); }
  static void clear() {
    for (const char* p : kAdapterParams) ros::param::del(std::string("~") + p);
  }
};

std::string tempFile(const std::string& name) {
  const std::string path = "/tmp/rover_test_adapter_" + std::to_string(::getpid()) + "_" + name;
  std::remove(path.c_str());
  return path;
}

std::vector<std::string> readLines(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

}  // namespace

// ---- the trajectory-prior verifier (the default plugin) ------------------------------------

TEST_F(Adapter, RejectsAFalseLoopAndAcceptsATrueOneAsThePatchUsesThem) {
  const std::string log = tempFile("verdicts.csv");
  ros::param::set("~verdict_log", log);
  const sim::Scene s = corridor(2);
  const std::vector<const sim::SimCandidate*> picks = falseThenTrue(s);
  ASSERT_TRUE(picks[0] && picks[1]);

  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  EXPECT_TRUE(pg.rover.verifying());
  Listener listen;
  ASSERT_TRUE(listen.connect());

  std::vector<FakeKeyFrame> looped;
  const int inliers[] = {31, 47};  // PnP inliers findConnection keeps on the keyframe (patch)
  for (const sim::SimKeyframe& k : s.keyframes) {
    std::unique_ptr<Detection> d;
    for (size_t i = 0; i < 2; ++i)
      if (picks[i]->candidate.query_index == k.index)
        d.reset(new Detection{static_cast<int>(picks[i]->candidate.match_index), loopInfo(picks[i]->candidate), inliers[i]});
    const FakeKeyFrame& kf = pg.addKeyFrame(keyframe(k, 1), d.get());
    if (d) {
      looped.push_back(kf);
      if (looped.size() == 1) {
        // The false loop is rejected and touches nothing loop_fusion would act on, and is
        // dropped from the keyframe (savePoseGraph would write loop_index otherwise).
        EXPECT_FALSE(kf.has_loop);
        EXPECT_EQ(kf.loop_index, -1);
        EXPECT_TRUE(kf.loop_info.isZero());
        EXPECT_EQ(pg.earliest_loop_index, -1);
        EXPECT_TRUE(pg.optimize_buf.empty());
      }
    }
    if (looped.size() == 2) break;
  }
  ASSERT_EQ(looped.size(), 2u);
  EXPECT_FALSE(looped[0].has_loop);
  EXPECT_TRUE(looped[1].has_loop);
  EXPECT_EQ(pg.earliest_loop_index, picks[1]->candidate.match_index);
  EXPECT_EQ(pg.optimize_buf, std::vector<int>{looped[1].index});
  EXPECT_EQ(pg.rover.verdictCount(), 2u);

  // ~loop_verdicts
  ASSERT_TRUE(listen.waitFor(2, 2));
  ASSERT_EQ(listen.verdicts_.size(), 2u);
  const LoopVerdict& rejected = listen.verdicts_[0];
  const LoopVerdict& accepted = listen.verdicts_[1];
  EXPECT_EQ(rejected.query_index, picks[0]->candidate.query_index);
  EXPECT_EQ(rejected.match_index, picks[0]->candidate.match_index);
  EXPECT_FALSE(rejected.accepted);
  // A look-alike 3 m away after one lap: the innovation gate of config/rover_indoor.yaml
  // (0.5 m + 2 % of the path) rejects it before the trial solve.
  EXPECT_EQ(rejected.reason, LoopVerdict::INNOVATION_ABOVE_BOUND) << rejected.detail;
  EXPECT_DOUBLE_EQ(rejected.threshold, 0.2);  // config/rover_indoor.yaml, fixed threshold
  EXPECT_GT(rejected.innovation, 0.5 + 0.02 * rejected.path_length);
  EXPECT_GT(rejected.path_length, 10.0);
  EXPECT_FALSE(rejected.converged);  // no trial solve
  EXPECT_EQ(rejected.verifier, kRover);
  EXPECT_EQ(rejected.inliers, 31);
  EXPECT_EQ(accepted.inliers, 47);
  EXPECT_EQ(rejected.header.frame_id, "world");
  EXPECT_NEAR(rejected.query_stamp.toSec(), s.keyframes[rejected.query_index].stamp, 1e-6);
  EXPECT_NEAR(rejected.match_stamp.toSec(), s.keyframes[rejected.match_index].stamp, 1e-6);
  EXPECT_EQ(accepted.query_index, looped[1].index);
  EXPECT_TRUE(accepted.accepted);
  EXPECT_EQ(accepted.reason, LoopVerdict::ACCEPTED);
  EXPECT_LE(accepted.score, 0.5);
  EXPECT_GT(accepted.window_size, 50);

  // ~loop_markers: a red line + score text for the rejected loop, green for the accepted one.
  ASSERT_EQ(listen.markers_.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const MarkerArray& arr = listen.markers_[i];
    ASSERT_EQ(arr.markers.size(), 2u);
    const Marker& line = arr.markers[0];
    const Marker& text = arr.markers[1];
    EXPECT_EQ(line.type, Marker::LINE_LIST);
    EXPECT_EQ(line.header.frame_id, "world");
    ASSERT_EQ(line.points.size(), 2u);
    EXPECT_EQ(text.type, Marker::TEXT_VIEW_FACING);
    // the score, or the reason when there is none (decided by the innovation gate)
    char score[32];
    std::snprintf(score, sizeof(score), "%.2f m", listen.verdicts_[i].score);
    const std::string shown = std::isfinite(listen.verdicts_[i].score) ? score : listen.verdicts_[i].reason;
    EXPECT_TRUE(contains(text.text, shown)) << text.text << " lacks " << shown;
    EXPECT_TRUE(contains(text.text, std::to_string(listen.verdicts_[i].query_index) + "->" +
                                        std::to_string(listen.verdicts_[i].match_index)))
        << text.text;
  }
  const Marker& red = listen.markers_[0].markers[0];
  const Marker& green = listen.markers_[1].markers[0];
  EXPECT_EQ(red.ns, "rejected_loops");
  EXPECT_GT(red.color.r, red.color.g);
  EXPECT_EQ(green.ns, "accepted_loops");
  EXPECT_GT(green.color.g, green.color.r);
  // The accepted loop is drawn at the verifier's corrected estimate: its ends meet (within
  // the relative pose), whereas the VIO positions are metres apart after a lap of drift.
  const Eigen::Vector3d g0(green.points[0].x, green.points[0].y, green.points[0].z);
  const Eigen::Vector3d g1(green.points[1].x, green.points[1].y, green.points[1].z);
  EXPECT_LT((g0 - g1).norm(), picks[1]->candidate.relative_t.norm() + 0.3);

  // ~verdict_log
  const std::vector<std::string> rows = readLines(log);
  ASSERT_EQ(rows.size(), 3u) << log;
  EXPECT_EQ(rows[0], core::verdictCsvHeader());
  for (size_t i = 0; i < 2; ++i) {
    const LoopVerdict& v = listen.verdicts_[i];
    EXPECT_TRUE(contains(rows[i + 1], "," + std::to_string(v.query_index) + "," + std::to_string(v.match_index) +
                                          (v.accepted ? ",1,accepted," : ",0," + v.reason + ",")))
        << rows[i + 1];
    // inliers, innovation, path_length, verifier
    EXPECT_TRUE(contains(rows[i + 1], "," + std::to_string(inliers[i]) + ",")) << rows[i + 1];
    EXPECT_TRUE(contains(rows[i + 1], std::string(",") + kRover + ",")) << rows[i + 1];
  }
  std::remove(log.c_str());
}

TEST_F(Adapter, SixDofPoseGraphWithoutImu) {
  // loop_fusion without IMU (setIMUFlag(false)): `mode: auto` gives the 6-DoF graph; the
  // sequence shift in FakePoseGraph takes the full rotation, as loop_fusion does.
  const sim::Scene s = corridor(2);
  const std::vector<const sim::SimCandidate*> picks = falseThenTrue(s);
  ASSERT_TRUE(picks[0] && picks[1]);
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(false));
  std::vector<bool> has_loop;
  for (const sim::SimKeyframe& k : s.keyframes) {
    std::unique_ptr<Detection> d;
    for (const sim::SimCandidate* c : picks)
      if (c->candidate.query_index == k.index) d.reset(new Detection{static_cast<int>(c->candidate.match_index), loopInfo(c->candidate)});
    const bool detected = d != nullptr;
    const FakeKeyFrame& kf = pg.addKeyFrame(keyframe(k, 1), d.get());
    if (detected) has_loop.push_back(kf.has_loop);
    if (has_loop.size() == 2) break;
  }
  EXPECT_EQ(has_loop, (std::vector<bool>{false, true}));
}

namespace {

/// A corridor of three laps: laps 1-2 a saved pose graph, lap 3 a new session.
struct MapAndSession {
  sim::Scene scene = corridor(3);
  int per_lap = static_cast<int>(scene.keyframes.size() / 3);
  std::map<int64_t, const sim::SimCandidate*> candidates = byQuery(scene);
  core::Pose frame;  ///< the session's own VIO frame
  std::map<int, Detection> detections;  ///< what findConnection found, by query keyframe
};

/// loadPoseGraph: laps 1-2 of `m` (sequence 0, with their stored true loops).
void loadMap(FakePoseGraph& pg, MapAndSession& m) {
  int stored = 0;
  for (int i = 0; i < 2 * m.per_lap; ++i) {
    FakeKeyFrame kf = keyframe(m.scene.keyframes[i], 0);
    auto c = m.candidates.find(i);
    if (c != m.candidates.end() && c->second->is_true) {
      kf.has_loop = true;
      kf.loop_index = static_cast<int>(c->second->candidate.match_index);
      kf.loop_info = loopInfo(c->second->candidate);
      ++stored;
    }
    EXPECT_TRUE(pg.loadKeyFrame(kf)) << "stored loop of keyframe " << i;
  }
  EXPECT_GT(stored, 2);
  EXPECT_EQ(pg.rover.verdictCount(), 0u);  // stored loops are not verdicts
  // The new session starts in its own VIO frame.
  const core::Pose session_frame(Eigen::Vector3d(4.0, -7.0, 0.5),
                                 Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d::UnitZ())));
  const core::Pose to_session = sim::relative(m.scene.keyframes[2 * m.per_lap].vio, core::Pose());
  m.frame = sim::compose(session_frame, to_session);
}

/// addKeyFrame for keyframe i of lap 3 (sequence 1), with its candidate if `use(candidate)`.
const FakeKeyFrame& sessionKeyFrame(FakePoseGraph& pg, MapAndSession& m, int i,
                                    const std::function<bool(const sim::SimCandidate&)>& use) {
  std::unique_ptr<Detection> d;
  auto c = m.candidates.find(i);
  if (c != m.candidates.end() && use(*c->second)) {
    d.reset(new Detection{static_cast<int>(c->second->candidate.match_index), loopInfo(c->second->candidate),
                          20 + i % 50});
    m.detections[i] = *d;
  }
  return pg.addKeyFrame(keyframe(m.scene.keyframes[i], 1, m.frame), d.get());
}

/// loadPoseGraph of laps 1-2, then lap 3 as a new session in its own VIO frame up to its
/// `loops`-th true loop into the map. Returns the keyframes of those loops as addKeyFrame
/// stored them.
std::vector<FakeKeyFrame> loadedMapThenNewSession(FakePoseGraph& pg, size_t loops = 3,
                                                  MapAndSession* out = nullptr) {
  MapAndSession local;
  MapAndSession& m = out ? *out : local;
  loadMap(pg, m);
  std::vector<FakeKeyFrame> looped;
  for (int i = 2 * m.per_lap; i < 3 * m.per_lap && looped.size() < loops; ++i) {
    const FakeKeyFrame& kf = sessionKeyFrame(pg, m, i, [](const sim::SimCandidate& c) { return c.is_true; });
    if (m.detections.count(i)) looped.push_back(kf);
  }
  EXPECT_EQ(looped.size(), loops);
  return looped;
}

}  // namespace

TEST_F(Adapter, FirstLoopIntoALoadedMapIsRejectedWithRelocalisationReject) {
  // ~relocalisation: reject: a loop between sequences that nothing connects has no trajectory
  // prior to be verified against, and it is the loop that would move the whole session. It is
  // rejected and dropped; loop_fusion does not shift the session for it.
  ros::param::set("~relocalisation", "reject");
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  const std::vector<FakeKeyFrame> looped = loadedMapThenNewSession(pg);
  ASSERT_EQ(looped.size(), 3u);
  const int earliest_of_the_map = pg.earliest_loop_index;
  ASSERT_TRUE(listen.waitFor(3, 3));
  for (size_t i = 0; i < 3; ++i) {
    EXPECT_FALSE(looped[i].has_loop);
    EXPECT_EQ(looped[i].loop_index, -1);
    EXPECT_FALSE(listen.verdicts_[i].accepted);
    EXPECT_EQ(listen.verdicts_[i].reason, LoopVerdict::NO_TRAJECTORY_PRIOR) << listen.verdicts_[i].detail;
    EXPECT_TRUE(contains(listen.verdicts_[i].detail, "relocalisation: reject")) << listen.verdicts_[i].detail;
  }
  EXPECT_EQ(pg.sequence_loop[1], 0);
  EXPECT_TRUE(pg.w_r_vio.isIdentity());
  EXPECT_TRUE(pg.w_t_vio.isZero());
  EXPECT_EQ(pg.earliest_loop_index, earliest_of_the_map);
  EXPECT_TRUE(pg.optimize_buf.empty());
}

TEST_F(Adapter, LoadedPoseGraphThenANewSessionWithRelocalisationAcceptUnverified) {
  ros::param::set("~relocalisation", "accept_unverified");
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  const std::vector<FakeKeyFrame> looped = loadedMapThenNewSession(pg);
  ASSERT_EQ(looped.size(), 3u);
  ASSERT_TRUE(listen.waitFor(3, 3));
  // The first loop into the loaded map has no trajectory prior, is used unverified, and
  // shifts the session into the map's frame (sequence_loop, w_r_vio).
  EXPECT_TRUE(looped[0].has_loop);
  EXPECT_EQ(listen.verdicts_[0].reason, LoopVerdict::NO_TRAJECTORY_PRIOR);
  EXPECT_TRUE(listen.verdicts_[0].accepted);
  EXPECT_EQ(pg.sequence_loop[1], 1);
  // Later loops are verified against the prior, in the shifted frame loop_fusion hands over.
  for (size_t i = 1; i < 3; ++i) {
    EXPECT_TRUE(looped[i].has_loop) << listen.verdicts_[i].detail;
    EXPECT_EQ(listen.verdicts_[i].reason, LoopVerdict::ACCEPTED) << listen.verdicts_[i].detail;
    EXPECT_LT(listen.verdicts_[i].score, 0.2) << listen.verdicts_[i].detail;
  }
  EXPECT_EQ(pg.optimize_buf.size(), 3u);
}

namespace {

/// The keyframe position loop_fusion's first-loop shift puts the query of a loop at: the
/// match's VIO pose composed with loop_info (useLoop's w_P_cur).
Eigen::Vector3d placedByLoop(const FakePoseGraph& pg, const FakeKeyFrame& query) {
  const FakeKeyFrame& match = pg.keyframelist.at(query.loop_index);
  return match.vio_R_w_i * Eigen::Vector3d(query.loop_info.head<3>()) + match.vio_T_w_i;
}

}  // namespace

TEST_F(Adapter, FirstLoopsIntoALoadedMapAreHeldUntilConfirmedThenUsed) {
  // ~relocalisation: confirm (the default). The first loops into a loaded map have no
  // trajectory prior: each is held (a deferred verdict; dropped from its keyframe, so neither
  // used nor saved) until confirm_count (3, config/rover_indoor.yaml) of them agree with each
  // other. Then they are released together and loop_fusion applies them to their keyframes
  // exactly as findConnection found them: the first shifts the session into the map's frame as
  // loop_fusion does for a first loop (once), each queues an optimisation. Later loops are
  // verified against the prior in the shifted frame.
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  MapAndSession m;
  const std::vector<FakeKeyFrame> looped = loadedMapThenNewSession(pg, 6, &m);
  ASSERT_EQ(looped.size(), 6u);
  ASSERT_TRUE(listen.waitFor(9, 9));
  ASSERT_EQ(listen.verdicts_.size(), 9u);
  int earliest = -1;  // of the map's stored loops and the session's released ones
  for (int i = 0; i < 2 * m.per_lap; ++i) {
    auto c = m.candidates.find(i);
    if (c != m.candidates.end() && c->second->is_true && (earliest == -1 || c->second->candidate.match_index < earliest))
      earliest = static_cast<int>(c->second->candidate.match_index);
  }
  for (size_t i = 0; i < 3; ++i) {
    SCOPED_TRACE(i);
    const LoopVerdict& held = listen.verdicts_[i];
    EXPECT_EQ(held.query_index, looped[i].index);
    EXPECT_FALSE(held.accepted);
    EXPECT_FALSE(held.final);
    EXPECT_EQ(held.reason, LoopVerdict::DEFERRED) << held.detail;
    EXPECT_EQ(held.decision, LoopVerdict::VERIFY);
    if (i < 2) {  // (the third's addKeyFrame already applied the releases its verify made)
      EXPECT_FALSE(looped[i].has_loop) << "held: not on the keyframe while held";
      EXPECT_EQ(looped[i].loop_index, -1);
    }
    const LoopVerdict& released = listen.verdicts_[3 + i];
    EXPECT_EQ(released.query_index, looped[i].index);
    EXPECT_TRUE(released.accepted) << released.detail;
    EXPECT_TRUE(released.final);
    EXPECT_EQ(released.reason, LoopVerdict::ACCEPTED);
    EXPECT_EQ(released.decision, LoopVerdict::RELEASE);
    const Detection& d = m.detections.at(looped[i].index);
    EXPECT_EQ(released.inliers, d.inliers);
    // Applied to its keyframe as findConnection had set it.
    const FakeKeyFrame& kf = pg.keyframelist.at(looped[i].index);
    EXPECT_TRUE(kf.has_loop);
    EXPECT_EQ(kf.loop_index, d.loop_index);
    EXPECT_TRUE(kf.loop_info == d.loop_info) << kf.loop_info.transpose() << " vs " << d.loop_info.transpose();
    EXPECT_EQ(kf.loop_inliers, d.inliers);
    earliest = std::min(earliest, d.loop_index);
    // In the map's frame now: shifted once (the first exactly onto where its loop puts it).
    EXPECT_LT((kf.vio_T_w_i - placedByLoop(pg, kf)).norm(), i == 0 ? 1e-9 : 0.3) << kf.vio_T_w_i.transpose();
  }
  EXPECT_EQ(pg.sequence_loop[1], 1);
  EXPECT_FALSE(pg.w_r_vio.isIdentity());
  EXPECT_EQ(pg.earliest_loop_index, earliest);
  for (size_t i = 3; i < 6; ++i) {
    // Verified against the prior, in the frame loop_fusion shifted the session into.
    const LoopVerdict& v = listen.verdicts_[3 + i];
    EXPECT_EQ(v.query_index, looped[i].index);
    EXPECT_EQ(v.reason, LoopVerdict::ACCEPTED) << v.detail;
    EXPECT_EQ(v.decision, LoopVerdict::VERIFY);
    EXPECT_TRUE(v.final);
    EXPECT_LT(v.score, 0.2) << v.detail;
    EXPECT_TRUE(looped[i].has_loop);
  }
  // The releases were applied at the end of the addKeyFrame whose verification confirmed them
  // (the third): each useLoop queues its keyframe, then one optimisation up to the newest.
  const int q3 = looped[2].index;
  EXPECT_EQ(pg.optimize_buf, (std::vector<int>{looped[0].index, q3, looped[1].index, q3, q3, q3, looped[3].index,
                                               looped[4].index, looped[5].index}));
  EXPECT_EQ(pg.rover.heldCount(), 0u);
}

TEST_F(Adapter, AnUnconfirmedRelocalisationIsDroppedAndNeverUsed) {
  // A look-alike of the map seen once from the new session: held, nothing agrees with it within
  // confirm_window (40) keyframes, dropped (reason unconfirmed). loop_fusion never saw it as a
  // loop: no shift, no optimisation, not saved.
  const std::string file = tempFile("dropped_pose_graph.txt");
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  MapAndSession m;
  loadMap(pg, m);
  const int earliest_of_the_map = pg.earliest_loop_index;
  const int end = 3 * m.per_lap;
  const sim::SimCandidate* lookalike = nullptr;
  for (const sim::SimCandidate& c : m.scene.candidates)
    if (!c.is_true && c.candidate.query_index >= 2 * m.per_lap && c.candidate.match_index < 2 * m.per_lap &&
        c.candidate.query_index + 45 < end) {
      lookalike = &c;
      break;
    }
  ASSERT_NE(lookalike, nullptr);
  const int q = static_cast<int>(lookalike->candidate.query_index);
  for (int i = 2 * m.per_lap; i <= q + 45; ++i)
    sessionKeyFrame(pg, m, i, [&](const sim::SimCandidate& c) { return &c == lookalike; });
  ASSERT_TRUE(listen.waitFor(2, 2));
  ASSERT_EQ(listen.verdicts_.size(), 2u);
  EXPECT_EQ(listen.verdicts_[0].reason, LoopVerdict::DEFERRED) << listen.verdicts_[0].detail;
  EXPECT_FALSE(listen.verdicts_[0].final);
  const LoopVerdict& dropped = listen.verdicts_[1];
  EXPECT_EQ(dropped.query_index, q);
  EXPECT_FALSE(dropped.accepted);
  EXPECT_TRUE(dropped.final);
  EXPECT_EQ(dropped.reason, LoopVerdict::UNCONFIRMED) << dropped.detail;
  EXPECT_EQ(dropped.decision, LoopVerdict::DROP);
  const FakeKeyFrame& kf = pg.keyframelist.at(q);
  EXPECT_FALSE(kf.has_loop);
  EXPECT_EQ(kf.loop_index, -1);
  EXPECT_TRUE(kf.loop_info.isZero());
  EXPECT_EQ(pg.sequence_loop[1], 0);
  EXPECT_TRUE(pg.w_r_vio.isIdentity());
  EXPECT_EQ(pg.earliest_loop_index, earliest_of_the_map);
  EXPECT_TRUE(pg.optimize_buf.empty());
  EXPECT_EQ(pg.rover.heldCount(), 0u);
  pg.savePoseGraph(file);
  FakePoseGraph next;
  ASSERT_TRUE(next.setIMUFlag(true));
  ASSERT_EQ(next.loadPoseGraph(file), q + 46);
  EXPECT_EQ(next.keyframelist.at(q).loop_index, -1) << "a dropped loop is not saved";
  std::remove(file.c_str());
}

namespace {

/// A verifier the test scripts, for the adapter's side of held, released, dropped and revoked
/// loops (core::Verifier does not emit revocations yet): a candidate whose query keyframe is in
/// `hold` gets a deferred verdict, any other is accepted; the decisions the test queues with
/// decide() are handed out by the next takeDecisions(), after an addKeyframe or a verify.
class ScriptedVerifier : public LoopVerifier {
 public:
  struct Script {
    std::set<int64_t> hold;
    std::map<std::pair<int64_t, int64_t>, core::LoopCandidate> seen;
    std::vector<core::LoopDecision> queued;
    void decide(core::LoopDecision::Kind kind, int64_t query, int64_t match) {
      core::LoopDecision d;
      d.kind = kind;
      d.candidate = seen.at(std::make_pair(query, match));
      if (kind == core::LoopDecision::Kind::kRelease)
        d.verdict = core::Verdict::Accept(d.candidate, "released by the script");
      else
        d.verdict = core::Verdict::Reject(
            kind == core::LoopDecision::Kind::kDrop ? core::Reason::kUnconfirmed : core::Reason::kRevoked, d.candidate,
            std::string(core::toString(kind)) + " by the script");
      queued.push_back(d);
    }
  };
  explicit ScriptedVerifier(std::shared_ptr<Script> script) : script_(std::move(script)) {}
  core::Status addKeyframe(int64_t, double, int, const Eigen::Vector3d&, const Eigen::Quaterniond&) override {
    return core::Status::Ok();
  }
  core::Verdict verify(const core::LoopCandidate& c) override {
    script_->seen[std::make_pair(c.query_index, c.match_index)] = c;
    if (script_->hold.count(c.query_index)) return core::Verdict::Defer(c, "held by the script");
    return core::Verdict::Accept(c, "accepted by the script");
  }
  core::Status commit(const core::LoopCandidate&) override { return core::Status::Ok(); }
  std::vector<core::LoopDecision> takeDecisions() override {
    std::vector<core::LoopDecision> out;
    out.swap(script_->queued);
    return out;
  }

 protected:
  bool onInitialize() override { return true; }

 private:
  std::shared_ptr<Script> script_;
};

/// The markers of one MarkerArray as "ACTION ns id" strings.
std::vector<std::string> markerIds(const MarkerArray& arr) {
  std::vector<std::string> out;
  for (const Marker& mk : arr.markers)
    out.push_back(std::string(mk.action == Marker::DELETE ? "DELETE " : "ADD ") + mk.ns + " " + std::to_string(mk.id));
  return out;
}

}  // namespace

TEST_F(Adapter, HeldLoopsAreAppliedWhenReleasedRemovedWhenRevokedAndSavedOnlyWhileUsed) {
  // Held 50 -> 2 released, held 51 -> 3 dropped, accepted 52 -> 4 revoked, held 55 -> 5 still
  // held at the end. loop_fusion (FakePoseGraph: the patch's calls and useLoop) applies each to
  // its keyframe; every candidate has exactly one final verdict, every used loop exactly one
  // accepting one; markers change colour; the CSV log says final and decision; a save and load
  // holds only the loop in use.
  const std::string log = tempFile("deferred.csv");
  const std::string file = tempFile("deferred_pose_graph.txt");
  ros::param::set("~verdict_log", log);
  std::shared_ptr<ScriptedVerifier::Script> script = std::make_shared<ScriptedVerifier::Script>();
  script->hold = {50, 51, 55};
  FakePoseGraph pg;
  pg.use_imu = true;
  ASSERT_TRUE(pg.rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new ScriptedVerifier(script)),
                                              "test/Scripted"));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  std::map<int, Detection> found;
  auto add = [&](int i) -> const FakeKeyFrame& {
    FakeKeyFrame kf;
    kf.time_stamp = 1.0 + i;
    kf.vio_T_w_i = Eigen::Vector3d(0.5 * i, 0.0, 0.0);
    std::unique_ptr<Detection> d;
    if (i >= 50 && i != 53 && i != 54) {
      LoopInfo info;
      info << 0.1 + 0.001 * i, -0.02, 0.003, 1.0, 0.0, 0.0, 0.0, 0.5;
      d.reset(new Detection{i - 48, info, i - 17});
      found[i] = *d;
    }
    return pg.addKeyFrame(kf, d.get());
  };
  for (int i = 0; i < 50; ++i) add(i);
  EXPECT_FALSE(add(50).has_loop);
  EXPECT_FALSE(add(51).has_loop);
  EXPECT_TRUE(add(52).has_loop);
  EXPECT_EQ(pg.rover.heldCount(), 2u);
  EXPECT_EQ(pg.optimize_buf, std::vector<int>{52});
  EXPECT_EQ(pg.earliest_loop_index, 4);

  script->decide(core::LoopDecision::Kind::kRelease, 50, 2);
  script->decide(core::LoopDecision::Kind::kDrop, 51, 3);
  add(53);  // the decisions come with this keyframe
  const FakeKeyFrame& released = pg.keyframelist.at(50);
  EXPECT_TRUE(released.has_loop);
  EXPECT_EQ(released.loop_index, 2);
  EXPECT_TRUE(released.loop_info == found[50].loop_info) << released.loop_info.transpose();
  EXPECT_EQ(released.loop_inliers, found[50].inliers);
  EXPECT_FALSE(pg.keyframelist.at(51).has_loop);
  EXPECT_EQ(pg.keyframelist.at(51).loop_index, -1);
  EXPECT_EQ(pg.earliest_loop_index, 2);
  EXPECT_EQ(pg.optimize_buf, (std::vector<int>{52, 50, 53}));  // useLoop(50), then up to the newest
  EXPECT_EQ(pg.rover.heldCount(), 0u);

  script->decide(core::LoopDecision::Kind::kRevoke, 52, 4);
  add(54);
  const FakeKeyFrame& revoked = pg.keyframelist.at(52);
  EXPECT_FALSE(revoked.has_loop);
  EXPECT_EQ(revoked.loop_index, -1);
  EXPECT_TRUE(revoked.loop_info.isZero());
  EXPECT_EQ(revoked.loop_inliers, -1);
  EXPECT_EQ(pg.optimize_buf, (std::vector<int>{52, 50, 53, 54}));
  EXPECT_FALSE(add(55).has_loop);
  EXPECT_EQ(pg.rover.heldCount(), 1u);
  EXPECT_EQ(pg.rover.verdictCount(), 7u);

  // ~loop_verdicts: one final verdict per candidate, one accepting verdict per used loop.
  ASSERT_TRUE(listen.waitFor(7, 7));
  ASSERT_EQ(listen.verdicts_.size(), 7u);
  struct Expected {
    int query;
    bool accepted, final;
    const char* reason;
    const char* decision;
  };
  const Expected expected[] = {
      {50, false, false, "deferred", "verify"}, {51, false, false, "deferred", "verify"},
      {52, true, true, "accepted", "verify"},   {50, true, true, "accepted", "release"},
      {51, false, true, "unconfirmed", "drop"}, {52, false, true, "revoked", "revoke"},
      {55, false, false, "deferred", "verify"}};
  for (size_t i = 0; i < 7; ++i) {
    SCOPED_TRACE(i);
    const LoopVerdict& v = listen.verdicts_[i];
    EXPECT_EQ(v.query_index, expected[i].query);
    EXPECT_EQ(v.match_index, expected[i].query - 48);
    EXPECT_EQ(v.accepted, expected[i].accepted);
    EXPECT_EQ(v.final, expected[i].final);
    EXPECT_EQ(v.reason, expected[i].reason);
    EXPECT_EQ(v.decision, expected[i].decision);
    EXPECT_EQ(v.inliers, expected[i].query - 17);
    EXPECT_EQ(v.verifier, "test/Scripted");
    EXPECT_NEAR(v.query_stamp.toSec(), 1.0 + expected[i].query, 1e-9);
  }

  // ~loop_markers: a held loop is amber; its final verdict replaces the marker (same id,
  // another namespace); a revocation turns the green marker red.
  ASSERT_EQ(listen.markers_.size(), 7u);
  std::vector<int> id(7);
  for (size_t i = 0; i < 7; ++i) id[i] = listen.markers_[i].markers.back().id;
  auto ids = [&](size_t i) { return markerIds(listen.markers_[i]); };
  const std::string a = std::to_string(id[0]), b = std::to_string(id[1]), c = std::to_string(id[2]);
  EXPECT_EQ(ids(0), (std::vector<std::string>{"ADD held_loops " + a, "ADD held_loops_score " + a}));
  EXPECT_EQ(ids(3), (std::vector<std::string>{"DELETE held_loops " + a, "DELETE held_loops_score " + a,
                                              "ADD accepted_loops " + a, "ADD accepted_loops_score " + a}));
  EXPECT_EQ(ids(4), (std::vector<std::string>{"DELETE held_loops " + b, "DELETE held_loops_score " + b,
                                              "ADD rejected_loops " + b, "ADD rejected_loops_score " + b}));
  EXPECT_EQ(ids(5), (std::vector<std::string>{"DELETE accepted_loops " + c, "DELETE accepted_loops_score " + c,
                                              "ADD revoked_loops " + c, "ADD revoked_loops_score " + c}));
  const Marker& amber = listen.markers_[0].markers[0];
  const Marker& green = listen.markers_[3].markers[2];
  const Marker& red = listen.markers_[5].markers[2];
  EXPECT_GT(amber.color.r, 0.5);
  EXPECT_GT(amber.color.g, 0.5);
  EXPECT_GT(green.color.g, green.color.r);
  EXPECT_GT(red.color.r, red.color.g);
  EXPECT_TRUE(contains(listen.markers_[3].markers[3].text, "(release)")) << listen.markers_[3].markers[3].text;

  // ~verdict_log: the columns final and decision.
  const std::vector<std::string> rows = readLines(log);
  ASSERT_EQ(rows.size(), 8u);
  EXPECT_TRUE(contains(rows[0], ",detail,final,decision")) << rows[0];
  for (size_t i = 0; i < 7; ++i) {
    const std::string tail = std::string(",") + (expected[i].final ? "1" : "0") + "," + expected[i].decision;
    EXPECT_EQ(rows[i + 1].substr(rows[i + 1].size() - tail.size()), tail) << rows[i + 1];
  }

  // savePoseGraph -> loadPoseGraph: only the loop in use (released 50 -> 2) is stored; the
  // dropped, revoked and still held ones are not.
  pg.savePoseGraph(file);
  FakePoseGraph next;
  ASSERT_TRUE(next.setIMUFlag(true));
  ASSERT_EQ(next.loadPoseGraph(file), 56);
  std::set<int> stored;
  for (const auto& kf : next.keyframelist)
    if (kf.second.loop_index != -1) stored.insert(kf.first);
  EXPECT_EQ(stored, std::set<int>{50});
  EXPECT_NEAR((next.keyframelist.at(50).loop_info - found[50].loop_info).norm(), 0.0, 1e-5);  // %f in the file
  std::remove(log.c_str());
  std::remove(file.c_str());
}

TEST_F(Adapter, CandidatesStillHeldWhenLoopFusionEndsGetTheirFinalVerdict) {
  // A candidate still held when loop_fusion ended kept only its deferred
  // verdict (final false): the verdict log had no final verdict for it. Now the adapter's end
  // (finish(), from its destructor) drops it: unconfirmed, decision drop, on the topic and in
  // the log; later loops are rejected.
  const std::string log = tempFile("held_at_end.csv");
  ros::param::set("~verdict_log", log);
  std::shared_ptr<ScriptedVerifier::Script> script = std::make_shared<ScriptedVerifier::Script>();
  script->hold = {30, 31};
  Listener listen;
  {
    FakePoseGraph pg;
    pg.use_imu = true;
    ASSERT_TRUE(pg.rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new ScriptedVerifier(script)),
                                                "test/Scripted"));
    ASSERT_TRUE(listen.connect());
    for (int i = 0; i < 33; ++i) {
      FakeKeyFrame kf;
      kf.time_stamp = 1.0 + i;
      kf.vio_T_w_i = Eigen::Vector3d(0.5 * i, 0.0, 0.0);
      LoopInfo info;
      info << 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5;
      const Detection d{i - 28, info, 25};
      pg.addKeyFrame(kf, i >= 30 ? &d : nullptr);
    }
    EXPECT_EQ(pg.rover.heldCount(), 2u);
    ASSERT_TRUE(listen.waitFor(3, 0));
    pg.rover.finish();  // what the destructor does; a second call (the destructor's) does nothing
    EXPECT_EQ(pg.rover.heldCount(), 0u);
    LoopInfo info;
    info << 0.1, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5;
    EXPECT_FALSE(pg.rover.verifyLoop(32, 3, info)) << "after the end every loop is rejected";
    // Received while the adapter (the topic's publisher) still exists: messages still queued
    // in a publisher that is destroyed may never be sent (seen once in CI); the verdict log
    // below is the record that must survive the adapter.
    ASSERT_TRUE(listen.waitFor(6, 0));
  }
  ASSERT_EQ(listen.verdicts_.size(), 6u);
  for (int i : {3, 4}) {
    const LoopVerdict& v = listen.verdicts_[i];
    EXPECT_EQ(v.query_index, 30 + (i - 3));
    EXPECT_EQ(v.match_index, 2 + (i - 3));
    EXPECT_FALSE(v.accepted);
    EXPECT_TRUE(v.final);
    EXPECT_EQ(v.reason, LoopVerdict::UNCONFIRMED);
    EXPECT_EQ(v.decision, LoopVerdict::DROP);
    EXPECT_EQ(v.inliers, 25);
    EXPECT_TRUE(contains(v.detail, "still held when loop_fusion ended")) << v.detail;
  }
  EXPECT_EQ(listen.verdicts_[5].reason, LoopVerdict::INVALID_INPUT);
  // The log (flushed when the adapter is gone): every candidate's final row.
  const std::vector<std::string> rows = readLines(log);
  ASSERT_EQ(rows.size(), 7u);
  for (int i : {4, 5}) {
    EXPECT_TRUE(contains(rows[i], ",unconfirmed,")) << rows[i];
    EXPECT_EQ(rows[i].substr(rows[i].size() - 7), ",1,drop") << rows[i];
  }
  std::remove(log.c_str());
}

TEST_F(Adapter, AReleasedFirstLoopOfAnEarlierSessionShiftsThatSessionOnly) {
  // A loaded map (sequence 0), session 1 holds its first loop into the map, session 2 starts
  // before the verifier releases it. useLoop shifts session 1 into the map's frame (the
  // released query once) and leaves w_r_vio / w_t_vio, the shift of the keyframes still to come
  // (session 2's), alone.
  std::shared_ptr<ScriptedVerifier::Script> script = std::make_shared<ScriptedVerifier::Script>();
  script->hold = {15};
  FakePoseGraph pg;
  pg.use_imu = true;
  ASSERT_TRUE(pg.rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new ScriptedVerifier(script)),
                                              "test/Scripted"));
  for (int i = 0; i < 10; ++i) {
    FakeKeyFrame kf;
    kf.time_stamp = 1.0 + i;
    kf.vio_T_w_i = Eigen::Vector3d(0.5 * i, 0.0, 0.0);
    ASSERT_TRUE(pg.loadKeyFrame(kf));
  }
  const Eigen::Matrix3d turned = yawR(40.0);
  for (int i = 10; i < 30; ++i) {
    FakeKeyFrame kf;
    kf.time_stamp = 1.0 + i;
    kf.sequence = i < 20 ? 1 : 2;
    kf.vio_T_w_i = Eigen::Vector3d(0.5 * (i % 10), 7.0 * kf.sequence, 0.0);
    kf.vio_R_w_i = turned;
    if (i == 25) script->decide(core::LoopDecision::Kind::kRelease, 15, 5);
    if (i == 15) {
      // findConnection: keyframe 15 is where keyframe 5 is, turned by the same 40 degrees as in
      // its VIO frame: session 1's frame is the map's shifted by (0, 7, 0), no rotation
      const Eigen::Quaterniond q(turned);
      const Detection d{5, (LoopInfo() << 0, 0, 0, q.w(), q.x(), q.y(), q.z(), 40.0).finished(), 30};
      EXPECT_FALSE(pg.addKeyFrame(kf, &d).has_loop);
    } else {
      pg.addKeyFrame(kf, nullptr);
    }
  }
  const FakeKeyFrame& released = pg.keyframelist.at(15);
  EXPECT_TRUE(released.has_loop);
  EXPECT_EQ(released.loop_index, 5);
  EXPECT_LT((released.vio_T_w_i - pg.keyframelist.at(5).vio_T_w_i).norm(), 1e-9) << released.vio_T_w_i.transpose();
  EXPECT_LT((pg.keyframelist.at(16).vio_T_w_i - Eigen::Vector3d(3.0, 0.0, 0.0)).norm(), 1e-9)
      << "the rest of session 1 follows";
  EXPECT_EQ(pg.sequence_loop, (std::vector<int>{0, 1, 0}));
  EXPECT_TRUE(pg.w_r_vio.isIdentity());
  EXPECT_TRUE(pg.w_t_vio.isZero());
  for (int i = 20; i < 30; ++i)
    EXPECT_LT((pg.keyframelist.at(i).vio_T_w_i - Eigen::Vector3d(0.5 * (i % 10), 14.0, 0.0)).norm(), 1e-12) << i;
  EXPECT_EQ(pg.optimize_buf, (std::vector<int>{15, 25}));
  EXPECT_EQ(pg.earliest_loop_index, 5);
}

TEST_F(Adapter, HostDerivedKeysInTheVerifierYamlAreIgnoredWithAnError) {
  // anchor_incoming_keyframes: true would make the verifier shift the session a second time on
  // top of loop_fusion's w_r_vio / w_t_vio (later loops would look metres off and be rejected);
  // accept_without_prior: false would override ~relocalisation. Both come from the host.
  ros::param::set("~relocalisation", "accept_unverified");
  ros::param::set("~rover/anchor_incoming_keyframes", true);
  ros::param::set("~rover/accept_without_prior", false);
  ros::param::set("~rover/confirm_without_prior", true);
  LogCapture log;
  ASSERT_TRUE(log.connect());
  FakePoseGraph pg;
  const bool started = pg.setIMUFlag(true);
  ros::param::del("~rover/anchor_incoming_keyframes");
  ros::param::del("~rover/accept_without_prior");
  ros::param::del("~rover/confirm_without_prior");
  ASSERT_TRUE(started);
  for (const char* key : {"/loop_fusion/rover/anchor_incoming_keyframes", "/loop_fusion/rover/accept_without_prior",
                          "/loop_fusion/rover/confirm_without_prior"})
    EXPECT_FALSE(log.waitFor(rosgraph_msgs::Log::ERROR, {key, "ignored", "host"}).empty()) << key;
  Listener listen;
  ASSERT_TRUE(listen.connect());
  const std::vector<FakeKeyFrame> looped = loadedMapThenNewSession(pg);
  ASSERT_EQ(looped.size(), 3u);
  ASSERT_TRUE(listen.waitFor(3, 3));
  EXPECT_TRUE(listen.verdicts_[0].accepted) << listen.verdicts_[0].detail;
  for (size_t i = 1; i < 3; ++i) {
    EXPECT_EQ(listen.verdicts_[i].reason, LoopVerdict::ACCEPTED) << listen.verdicts_[i].detail;
    EXPECT_LT(listen.verdicts_[i].score, 0.2) << listen.verdicts_[i].detail;
  }
}

TEST_F(Adapter, EveryDecisionParameterIsLoggedAtStartUp) {
  LogCapture log;
  ASSERT_TRUE(log.connect());
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  const std::string line = log.waitFor(rosgraph_msgs::Log::INFO, {"decision parameters"});
  ASSERT_FALSE(line.empty());
  for (const std::string& name : verifierParameterNames())
    EXPECT_TRUE(contains(line, " " + name + "=") || contains(line, ": " + name + "=")) << name << " not in: " << line;
  EXPECT_TRUE(contains(line, "max_innovation=0.5 max_innovation_per_metre=0.02")) << line;  // rover_indoor.yaml
  EXPECT_FALSE(log.waitFor(rosgraph_msgs::Log::INFO, {"relocalisation: confirm"}).empty());
}

TEST_F(Adapter, RejectedLoopsAreNotSavedInThePoseGraph) {
  // A run with false and true candidates, saved as savePoseGraph writes pose_graph.txt and
  // loaded as loadPoseGraph reads it (loop_index != -1 is a loop): the file holds exactly the
  // accepted loops, and the next run commits all of them.
  const std::string file = tempFile("pose_graph.txt");
  const sim::Scene s = corridor(2);
  const std::map<int64_t, const sim::SimCandidate*> candidates = byQuery(s);
  std::set<int> accepted, rejected;
  {
    FakePoseGraph pg;
    ASSERT_TRUE(pg.setIMUFlag(true));
    for (const sim::SimKeyframe& k : s.keyframes) {
      std::unique_ptr<Detection> d;
      auto c = candidates.find(k.index);
      if (c != candidates.end())
        d.reset(new Detection{static_cast<int>(c->second->candidate.match_index), loopInfo(c->second->candidate)});
      const FakeKeyFrame& kf = pg.addKeyFrame(keyframe(k, 1), d.get());
      if (d) (kf.has_loop ? accepted : rejected).insert(kf.index);
    }
    ASSERT_GT(accepted.size(), 2u);
    ASSERT_GT(rejected.size(), 2u);
    pg.savePoseGraph(file);
  }
  FakePoseGraph next;
  ASSERT_TRUE(next.setIMUFlag(true));
  ASSERT_EQ(next.loadPoseGraph(file), static_cast<int>(s.keyframes.size()));
  std::set<int> stored;
  for (const auto& kf : next.keyframelist) {
    if (kf.second.loop_index != -1) stored.insert(kf.first);
    EXPECT_EQ(kf.second.has_loop, kf.second.loop_index != -1) << kf.first;
  }
  EXPECT_EQ(stored, accepted);
  for (int i : rejected) EXPECT_TRUE(next.keyframelist.at(i).loop_info.isZero()) << i;
  std::remove(file.c_str());
}

// ---- plugin selection ----------------------------------------------------------------------

TEST_F(Adapter, AcceptAllPluginUsesEveryLoopLikeUpstream) {
  ros::param::set("~verifier_type", kAcceptAll);
  ros::param::set("~marker_frame", "map");
  ros::param::set("~publish_markers", false);
  const sim::Scene s = corridor(2);
  const std::vector<const sim::SimCandidate*> picks = falseThenTrue(s);
  ASSERT_TRUE(picks[0]);
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  Listener listen;
  ASSERT_TRUE(listen.connect(false));
  const FakeKeyFrame* looped = nullptr;
  for (const sim::SimKeyframe& k : s.keyframes) {
    std::unique_ptr<Detection> d;
    if (k.index == picks[0]->candidate.query_index)
      d.reset(new Detection{static_cast<int>(picks[0]->candidate.match_index), loopInfo(picks[0]->candidate)});
    const FakeKeyFrame& kf = pg.addKeyFrame(keyframe(k, 1), d.get());
    if (d) {
      looped = &kf;
      break;
    }
  }
  ASSERT_TRUE(looped);
  EXPECT_TRUE(looped->has_loop);  // the false loop the trajectory-prior verifier rejects
  EXPECT_EQ(pg.optimize_buf.size(), 1u);
  ASSERT_TRUE(listen.waitFor(1, 0));
  EXPECT_TRUE(listen.verdicts_[0].accepted);
  EXPECT_EQ(listen.verdicts_[0].verifier, kAcceptAll);
  EXPECT_EQ(listen.verdicts_[0].header.frame_id, "map");
  EXPECT_EQ(listen.markerPublishers(), 0u);  // ~publish_markers: false
}

TEST_F(Adapter, UnknownVerifierTypeFallsBackToAcceptAllOnlyWhenAskedTo) {
  ros::param::set("~verifier_type", "rover_loop_fusion/NoSuchVerifier");
  ros::param::set("~fallback_to_accept_all", true);
  FakePoseGraph pg;
  EXPECT_FALSE(pg.setIMUFlag(true));
  EXPECT_FALSE(pg.rover.verifying());
  Listener listen;
  ASSERT_TRUE(listen.connect());
  const sim::Scene s = corridor(2);
  const sim::SimCandidate* f = falseThenTrue(s)[0];
  ASSERT_TRUE(f);
  for (int64_t i = 0; i < f->candidate.query_index; ++i) pg.addKeyFrame(keyframe(s.keyframes[i], 1), nullptr);
  const Detection d{static_cast<int>(f->candidate.match_index), loopInfo(f->candidate)};
  EXPECT_TRUE(pg.addKeyFrame(keyframe(s.keyframes[f->candidate.query_index], 1), &d).has_loop);
  ASSERT_TRUE(listen.waitFor(1, 1));
  EXPECT_TRUE(listen.verdicts_[0].accepted);
  EXPECT_EQ(listen.verdicts_[0].verifier, "fallback:accept_all");
  EXPECT_TRUE(contains(listen.verdicts_[0].detail, "unknown verifier type 'rover_loop_fusion/NoSuchVerifier'"))
      << listen.verdicts_[0].detail;
  EXPECT_TRUE(contains(listen.verdicts_[0].detail, kRover)) << "lists the available types: " << listen.verdicts_[0].detail;
}

TEST_F(Adapter, BadVerifierParameterFallsBackToAcceptAllOnlyWhenAskedTo) {
  ros::param::set("~verifier_name", "broken");
  ros::param::set("~broken/threshold", -1.0);
  ros::param::set("~fallback_to_accept_all", true);
  FakePoseGraph pg;
  EXPECT_FALSE(pg.setIMUFlag(true));
  ros::param::del("~broken");
  Listener listen;
  ASSERT_TRUE(listen.connect());
  for (int i = 0; i < 60; ++i) {
    FakeKeyFrame kf;
    kf.time_stamp = i;
    kf.vio_T_w_i = Eigen::Vector3d(0.5 * i, 0, 0);
    pg.addKeyFrame(kf, nullptr);
  }
  FakeKeyFrame kf;
  kf.time_stamp = 60;
  const Detection d{0, (LoopInfo() << 0.1, 0, 0, 1, 0, 0, 0, 0).finished()};
  EXPECT_TRUE(pg.addKeyFrame(kf, &d).has_loop);
  ASSERT_TRUE(listen.waitFor(1, 1));
  EXPECT_TRUE(contains(listen.verdicts_[0].detail, "threshold")) << listen.verdicts_[0].detail;
  EXPECT_TRUE(contains(listen.verdicts_[0].detail, "/loop_fusion/broken")) << listen.verdicts_[0].detail;
}

// ---- configuration errors stop the host (child processes) ----------------------------------

namespace {

struct HostRun {
  int exit_code = -1;
  std::string output;
};

/// Runs test/ros/adapter_host.cpp (a stand-in for the patched loop_fusion_node) as node
/// `name`, whose private parameters the caller has set.
HostRun runHost(const std::string& name, const std::string& args = "") {
  HostRun r;
  // A host that hangs (e.g. opening a FIFO) is killed after 60 s: exit code 124.
  const std::string cmd =
      "timeout -k 5 60 " + std::string(ROVER_ADAPTER_HOST) + " __name:=" + name + " " + args + " 2>&1";
  FILE* p = ::popen(cmd.c_str(), "r");
  if (!p) return r;
  char buf[4096];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) r.output.append(buf, n);
  const int status = ::pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

}  // namespace

TEST(AdapterStop, ALoopFusionThatEndsByTerminateStillLogsTheFinalVerdictOfAHeldCandidate) {
  // Upstream loop_fusion ends by std::terminate (its main returns with joinable
  // threads: exit status -6 after the 's' save and after Ctrl-C); no destructor runs, so a
  // candidate still held kept only its deferred row. The adapter's terminate handler gives it its
  // final verdict and flushes the log before the abort.
  const std::string log = tempFile("terminate.csv");
  ros::param::set("/terminating_host/verdict_log", log);
  const HostRun r = runHost("terminating_host", "--end-like-loop-fusion");
  ros::param::del("/terminating_host/verdict_log");
  EXPECT_TRUE(contains(r.output, "host: returning from main with a joinable thread")) << r.output;
  EXPECT_NE(r.exit_code, 0) << "the host must end as loop_fusion does (abort)\n" << r.output;
  // What the user sees in loop_fusion's log, redirected to a file or a pipe (buffered): abort()
  // flushes nothing, so the adapter does.
  EXPECT_TRUE(contains(r.output, "loop_fusion ends: 1 candidates still held got their final verdict")) << r.output;
  const std::vector<std::string> rows = readLines(log);
  ASSERT_EQ(rows.size(), 3u) << r.output;
  EXPECT_TRUE(contains(rows[1], ",deferred,") && contains(rows[1], ",0,verify")) << rows[1];
  EXPECT_TRUE(contains(rows[2], ",unconfirmed,") && contains(rows[2], "still held when loop_fusion ended") &&
              contains(rows[2], ",1,drop"))
      << rows[2];
  std::remove(log.c_str());
}

TEST(AdapterStop, ValidParametersStartTheHost) {
  // The harness itself: a correct configuration gets through initialize and verifies.
  const HostRun r = runHost("rover_host_ok");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "host: initialize returned true")) << r.output;
  EXPECT_TRUE(contains(r.output, "host: verifyLoop returned")) << r.output;
}

TEST(AdapterStop, UnknownVerifierTypeStopsAndNamesTheParameter) {
  ros::param::set("/rover_host_type/verifier_type", "rover_loop_fusion/Typo");
  const HostRun r = runHost("rover_host_type");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_FALSE(contains(r.output, "host: initialize returned")) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_type/verifier_type")) << r.output;
  EXPECT_TRUE(contains(r.output, "rover_loop_fusion/Typo")) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_type/fallback_to_accept_all")) << r.output;
}

TEST(AdapterStop, BadThresholdStopsAndNamesTheParameter) {
  ros::param::set("/rover_host_threshold/rover/threshold", -1.0);
  const HostRun r = runHost("rover_host_threshold");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_FALSE(contains(r.output, "host: initialize returned")) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_threshold/rover")) << r.output;
  EXPECT_TRUE(contains(r.output, "threshold must be a positive number")) << r.output;
}

TEST(AdapterStop, WrongTypeOfAnAdapterParameterStops) {
  // Even with the fallback on: the adapter's own parameters are not the plugin's.
  ros::param::set("/rover_host_bool/publish_markers", std::string("yes"));
  ros::param::set("/rover_host_bool/fallback_to_accept_all", true);
  const HostRun r = runHost("rover_host_bool");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_bool/publish_markers must be true or false")) << r.output;
}

TEST(AdapterStop, UnwritableVerdictLogStops) {
  ros::param::set("/rover_host_log/verdict_log", std::string("/nonexistent-dir/verdicts.csv"));
  const HostRun r = runHost("rover_host_log");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_log/verdict_log")) << r.output;
}

TEST(AdapterStop, AVerdictLogFifoWithoutReaderDoesNotBlockStartUp) {
  // open() of a FIFO for writing waits for a reader: loop_fusion would never get past
  // setIMUFlag. The log is opened without blocking, and the rows wait for a reader.
  const std::string fifo = tempFile("verdicts.fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  ros::param::set("/rover_host_fifo/verdict_log", fifo);
  const HostRun r = runHost("rover_host_fifo");
  std::remove(fifo.c_str());
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "host: initialize returned true")) << r.output;
  EXPECT_TRUE(contains(r.output, "host: verifyLoop returned")) << r.output;
  EXPECT_TRUE(contains(r.output, "has no reader yet")) << r.output;
  EXPECT_TRUE(contains(r.output, "were not written")) << "the lost rows are reported: " << r.output;
}

TEST(AdapterStop, UnknownKeysInTheAdapterNamespaceAreReported) {
  ros::param::set("/rover_host_typo/verdict_logg", std::string("/tmp/x.csv"));
  ros::param::set("/rover_host_typo/rovr/threshold", 0.3);
  const HostRun r = runHost("rover_host_typo");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(contains(r.output, "unknown parameter /rover_host_typo/verdict_logg")) << r.output;
  EXPECT_TRUE(contains(r.output, "unknown parameter namespace /rover_host_typo/rovr/")) << r.output;
}

TEST(AdapterStop, BadRelocalisationPolicyStops) {
  ros::param::set("/rover_host_reloc/relocalisation", std::string("accept"));
  const HostRun r = runHost("rover_host_reloc");
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_TRUE(contains(r.output, "/rover_host_reloc/relocalisation must be confirm, reject or accept_unverified")) << r.output;
}

// ---- host safety ---------------------------------------------------------------------------

namespace {

/// A verifier that misbehaves where it is told to.
class MisbehavingVerifier : public LoopVerifier {
 public:
  bool throw_on_init = false, throw_on_add = false, throw_on_verify = false, throw_on_commit = false,
       refuse_commit = false, throw_on_estimate = false;
  core::Status addKeyframe(int64_t, double, int, const Eigen::Vector3d&, const Eigen::Quaterniond&) override {
    if (throw_on_add) throw std::runtime_error("addKeyframe exploded");
    return core::Status::Ok();
  }
  core::Verdict verify(const core::LoopCandidate& c) override {
    if (throw_on_verify) throw std::runtime_error("verify exploded");
    return acceptedVerdict(c);
  }
  core::Status commit(const core::LoopCandidate&) override {
    if (throw_on_commit) throw 42;  // not even a std::exception
    return refuse_commit ? core::Status::Error("no room") : core::Status::Ok();
  }
  bool estimate(int64_t, core::Pose*) const override {
    if (throw_on_estimate) throw std::runtime_error("estimate exploded");
    return false;
  }

 protected:
  bool onInitialize() override {
    if (throw_on_init) throw std::runtime_error("onInitialize exploded");
    return true;
  }
};

/// Two keyframes and one loop between them, as the patch hands them over.
bool oneLoop(LoopFusionAdapter& rover) {
  rover.addKeyframe(0, 1.0, 1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());
  rover.addKeyframe(1, 2.0, 1, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Identity());
  LoopInfo info;
  info << 1, 0, 0, 1, 0, 0, 0, 0;
  return rover.verifyLoop(1, 0, info);
}

}  // namespace

TEST_F(Adapter, ExceptionsFromTheVerifierNeverReachTheHostAndRejectTheLoop) {
  struct Case {
    const char* what;
    bool MisbehavingVerifier::*flag;
    bool used;  // what verifyLoop must return
    const char* detail;
  };
  const Case cases[] = {
      {"verify throws", &MisbehavingVerifier::throw_on_verify, false, "verify exploded"},
      {"commit throws a non-std exception", &MisbehavingVerifier::throw_on_commit, false, "exception"},
      {"commit refused", &MisbehavingVerifier::refuse_commit, false, "refused to commit it: no room"},
      {"addKeyframe throws", &MisbehavingVerifier::throw_on_add, true, ""},
      // drawing the marker fails after the commit: the loop is used and its verdict published
      // (every committed loop has exactly one verdict), without the marker
      {"estimate (markers) throws", &MisbehavingVerifier::throw_on_estimate, true, ""},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.what);
    std::unique_ptr<MisbehavingVerifier> v(new MisbehavingVerifier);
    (*v).*(c.flag) = true;
    LoopFusionAdapter rover;
    ASSERT_TRUE(rover.initializeWithVerifier(true, std::move(v), "test/Misbehaving"));
    Listener listen;
    ASSERT_TRUE(listen.connect());
    EXPECT_EQ(oneLoop(rover), c.used);
    EXPECT_EQ(rover.verdictCount(), 1u);
    ASSERT_TRUE(listen.waitFor(1, 0));
    EXPECT_EQ(listen.verdicts_[0].accepted, c.used);
    EXPECT_EQ(listen.verdicts_[0].verifier, "test/Misbehaving");
    EXPECT_TRUE(contains(listen.verdicts_[0].detail, c.detail)) << listen.verdicts_[0].detail;
    if (!c.used) {
      EXPECT_EQ(listen.verdicts_[0].reason, LoopVerdict::INVALID_INPUT);
    }
  }
}

TEST_F(Adapter, VerifierThatThrowsOnInitializeFallsBackWhenAskedTo) {
  ros::param::set("~fallback_to_accept_all", true);
  std::unique_ptr<MisbehavingVerifier> v(new MisbehavingVerifier);
  v->throw_on_init = true;
  LoopFusionAdapter rover;
  EXPECT_FALSE(rover.initializeWithVerifier(true, std::move(v), "test/Misbehaving"));
  EXPECT_FALSE(rover.verifying());
  EXPECT_TRUE(oneLoop(rover));
}

TEST_F(Adapter, WithoutInitializeEveryLoopIsRejected) {
  LoopFusionAdapter rover;
  EXPECT_FALSE(oneLoop(rover));
  EXPECT_FALSE(rover.commitStoredLoop(1, 0, LoopInfo::Zero()));
  EXPECT_FALSE(rover.verifying());
  EXPECT_EQ(rover.verdictCount(), 0u);
}

TEST_F(Adapter, SecondInitializeIsIgnored) {
  LoopFusionAdapter rover;
  ASSERT_TRUE(rover.initialize(true));
  ros::param::set("~verifier_type", "rover_loop_fusion/NoSuchVerifier");
  EXPECT_TRUE(rover.initialize(false));
  EXPECT_TRUE(rover.verifying());
}

TEST_F(Adapter, BadCandidatesAreRejectedNotThrown) {
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  for (int i = 0; i < 3; ++i) {
    FakeKeyFrame kf;
    kf.time_stamp = i;
    pg.addKeyFrame(kf, nullptr);
  }
  const double nan = std::nan("");
  EXPECT_FALSE(pg.rover.verifyLoop(2, 0, (LoopInfo() << nan, 0, 0, 1, 0, 0, 0, 0).finished()));
  EXPECT_FALSE(pg.rover.verifyLoop(2, 0, (LoopInfo() << 0, 0, 0, 0, 0, 0, 0, 0).finished()));  // zero quaternion
  EXPECT_FALSE(pg.rover.verifyLoop(2, 99, (LoopInfo() << 0, 0, 0, 1, 0, 0, 0, 0).finished()));  // unknown match
  EXPECT_FALSE(pg.rover.verifyLoop(0, 2, (LoopInfo() << 0, 0, 0, 1, 0, 0, 0, 0).finished()));   // match newer
  EXPECT_EQ(pg.rover.verdictCount(), 4u);
  pg.rover.addKeyframe(3, 0.5, 1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());  // stamp goes back
  pg.rover.addKeyframe(4, 9.0, 1, Eigen::Vector3d::Constant(nan), Eigen::Matrix3d::Identity());
  EXPECT_FALSE(pg.rover.verifyLoop(4, 0, (LoopInfo() << 0, 0, 0, 1, 0, 0, 0, 0).finished()));
}

TEST_F(Adapter, EveryCommittedLoopGetsItsVerdictWhateverTheStamps) {
  // Stamps beyond ros::Time's range (ros::Time(double) throws for them) must not cost the
  // verdict of a loop that was committed: it is published with the stamp saturated.
  LoopFusionAdapter rover;
  ASSERT_TRUE(rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new MisbehavingVerifier), "test/Accept"));
  Listener listen;
  ASSERT_TRUE(listen.connect());
  rover.addKeyframe(0, 4294967295.25, 1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());
  rover.addKeyframe(1, 1e300, 1, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Identity());
  LoopInfo info;
  info << 1, 0, 0, 1, 0, 0, 0, 0;
  EXPECT_TRUE(rover.verifyLoop(1, 0, info));
  EXPECT_EQ(rover.verdictCount(), 1u);
  ASSERT_TRUE(listen.waitFor(1, 0));
  EXPECT_TRUE(listen.verdicts_[0].accepted);
  EXPECT_EQ(listen.verdicts_[0].query_stamp, ros::TIME_MAX);
}

namespace {
/// `n` keyframes without loops, stamped `stamp(i)`, at VIO position `position(i)`.
void addKeyframes(FakePoseGraph* pg, int n, const std::function<double(int)>& stamp,
                  const std::function<Eigen::Vector3d(int)>& position) {
  for (int i = 0; i < n; ++i) {
    FakeKeyFrame kf;
    kf.time_stamp = stamp(i);
    kf.vio_T_w_i = position(i);
    pg->addKeyFrame(kf, nullptr);
  }
}
}  // namespace

TEST_F(Adapter, WhatTheVerifierSaysOfAKeyframeItTookIsLoggedInsideLoopFusion) {
  // A keyframe the verifier takes with a warning (here a stalled driver: the clock stops while
  // the pose moves on; elsewhere a VIO relocation, a global pass stopped at its budget) is
  // logged as the standalone node logs it, not kept silent inside loop_fusion.
  LogCapture log;
  ASSERT_TRUE(log.connect());
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  addKeyframes(&pg, 4, [](int i) { return 100.0 + std::min(i, 1); },  // 100, 101, 101, 101
               [](int i) { return Eigen::Vector3d(0.5 * i, 0.0, 0.0); });
  const std::string line = log.waitFor(rosgraph_msgs::Log::WARN, {"verifier, keyframe 2:", "clock stopped"});
  EXPECT_FALSE(line.empty());
  EXPECT_EQ(log.count(rosgraph_msgs::Log::WARN, "clock stopped"), 1u);  // the verifier says it once
}

TEST_F(Adapter, WarningsTheRateLimitHeldBackAreSummarisedWhenLoopFusionEnds) {
  // 25 keyframes the verifier refuses (a NaN position): 20 warnings one by one, then the rest
  // wait for a summary, which finish() (loop_fusion ending) must not lose.
  LogCapture log;
  ASSERT_TRUE(log.connect());
  FakePoseGraph pg;
  ASSERT_TRUE(pg.setIMUFlag(true));
  addKeyframes(&pg, 25, [](int i) { return 100.0 + i; }, [](int) { return Eigen::Vector3d(std::nan(""), 0.0, 0.0); });
  EXPECT_FALSE(log.waitFor(rosgraph_msgs::Log::WARN, {"keyframe 19 not added", "further ones are summarised"}).empty());
  pg.rover.finish();
  EXPECT_FALSE(log.waitFor(rosgraph_msgs::Log::WARN, {"5 more like this (25 in all)", "keyframe 24 not added"}).empty());
}

TEST_F(Adapter, AStalledVerdictLogReaderNeverHoldsUpVerification) {
  // The CSV log is written on its own thread: with a FIFO whose reader does not read, the
  // pipe fills after a few hundred rows, and verifyLoop must still return for every loop.
  const std::string fifo = tempFile("stalled.fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  ros::param::set("~verdict_log", fifo);
  const int n = 3000;  // ~600 kB of rows: ten times a pipe's buffer
  std::atomic<bool> done(false);
  std::atomic<int> used(0);
  {
    LoopFusionAdapter rover;
    ASSERT_TRUE(rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new MisbehavingVerifier), "test/Accept"));
    std::thread host([&] {
      rover.addKeyframe(0, 1.0, 1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());
      rover.addKeyframe(1, 2.0, 1, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Identity());
      LoopInfo info;
      info << 1, 0, 0, 1, 0, 0, 0, 0;
      for (int i = 0; i < n; ++i) used += rover.verifyLoop(1, 0, info);
      done = true;
    });
    // Liveness, not speed: the reader starts reading when the host is done, or after 30 s.
    for (int i = 0; i < 3000 && !done; ++i) ros::WallDuration(0.01).sleep();
    const bool finished_while_stalled = done;
    std::string text;
    char buf[65536];
    int lines = 0;
    const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(60.0);
    while (lines < n + 1 && ros::WallTime::now() < give_up) {
      const ssize_t got = ::read(reader, buf, sizeof(buf));
      if (got > 0) {
        for (ssize_t i = 0; i < got; ++i) lines += buf[i] == '\n';
      } else {
        ros::WallDuration(0.01).sleep();
      }
    }
    host.join();
    EXPECT_TRUE(finished_while_stalled) << "verifyLoop waited for the verdict log's reader";
    EXPECT_EQ(used.load(), n);
    EXPECT_EQ(lines, n + 1) << "header + one row per verdict once the reader reads";
  }
  ::close(reader);
  std::remove(fifo.c_str());
}

TEST_F(Adapter, VerdictLogWriteErrorsAreReported) {
  // /dev/full: every write fails (ENOSPC). Verification goes on; the loss is an ERROR.
  LogCapture log;
  ASSERT_TRUE(log.connect());
  ros::param::set("~verdict_log", std::string("/dev/full"));
  LoopFusionAdapter rover;
  ASSERT_TRUE(rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(new MisbehavingVerifier), "test/Accept"));
  EXPECT_TRUE(oneLoop(rover));
  EXPECT_FALSE(log.waitFor(rosgraph_msgs::Log::ERROR, {"/dev/full", "No space left on device", "lost"}).empty());
}

// ---- ~loop_candidates: what a recorded run replays through rover_verifier_node --------------

namespace {

/// Subscribes to ~loop_candidates on its own callback queue, so that it can be spun from
/// inside a verifier's verify().
class CandidateSpy {
 public:
  CandidateSpy() : nh_("~") {
    nh_.setCallbackQueue(&queue_);
    sub_ = nh_.subscribe("loop_candidates", 100, &CandidateSpy::on, this);
  }
  /// Spins until n candidates arrived (bounded, no timing asserted).
  bool waitFor(size_t n) {
    const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(30.0);
    while (msgs.size() < n && ros::WallTime::now() < give_up && ros::ok()) queue_.callAvailable(ros::WallDuration(0.01));
    return msgs.size() >= n;
  }
  bool connected() {
    const ros::WallTime give_up = ros::WallTime::now() + ros::WallDuration(30.0);
    while (sub_.getNumPublishers() == 0 && ros::WallTime::now() < give_up) ros::WallDuration(0.01).sleep();
    return sub_.getNumPublishers() > 0;
  }
  std::vector<LoopCandidate> msgs;

 private:
  void on(const LoopCandidate& m) { msgs.push_back(m); }
  ros::CallbackQueue queue_;
  ros::NodeHandle nh_;
  ros::Subscriber sub_;
};

/// Accepts every candidate; records whether its ~loop_candidates message had arrived by the
/// time verify() was called.
class SpyVerifier : public LoopVerifier {
 public:
  explicit SpyVerifier(CandidateSpy* spy) : spy_(spy) {}
  core::Status addKeyframe(int64_t, double, int, const Eigen::Vector3d&, const Eigen::Quaterniond&) override {
    return core::Status::Ok();
  }
  core::Verdict verify(const core::LoopCandidate& c) override {
    published_before_verify.push_back(spy_->waitFor(++verified_));
    return acceptedVerdict(c);
  }
  core::Status commit(const core::LoopCandidate&) override { return core::Status::Ok(); }
  std::vector<bool> published_before_verify;

 protected:
  bool onInitialize() override { return true; }

 private:
  CandidateSpy* spy_;
  size_t verified_ = 0;
};

}  // namespace

TEST_F(Adapter, EveryCandidateIsPublishedBeforeItIsVerified) {
  CandidateSpy spy;
  SpyVerifier* verifier = new SpyVerifier(&spy);
  LoopFusionAdapter rover;
  ASSERT_TRUE(rover.initializeWithVerifier(true, std::unique_ptr<LoopVerifier>(verifier), "test/Spy"));
  ASSERT_TRUE(spy.connected());
  rover.addKeyframe(7, 1403636579.763555527, 1, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());
  rover.addKeyframe(8, 1403636580.5, 1, Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Identity());
  const Eigen::Quaterniond q(Eigen::AngleAxisd(10.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  LoopInfo info;
  info << 0.5, -0.25, 0.125, q.w(), q.x(), q.y(), q.z(), 10.0;  // yaw in degrees
  EXPECT_TRUE(rover.verifyLoop(8, 7, info, 33));
  EXPECT_TRUE(rover.verifyLoop(8, 99, info));  // unknown match: published all the same
  EXPECT_EQ(verifier->published_before_verify, (std::vector<bool>{true, true}));
  ASSERT_EQ(spy.msgs.size(), 2u);
  const LoopCandidate& m = spy.msgs[0];
  // Named by stamp, as rover_verifier_node numbers keyframe poses itself.
  EXPECT_EQ(m.query_index, -1);
  EXPECT_EQ(m.match_index, -1);
  EXPECT_NEAR(m.query_stamp.toSec(), 1403636580.5, 1e-6);
  EXPECT_NEAR(m.match_stamp.toSec(), 1403636579.763555527, 1e-6);
  EXPECT_EQ(m.header.stamp, m.query_stamp);
  EXPECT_EQ(m.header.frame_id, "world");
  EXPECT_DOUBLE_EQ(m.relative_pose.position.x, 0.5);
  EXPECT_DOUBLE_EQ(m.relative_pose.position.y, -0.25);
  EXPECT_DOUBLE_EQ(m.relative_pose.position.z, 0.125);
  EXPECT_DOUBLE_EQ(m.relative_pose.orientation.w, q.w());
  EXPECT_DOUBLE_EQ(m.relative_pose.orientation.z, q.z());
  EXPECT_NEAR(m.relative_yaw, 10.0 * M_PI / 180.0, 1e-12);  // radians in the message
  EXPECT_EQ(m.inliers, 33);
  EXPECT_EQ(spy.msgs[1].match_stamp, ros::Time());  // no such keyframe: stamp 0
}

TEST_F(Adapter, CandidatesArePublishedWithTheRealPluginAndInFallbackToo) {
  // The default plugin, and the fallback when the plugin cannot start: every candidate the
  // adapter sees is published, whatever happens to it.
  for (bool fallback : {false, true}) {
    SCOPED_TRACE(fallback ? "fallback" : "rover");
    if (fallback) {
      ros::param::set("~verifier_type", "rover_loop_fusion/NoSuchVerifier");
      ros::param::set("~fallback_to_accept_all", true);
    }
    CandidateSpy spy;
    FakePoseGraph pg;
    EXPECT_EQ(pg.setIMUFlag(true), !fallback);
    ASSERT_TRUE(spy.connected());
    oneLoop(pg.rover);  // keyframes at stamps 1.0 and 2.0, a loop between them
    ASSERT_TRUE(spy.waitFor(1));
    EXPECT_NEAR(spy.msgs[0].query_stamp.toSec(), 2.0, 1e-9);
    EXPECT_NEAR(spy.msgs[0].match_stamp.toSec(), 1.0, 1e-9);
  }
}

// ---- the shipped YAMLs through the parameter server ----------------------------------------

TEST(ConfigFiles, ShippedYamlsLoadWithoutErrorsOrWarnings) {
  // adapter.test loads them into /yaml_check/{indoor,outdoor} with rosparam, as the launch
  // file does.
  const std::pair<const char*, double> files[] = {{"/yaml_check/indoor", 0.2}, {"/yaml_check/outdoor", 1.0}};
  for (const auto& f : files) {
    SCOPED_TRACE(f.first);
    ASSERT_TRUE(ros::param::has(std::string(f.first) + "/threshold"));
    const ConfigLoad load = loadVerifierConfig(ros::NodeHandle(f.first), true);
    EXPECT_TRUE(load.ok()) << (load.errors.empty() ? "" : load.errors[0]);
    EXPECT_TRUE(load.warnings.empty()) << (load.warnings.empty() ? "" : load.warnings[0]);
    EXPECT_DOUBLE_EQ(load.config.metric.threshold, f.second);
    const core::VerifierConfig defaults;
    EXPECT_EQ(load.config.mode, core::Mode::kFourDof);
    EXPECT_EQ(load.config.trial.max_iterations, defaults.trial.max_iterations);
    EXPECT_DOUBLE_EQ(load.config.trial.time_budget_ms, defaults.trial.time_budget_ms);
    EXPECT_NEAR(load.config.input.max_relative_yaw, defaults.input.max_relative_yaw, 1e-12);
    EXPECT_EQ(load.config.host.anchor_incoming_keyframes, false);
  }
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "loop_fusion");
  ros::NodeHandle nh("~");
  return RUN_ALL_TESTS();
}
