// Where verdicts go: the ~loop_verdicts topic, rviz markers on ~loop_markers and an optional
// CSV log (written on its own thread, verdict_log.h). Shared by the loop_fusion adapter and
// rover_verifier_node.
#pragma once

#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/ros/conversions.h"
#include "rover_loop_fusion/ros/verdict_log.h"

#include <Eigen/Core>
#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <string>
#include <vector>

namespace rover_loop_fusion {

/// The estimated position of keyframe `index` in a trajectory ordered by index (as
/// LoopVerifier::trajectory() returns it); false if the trajectory does not have it.
bool findTrajectoryPosition(const std::vector<core::TrajectoryPoint>& trajectory, int64_t index,
                            Eigen::Vector3d* position);

class VerdictOutput {
 public:
  struct Options {
    std::string frame_id = "world";  ///< frame of markers and verdict headers
    bool markers = true;
    std::string csv_path;  ///< empty: no CSV log
    /// Outgoing queue of ~loop_verdicts per subscriber (and the most CSV rows waiting). roscpp
    /// drops the oldest message of a full queue without telling anyone, so it must hold every
    /// verdict a burst can produce: at least as many as candidates can be waiting in the host.
    int queue_size = 100000;
  };

  VerdictOutput() = default;
  VerdictOutput(const VerdictOutput&) = delete;
  VerdictOutput& operator=(const VerdictOutput&) = delete;

  /// Advertises ~loop_verdicts and ~loop_markers on `nh`; opens the CSV log (appends, writes
  /// the header to a new or empty file) without blocking. False with a message if the log
  /// cannot be opened.
  bool initialize(ros::NodeHandle& nh, const Options& options, std::string* error);

  /// Publishes, draws and logs one verdict; returns the message. Throws only what roscpp's
  /// publish throws (the callers guard it).
  LoopVerdict publish(const core::Verdict& verdict, const VerdictContext& ctx);

  size_t published() const { return count_; }
  const VerdictLog& log() const { return log_; }

 private:
  Options options_;
  ros::Publisher verdict_pub_;
  ros::Publisher marker_pub_;
  VerdictLog log_;
  size_t count_ = 0;
};

}  // namespace rover_loop_fusion
