#include "rover_loop_fusion/ros/verdict_output.h"

#include "rover_loop_fusion/core/verdict_csv.h"

#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace rover_loop_fusion {

bool VerdictOutput::initialize(ros::NodeHandle& nh, const Options& options, std::string* error) {
  options_ = options;
  const uint32_t queue = static_cast<uint32_t>(std::max(kVerdictQueueSize, options_.queue_size));
  verdict_pub_ = nh.advertise<LoopVerdict>("loop_verdicts", queue);
  // Markers are for the eye: a small queue, latched for a late rviz.
  if (options_.markers) marker_pub_ = nh.advertise<visualization_msgs::MarkerArray>("loop_markers", 100, true);
  if (options_.csv_path.empty()) return true;
  std::string why;
  if (!log_.open(options_.csv_path, core::verdictCsvHeader(), &why)) {
    if (error) *error = why;
    return false;
  }
  return true;
}

namespace {

/// The namespace of a loop's line marker (its text: + "_score").
const char* markerNamespace(const core::Verdict& v) {
  if (v.accepted) return "accepted_loops";
  if (v.deferred) return "held_loops";
  if (v.reason == core::Reason::kRevoked) return "revoked_loops";
  return "rejected_loops";
}

}  // namespace

LoopVerdict VerdictOutput::publish(const core::Verdict& verdict, const VerdictContext& ctx) {
  const LoopVerdict m = toVerdictMsg(verdict, ctx, options_.frame_id);
  if (log_.isOpen())
    log_.append(core::verdictCsvRow(verdict, ctx.query_stamp, ctx.match_stamp, ctx.inliers, ctx.verifier,
                                    ctx.decision));
  ++count_;
  verdict_pub_.publish(m);
  if (options_.markers && ctx.have_positions) {
    // A held loop is drawn amber; its final verdict replaces that marker (green: released, red:
    // dropped), and a revocation turns an accepted loop's green marker red: one marker per
    // candidate, under the namespace of its state.
    const std::pair<int64_t, int64_t> key(verdict.query_index, verdict.match_index);
    const std::string ns = markerNamespace(verdict);
    int id = static_cast<int>(count_);
    visualization_msgs::MarkerArray arr;
    auto shown = shown_.find(key);
    if (shown != shown_.end()) {
      id = shown->second.id;
      if (shown->second.ns != ns)
        for (const std::string& gone : {shown->second.ns, shown->second.ns + "_score"}) {
          visualization_msgs::Marker del;
          del.header.frame_id = options_.frame_id;
          del.header.stamp = m.header.stamp;
          del.ns = gone;
          del.id = id;
          del.action = visualization_msgs::Marker::DELETE;
          arr.markers.push_back(del);
        }
      shown_.erase(shown);
    }
    // Only a held or accepted loop can change colour later.
    if (verdict.deferred || verdict.accepted) shown_[key] = Shown{id, ns};
    visualization_msgs::Marker line;
    line.header.frame_id = options_.frame_id;
    line.header.stamp = m.header.stamp;
    line.ns = ns;
    line.id = id;
    line.type = visualization_msgs::Marker::LINE_LIST;
    line.action = visualization_msgs::Marker::ADD;
    line.pose.orientation.w = 1.0;
    line.scale.x = 0.05;
    line.color.a = 1.0;
    line.color.r = verdict.accepted ? 0.1f : verdict.deferred ? 1.0f : 0.9f;
    line.color.g = verdict.accepted ? 0.8f : verdict.deferred ? 0.7f : 0.1f;
    line.color.b = 0.1f;
    line.points.push_back(toPoint(ctx.query_position));
    line.points.push_back(toPoint(ctx.match_position));
    visualization_msgs::Marker text = line;
    text.ns = line.ns + "_score";
    text.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    text.points.clear();
    text.pose.position = toPoint(0.5 * (ctx.query_position + ctx.match_position) + Eigen::Vector3d(0, 0, 0.3));
    text.scale.x = text.scale.y = 0.0;
    text.scale.z = 0.25;
    std::ostringstream label;
    label << m.query_index << "->" << m.match_index << " ";
    if (std::isfinite(m.score)) label << std::fixed << std::setprecision(2) << m.score << " m";
    else label << m.reason;
    if (m.decision != LoopVerdict::VERIFY || verdict.deferred) label << " (" << (verdict.deferred ? "held" : m.decision) << ")";
    text.text = label.str();
    arr.markers.push_back(line);
    arr.markers.push_back(text);
    marker_pub_.publish(arr);
  }
  return m;
}

}  // namespace rover_loop_fusion
