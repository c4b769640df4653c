#include "rover_loop_fusion/core/verdict_csv.h"

#include <iomanip>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {
std::string quoted(const std::string& s) {
  std::string out = "\"";
  for (char ch : s) {
    if (ch == '"') out += "\"\"";
    else if (ch == '\n' || ch == '\r') out += ' ';
    else out += ch;
  }
  return out + "\"";
}
}  // namespace

std::string verdictCsvHeader() {
  return "query_stamp,match_stamp,query_index,match_index,accepted,reason,score,threshold,d2,gate,converged,"
         "iterations,window_size,solve_ms,elapsed_ms,inliers,innovation,path_length,verifier,detail,final,decision";
}

std::string verdictCsvRow(const Verdict& v, double query_stamp, double match_stamp, int inliers,
                          const std::string& verifier, const std::string& decision) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(9) << query_stamp << ',' << match_stamp << ','
    << v.query_index << ',' << v.match_index << ',' << (v.accepted ? 1 : 0) << ','
    << toString(v.reason) << ',' << std::setprecision(6) << v.score << ',' << v.threshold << ',' << v.d2 << ','
    << v.gate << ',' << (v.converged ? 1 : 0) << ',' << v.iterations << ',' << v.window_size << ',' << v.solve_ms
    << ',' << v.elapsed_ms << ',' << inliers << ',' << v.innovation << ',' << v.path_length << ','
    << verifier << ',' << quoted(v.detail) << ',' << (v.deferred ? 0 : 1) << ',' << decision;
  return s.str();
}

}  // namespace core
}  // namespace rover_loop_fusion
