// One CSV format for verdict logs, written by the ROS nodes (~verdict_log) and by
// rover_replay, read by scripts/evaluate.py.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <string>

namespace rover_loop_fusion {
namespace core {

std::string verdictCsvHeader();
std::string verdictCsvRow(const Verdict& v, double query_stamp, double match_stamp, int inliers,
                          const std::string& verifier);

}  // namespace core
}  // namespace rover_loop_fusion
