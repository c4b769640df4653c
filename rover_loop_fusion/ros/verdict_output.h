// Where verdicts go: the ~loop_verdicts topic, rviz markers on ~loop_markers and an optional
// CSV log (written on its own thread, verdict_log.h). Shared by the loop_fusion adapter and
// rover_verifier_node.
#pragma once

#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/types.h"
#include "rover_loop_fusion/ros/conversions.h"
#include "rover_loop_fusion/ros/verdict_log.h"

#include <Eigen/Core>
#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <map>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {

/// The least outgoing queue of ~loop_verdicts per subscriber, in both hosts: roscpp drops the
/// oldest message of a full queue without telling anyone, so it must hold every verdict a burst
/// can produce (thousands of candidates timing out together, a backlog decided at shutdown).
constexpr int kVerdictQueueSize = 100000;

class VerdictOutput {
 public:
  struct Options {
    std::string frame_id = "world";  ///< frame of markers and verdict headers
    bool markers = true;
    std::string csv_path;  ///< empty: no CSV log
    /// Outgoing queue of ~loop_verdicts per subscriber: at least kVerdictQueueSize (a smaller
    /// value is raised to it), more for a host that can hold more candidates waiting.
    int queue_size = kVerdictQueueSize;
  };

  VerdictOutput() = default;
  VerdictOutput(const VerdictOutput&) = delete;
  VerdictOutput& operator=(const VerdictOutput&) = delete;

  /// Advertises ~loop_verdicts and ~loop_markers on `nh`; opens the CSV log (appends, writes
  /// the header to a new or empty file) without blocking. False with a message if the log
  /// cannot be opened.
  bool initialize(ros::NodeHandle& nh, const Options& options, std::string* error);

  /// Publishes, draws and logs one verdict; returns the message. Markers: one per candidate,
  /// green accepted, red rejected, amber held (deferred); the final verdict of a held
  /// candidate and the revocation of an accepted loop replace its marker (ns held_loops ->
  /// accepted_loops / rejected_loops, accepted_loops -> revoked_loops). Throws only what
  /// roscpp's publish throws (the callers guard it).
  LoopVerdict publish(const core::Verdict& verdict, const VerdictContext& ctx);

  size_t published() const { return count_; }
  const VerdictLog& log() const { return log_; }
  /// Waits up to timeout_s for the CSV rows queued so far to be written; the rows still waiting.
  size_t flushLog(double timeout_s) { return log_.isOpen() ? log_.flush(timeout_s) : 0; }

 private:
  Options options_;
  ros::Publisher verdict_pub_;
  ros::Publisher marker_pub_;
  VerdictLog log_;
  size_t count_ = 0;
  /// Markers that may change colour later (held and accepted loops), by (query, match).
  struct Shown {
    int id;
    std::string ns;
  };
  std::map<std::pair<int64_t, int64_t>, Shown> shown_;
};

}  // namespace rover_loop_fusion
