#include "rover_loop_fusion/ros/verdict_output.h"

#include "rover_loop_fusion/core/verdict_csv.h"

#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <iomanip>
#include <sstream>

namespace rover_loop_fusion {

namespace {

geometry_msgs::Point point(const Eigen::Vector3d& p) {
  geometry_msgs::Point q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  return q;
}

}  // namespace

bool findTrajectoryPosition(const std::vector<core::TrajectoryPoint>& trajectory, int64_t index,
                            Eigen::Vector3d* position) {
  auto it = std::lower_bound(trajectory.begin(), trajectory.end(), index,
                             [](const core::TrajectoryPoint& p, int64_t i) { return p.index < i; });
  if (it == trajectory.end() || it->index != index) return false;
  *position = it->estimate.t;
  return true;
}

LoopVerdict toMsg(const core::Verdict& v, const VerdictContext& ctx, const std::string& frame_id) {
  LoopVerdict m;
  m.header.stamp = ros::Time(std::max(0.0, ctx.query_stamp));
  m.header.frame_id = frame_id;
  m.query_index = v.query_index;
  m.match_index = v.match_index;
  m.query_stamp = ros::Time(std::max(0.0, ctx.query_stamp));
  m.match_stamp = ros::Time(std::max(0.0, ctx.match_stamp));
  m.accepted = v.accepted;
  m.reason = core::toString(v.reason);
  m.detail = v.detail;
  m.score = v.score;
  m.threshold = v.threshold;
  m.converged = v.converged;
  m.iterations = v.iterations;
  m.window_size = v.window_size;
  m.innovation = v.innovation;
  m.path_length = v.path_length;
  m.solve_ms = v.solve_ms;
  m.elapsed_ms = v.elapsed_ms;
  m.inliers = ctx.inliers;
  m.verifier = ctx.verifier;
  return m;
}

VerdictOutput::~VerdictOutput() {
  if (csv_) std::fclose(csv_);
}

bool VerdictOutput::initialize(ros::NodeHandle& nh, const Options& options, std::string* error) {
  options_ = options;
  verdict_pub_ = nh.advertise<LoopVerdict>("loop_verdicts", 100);
  if (options_.markers) marker_pub_ = nh.advertise<visualization_msgs::MarkerArray>("loop_markers", 100, true);
  if (!options_.csv_path.empty()) {
    csv_ = std::fopen(options_.csv_path.c_str(), "a");
    if (!csv_) {
      if (error) *error = "cannot open verdict log " + options_.csv_path + ": " + std::strerror(errno);
      return false;
    }
    if (std::ftell(csv_) == 0) {
      std::fprintf(csv_, "%s\n", core::verdictCsvHeader().c_str());
      std::fflush(csv_);
    }
  }
  return true;
}

LoopVerdict VerdictOutput::publish(const core::Verdict& verdict, const VerdictContext& ctx) {
  const LoopVerdict m = toMsg(verdict, ctx, options_.frame_id);
  verdict_pub_.publish(m);
  if (csv_) {
    std::fprintf(csv_, "%s\n", core::verdictCsvRow(verdict, ctx.query_stamp, ctx.match_stamp, ctx.inliers, ctx.verifier).c_str());
    std::fflush(csv_);
  }
  if (options_.markers && ctx.have_positions) {
    visualization_msgs::MarkerArray arr;
    visualization_msgs::Marker line;
    line.header.frame_id = options_.frame_id;
    line.header.stamp = m.header.stamp;
    line.ns = verdict.accepted ? "accepted_loops" : "rejected_loops";
    line.id = static_cast<int>(count_);
    line.type = visualization_msgs::Marker::LINE_LIST;
    line.action = visualization_msgs::Marker::ADD;
    line.pose.orientation.w = 1.0;
    line.scale.x = 0.05;
    line.color.a = 1.0;
    line.color.r = verdict.accepted ? 0.1f : 0.9f;
    line.color.g = verdict.accepted ? 0.8f : 0.1f;
    line.color.b = 0.1f;
    line.points.push_back(point(ctx.query_position));
    line.points.push_back(point(ctx.match_position));
    visualization_msgs::Marker text = line;
    text.ns = line.ns + "_score";
    text.type = visualization_msgs::Marker::TEXT_VIEW_FACING;
    text.points.clear();
    text.pose.position = point(0.5 * (ctx.query_position + ctx.match_position) + Eigen::Vector3d(0, 0, 0.3));
    text.scale.x = text.scale.y = 0.0;
    text.scale.z = 0.25;
    std::ostringstream label;
    label << m.query_index << "->" << m.match_index << " ";
    if (std::isfinite(m.score)) label << std::fixed << std::setprecision(2) << m.score << " m";
    else label << m.reason;
    text.text = label.str();
    arr.markers.push_back(line);
    arr.markers.push_back(text);
    marker_pub_.publish(arr);
  }
  ++count_;
  return m;
}

}  // namespace rover_loop_fusion
