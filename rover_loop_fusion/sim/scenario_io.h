// Scenario directories: plain-text keyframes, candidates and ground truth, the common input
// of rover_replay (core only) and the Python tools (simulator, benchmarks, evaluation).
// Format (docs/scenario-format.md), comma separated, '#' comments, a header line first:
//   keyframes.csv    index,stamp,sequence,x,y,z,qx,qy,qz,qw        (VIO pose)
//   candidates.csv   query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label
//                    (query in match frame; relative_yaw [rad]; label 1 true, 0 false, -1 unknown)
//   groundtruth.csv  index,x,y,z,qx,qy,qz,qw                      (optional)
//   odometry.csv     index,xx,xy,xz,xyaw,yy,yz,yyaw,zz,zyaw,yawyaw (optional: the covariance of
//                    the odometry step that ends at keyframe `index`, upper triangle, x y z yaw
//                    in that keyframe's frame; where the data carries it, e.g. g2o files)
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <Eigen/Core>

#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace sim {

struct ScenarioKeyframe {
  int64_t index = 0;
  double stamp = 0.0;
  int sequence = 0;
  core::Pose vio;
};

struct ScenarioCandidate {
  core::LoopCandidate candidate;
  int label = -1;
};

struct Scenario {
  std::vector<ScenarioKeyframe> keyframes;
  std::vector<ScenarioCandidate> candidates;  ///< in file order
  std::vector<int64_t> truth_index;
  std::vector<core::Pose> truth;  ///< empty without groundtruth.csv
  /// Step covariances of odometry.csv (empty without it): keyframe index -> covariance.
  std::vector<std::pair<int64_t, Eigen::Matrix4d>, Eigen::aligned_allocator<std::pair<int64_t, Eigen::Matrix4d>>>
      step_covariance;
};

/// Parses CSV text of one of the three files (a leading UTF-8 byte order mark is skipped). On
/// error returns false and sets `error` to "<name>:<line>: what". Keyframes and candidates are
/// parsed, not judged: NaN, a denormal like 1e-320 or an unknown index is the verifier's
/// business; a number beyond the range of double (1e999), an inlier count outside -1 ..
/// INT_MAX and a line longer than 64 kB are errors. Ground truth is judged: a value that is
/// not finite, or a second pose for one keyframe, is an error.
bool parseKeyframes(const std::string& text, const std::string& name,
                    std::vector<ScenarioKeyframe>* out, std::string* error);
bool parseCandidates(const std::string& text, const std::string& name,
                     std::vector<ScenarioCandidate>* out, std::string* error);
bool parseGroundTruth(const std::string& text, const std::string& name,
                      std::vector<int64_t>* index, std::vector<core::Pose>* out, std::string* error);

/// odometry.csv: a row per keyframe whose step covariance is given. Judged: values that are not
/// finite, a second row for a keyframe or a covariance that is not positive definite are errors.
bool parseStepCovariances(const std::string& text, const std::string& name,
                          std::vector<std::pair<int64_t, Eigen::Matrix4d>,
                                      Eigen::aligned_allocator<std::pair<int64_t, Eigen::Matrix4d>>>* out,
                          std::string* error);

/// Reads a scenario directory (groundtruth.csv and odometry.csv optional), each file line by line.
bool loadScenario(const std::string& dir, Scenario* out, std::string* error);

}  // namespace sim
}  // namespace rover_loop_fusion
