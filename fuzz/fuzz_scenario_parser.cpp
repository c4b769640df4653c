// Fuzzes the scenario file parsers (keyframes.csv, candidates.csv, groundtruth.csv): any
// text must be parsed or refused with a "name:line: what" message, never crash.
#include "rover_loop_fusion/sim/scenario_io.h"

#include <string>

using namespace rover_loop_fusion::sim;

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  std::string error;
  bool ok = false;
  switch (data[0] % 3) {
    case 0: {
      std::vector<ScenarioKeyframe> k;
      ok = parseKeyframes(text, "keyframes.csv", &k, &error);
      break;
    }
    case 1: {
      std::vector<ScenarioCandidate> c;
      ok = parseCandidates(text, "candidates.csv", &c, &error);
      if (ok)
        for (const ScenarioCandidate& x : c)
          if (x.label < -1 || x.label > 1) __builtin_trap();
      break;
    }
    default: {
      std::vector<int64_t> i;
      std::vector<rover_loop_fusion::core::Pose> p;
      ok = parseGroundTruth(text, "groundtruth.csv", &i, &p, &error);
      if (ok && i.size() != p.size()) __builtin_trap();
    }
  }
  if (!ok && error.empty()) __builtin_trap();
  return 0;
}
