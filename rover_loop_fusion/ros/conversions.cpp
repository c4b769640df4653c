#include "rover_loop_fusion/ros/conversions.h"

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>

namespace rover_loop_fusion {

ros::Time toRosTime(double seconds) {
  if (!(seconds > 0.0)) return ros::Time();
  if (!(seconds < 4294967296.0)) return ros::TIME_MAX;
  const double whole = std::floor(seconds);
  uint64_t sec = static_cast<uint64_t>(whole);
  uint64_t nsec = static_cast<uint64_t>(std::llround((seconds - whole) * 1e9));
  sec += nsec / 1000000000ull;
  nsec %= 1000000000ull;
  if (sec > 0xFFFFFFFFull) return ros::TIME_MAX;
  return ros::Time(static_cast<uint32_t>(sec), static_cast<uint32_t>(nsec));
}

ros::Time rosTimeFromNs(int64_t ns) {
  if (ns <= 0) return ros::Time();
  const uint64_t sec = static_cast<uint64_t>(ns) / 1000000000ull;
  if (sec > 0xFFFFFFFFull) return ros::TIME_MAX;
  return ros::Time(static_cast<uint32_t>(sec), static_cast<uint32_t>(static_cast<uint64_t>(ns) % 1000000000ull));
}

std::string stampText(const ros::Time& t) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%u.%09u", t.sec, t.nsec);
  return buf;
}

std::string stampText(double seconds) {
  if (seconds >= 0.0 && seconds < 4294967296.0) return stampText(toRosTime(seconds));
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.9g", seconds);
  return buf;
}

double yawOf(const Eigen::Quaterniond& q) {
  const double n = q.norm();
  if (!std::isfinite(n) || n < 1e-9) return std::nan("");
  const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
  return std::atan2(R(1, 0), R(0, 0));
}

geometry_msgs::Point toPoint(const Eigen::Vector3d& p) {
  geometry_msgs::Point q;
  q.x = p.x();
  q.y = p.y();
  q.z = p.z();
  return q;
}

geometry_msgs::PoseStamped toPoseStamped(const core::Pose& p, const ros::Time& stamp, const std::string& frame) {
  geometry_msgs::PoseStamped s;
  s.header.stamp = stamp;
  s.header.frame_id = frame;
  s.pose.position = toPoint(p.t);
  s.pose.orientation.w = p.q.w();
  s.pose.orientation.x = p.q.x();
  s.pose.orientation.y = p.q.y();
  s.pose.orientation.z = p.q.z();
  return s;
}

LoopCandidate toCandidateMsg(const core::LoopCandidate& c, double query_stamp, double match_stamp,
                             const std::string& frame_id) {
  LoopCandidate m;
  m.query_stamp = toRosTime(query_stamp);
  m.match_stamp = toRosTime(match_stamp);
  m.header.stamp = m.query_stamp;
  m.header.frame_id = frame_id;
  m.query_index = -1;
  m.match_index = -1;
  m.relative_pose.position = toPoint(c.relative_t);
  m.relative_pose.orientation.w = c.relative_q.w();
  m.relative_pose.orientation.x = c.relative_q.x();
  m.relative_pose.orientation.y = c.relative_q.y();
  m.relative_pose.orientation.z = c.relative_q.z();
  m.relative_yaw = c.relative_yaw;
  m.inliers = c.inliers;
  return m;
}

double loopYaw(const Eigen::Quaterniond& match_rotation, const Eigen::Quaterniond& relative) {
  const double nm = match_rotation.norm(), nr = relative.norm();
  if (!std::isfinite(nm) || !std::isfinite(nr) || nm < 1e-9 || nr < 1e-9) return std::nan("");
  const Eigen::Quaterniond m = match_rotation.normalized();
  const double d = yawOf(m * relative.normalized()) - yawOf(m);
  return std::atan2(std::sin(d), std::cos(d));
}

core::LoopCandidate fromCandidateMsg(const LoopCandidate& msg, int64_t query, int64_t match,
                                     const Eigen::Quaterniond& match_rotation) {
  core::LoopCandidate c;
  c.query_index = query;
  c.match_index = match;
  const geometry_msgs::Pose& p = msg.relative_pose;
  c.relative_t = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  c.relative_q = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
  c.relative_yaw = std::isnan(msg.relative_yaw) ? loopYaw(match_rotation, c.relative_q) : msg.relative_yaw;
  c.inliers = msg.inliers;
  return c;
}

LoopVerdict toVerdictMsg(const core::Verdict& v, const VerdictContext& ctx, const std::string& frame_id) {
  LoopVerdict m;
  m.query_stamp = toRosTime(ctx.query_stamp);
  m.match_stamp = toRosTime(ctx.match_stamp);
  m.header.stamp = m.query_stamp;
  m.header.frame_id = frame_id;
  m.query_index = v.query_index;
  m.match_index = v.match_index;
  m.accepted = v.accepted;
  m.reason = core::toString(v.reason);
  m.detail = v.detail;
  m.score = v.score;
  m.threshold = v.threshold;
  m.d2 = v.d2;
  m.gate = v.gate;
  m.converged = v.converged;
  m.iterations = v.iterations;
  m.window_size = v.window_size;
  m.innovation = v.innovation;
  m.path_length = v.path_length;
  m.solve_ms = v.solve_ms;
  m.elapsed_ms = v.elapsed_ms;
  m.inliers = ctx.inliers;
  m.verifier = ctx.verifier;
  m.final = !v.deferred;
  m.decision = ctx.decision;
  return m;
}

}  // namespace rover_loop_fusion
