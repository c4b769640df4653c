// Where verdicts go: the ~loop_verdicts topic, rviz markers on ~loop_markers and an optional
// CSV log. Shared by the loop_fusion adapter and rover_verifier_node.
#pragma once

#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/types.h"
#include "rover_loop_fusion/core/verifier.h"

#include <Eigen/Core>
#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <cstdio>
#include <string>
#include <vector>

namespace rover_loop_fusion {

/// What the core verdict does not know about the candidate.
struct VerdictContext {
  double query_stamp = 0.0;
  double match_stamp = 0.0;
  int inliers = -1;
  std::string verifier;  ///< plugin type
  bool have_positions = false;  ///< draw a marker only when both positions are known
  Eigen::Vector3d query_position = Eigen::Vector3d::Zero();
  Eigen::Vector3d match_position = Eigen::Vector3d::Zero();
};

/// The estimated position of keyframe `index` in a trajectory ordered by index (as
/// LoopVerifier::trajectory() returns it); false if the trajectory does not have it.
bool findTrajectoryPosition(const std::vector<core::TrajectoryPoint>& trajectory, int64_t index,
                            Eigen::Vector3d* position);

LoopVerdict toMsg(const core::Verdict& v, const VerdictContext& ctx, const std::string& frame_id);

class VerdictOutput {
 public:
  struct Options {
    std::string frame_id = "world";  ///< frame of markers and verdict headers
    bool markers = true;
    std::string csv_path;  ///< empty: no CSV log
  };

  VerdictOutput() = default;
  ~VerdictOutput();
  VerdictOutput(const VerdictOutput&) = delete;
  VerdictOutput& operator=(const VerdictOutput&) = delete;

  /// Advertises ~loop_verdicts and ~loop_markers on `nh`; opens the CSV log (appends, writes
  /// the header to a new or empty file). False with a message if the log cannot be opened.
  bool initialize(ros::NodeHandle& nh, const Options& options, std::string* error);

  /// Publishes, draws and logs one verdict; returns the message.
  LoopVerdict publish(const core::Verdict& verdict, const VerdictContext& ctx);

  size_t published() const { return count_; }

 private:
  Options options_;
  ros::Publisher verdict_pub_;
  ros::Publisher marker_pub_;
  std::FILE* csv_ = nullptr;
  size_t count_ = 0;
};

}  // namespace rover_loop_fusion
