// Conversions between the core's plain values and ROS messages, in one place for the loop_fusion
// adapter and rover_verifier_node. None of them throws, whatever the input: stamps outside
// ros::Time's range saturate (ros::Time(double) throws for them, and a throw after a commit
// would leave a used loop without its verdict).
#pragma once

#include "rover_loop_fusion/LoopCandidate.h"
#include "rover_loop_fusion/LoopVerdict.h"
#include "rover_loop_fusion/core/types.h"

#include <Eigen/Core>
#include <geometry_msgs/Point.h>
#include <geometry_msgs/PoseStamped.h>
#include <ros/time.h>

#include <cstdint>
#include <string>

namespace rover_loop_fusion {

/// Seconds -> ros::Time, rounded as ros::Time(double) rounds; NaN and values <= 0 give 0,
/// values beyond ros::TIME_MAX give ros::TIME_MAX.
ros::Time toRosTime(double seconds);
/// Nanoseconds -> ros::Time (<= 0: 0; saturating like toRosTime).
ros::Time rosTimeFromNs(int64_t ns);
/// "sec.nsec" with nine decimals; any double is printable ("nan", "-1.5e+300").
std::string stampText(const ros::Time& t);
std::string stampText(double seconds);

/// Yaw [rad] of a rotation (Z-Y-X, as loop_fusion's Utility::R2ypr, in radians); NaN for a
/// quaternion that cannot be normalised.
double yawOf(const Eigen::Quaterniond& q);

geometry_msgs::Point toPoint(const Eigen::Vector3d& p);
geometry_msgs::PoseStamped toPoseStamped(const core::Pose& p, const ros::Time& stamp, const std::string& frame);

/// A candidate message naming its keyframes by stamp (indices -1), as the adapter publishes it
/// on ~loop_candidates for replay through rover_verifier_node (whose keyframe numbers are not
/// loop_fusion's indices).
LoopCandidate toCandidateMsg(const core::LoopCandidate& c, double query_stamp, double match_stamp,
                             const std::string& frame_id);
/// The core candidate of a message whose keyframes resolved to `query` and `match`. A NaN
/// relative_yaw (unknown) is derived as loop_fusion computes loop_info[7], the difference of the
/// keyframes' world yaws: loopYaw(match_rotation, relative rotation), match_rotation being the
/// match keyframe's VIO rotation (not the yaw of the relative rotation, which differs from it
/// on a tilted body).
core::LoopCandidate fromCandidateMsg(const LoopCandidate& msg, int64_t query, int64_t match,
                                     const Eigen::Quaterniond& match_rotation);

/// loop_fusion's relative yaw of a loop [rad]: yaw(R_m R_rel) - yaw(R_m), wrapped to (-pi, pi];
/// NaN if a quaternion cannot be normalised.
double loopYaw(const Eigen::Quaterniond& match_rotation, const Eigen::Quaterniond& relative);

/// What the core verdict does not know about the candidate.
struct VerdictContext {
  double query_stamp = 0.0;
  double match_stamp = 0.0;
  int inliers = -1;
  std::string verifier;  ///< plugin type
  /// How the verdict came about: verify (when the candidate was verified), or the later
  /// decision on it: release, drop, revoke (LoopVerdict.msg).
  std::string decision = "verify";
  bool have_positions = false;  ///< draw a marker only when both positions are known
  Eigen::Vector3d query_position = Eigen::Vector3d::Zero();
  Eigen::Vector3d match_position = Eigen::Vector3d::Zero();
};

LoopVerdict toVerdictMsg(const core::Verdict& v, const VerdictContext& ctx, const std::string& frame_id);

}  // namespace rover_loop_fusion
