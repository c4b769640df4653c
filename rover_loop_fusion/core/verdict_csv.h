// One CSV format for verdict logs, written by the ROS nodes (~verdict_log) and by
// rover_replay, read by scripts/evaluate.py.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <string>

namespace rover_loop_fusion {
namespace core {

std::string verdictCsvHeader();
/// One row. `decision`: how the verdict came about (LoopVerdict.msg): "verify" (when the
/// candidate was verified; a deferred verdict is not final), or the later decision on it:
/// "release", "drop", "revoke" (toString(LoopDecision::Kind)). Column `final` is 0 only for a
/// deferred verdict.
std::string verdictCsvRow(const Verdict& v, double query_stamp, double match_stamp, int inliers,
                          const std::string& verifier, const std::string& decision = "verify");

}  // namespace core
}  // namespace rover_loop_fusion
