#include "rover_loop_fusion/sim/scenario_io.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>

namespace rover_loop_fusion {
namespace sim {

namespace {

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return std::string();
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

std::vector<std::string> split(const std::string& line) {
  std::vector<std::string> f;
  std::string item;
  std::stringstream ss(line);
  while (std::getline(ss, item, ',')) f.push_back(trim(item));
  if (!line.empty() && line.back() == ',') f.push_back(std::string());
  return f;
}

bool toDouble(const std::string& s, double* v) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *v = std::strtod(s.c_str(), &end);
  // ERANGE is overflow (+-HUGE_VAL: refused) or underflow (1e-320, a denormal or 0: a value).
  return end == s.c_str() + s.size() && !(errno == ERANGE && std::isinf(*v));
}

bool toInt(const std::string& s, int64_t* v) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  const long long x = std::strtoll(s.c_str(), &end, 10);
  *v = x;
  return end == s.c_str() + s.size() && errno != ERANGE;
}

/// Calls row(fields, error) for every data line after checking the header.
template <class Row>
bool parseTable(const std::string& text, const std::string& name, const std::string& header, Row row,
                std::string* error) {
  // A UTF-8 byte order mark (spreadsheets write one) is not part of the header.
  std::istringstream in(text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? text.substr(3) : text);
  std::string line;
  int lineno = 0;
  bool have_header = false;
  const size_t columns = split(header).size();
  while (std::getline(in, line)) {
    ++lineno;
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    auto fail = [&](const std::string& what) {
      *error = name + ":" + std::to_string(lineno) + ": " + what;
      return false;
    };
    if (!have_header) {
      if (t != header) return fail("expected the header '" + header + "'");
      have_header = true;
      continue;
    }
    const std::vector<std::string> f = split(t);
    if (f.size() != columns)
      return fail("expected " + std::to_string(columns) + " fields, got " + std::to_string(f.size()));
    std::string what;
    if (!row(f, &what)) return fail(what);
  }
  if (!have_header) {
    *error = name + ": empty (no header '" + header + "')";
    return false;
  }
  return true;
}

bool numbers(const std::vector<std::string>& f, size_t from, size_t n, double* out, std::string* what) {
  for (size_t i = 0; i < n; ++i) {
    if (!toDouble(f[from + i], &out[i])) {
      *what = "field " + std::to_string(from + i + 1) + " '" + f[from + i] + "' is not a number";
      return false;
    }
  }
  return true;
}

bool integer(const std::vector<std::string>& f, size_t i, int64_t* out, std::string* what) {
  if (toInt(f[i], out)) return true;
  *what = "field " + std::to_string(i + 1) + " '" + f[i] + "' is not an integer";
  return false;
}

core::Pose pose(const double* p) {  // x y z qx qy qz qw
  return core::Pose(Eigen::Vector3d(p[0], p[1], p[2]), Eigen::Quaterniond(p[6], p[3], p[4], p[5]));
}

bool readFile(const std::string& path, std::string* text, std::string* error) {
  std::ifstream f(path);
  if (!f) {
    *error = "cannot read " + path;
    return false;
  }
  std::ostringstream ss;
  ss << f.rdbuf();
  *text = ss.str();
  return true;
}

}  // namespace

bool parseKeyframes(const std::string& text, const std::string& name,
                    std::vector<ScenarioKeyframe>* out, std::string* error) {
  out->clear();
  return parseTable(text, name, "index,stamp,sequence,x,y,z,qx,qy,qz,qw",
                    [&](const std::vector<std::string>& f, std::string* what) {
                      ScenarioKeyframe k;
                      int64_t seq = 0;
                      double v[8];
                      if (!integer(f, 0, &k.index, what) || !numbers(f, 1, 1, &k.stamp, what) ||
                          !integer(f, 2, &seq, what) || !numbers(f, 3, 7, v, what))
                        return false;
                      if (seq < -1000000 || seq > 1000000) {
                        *what = "sequence out of range";
                        return false;
                      }
                      k.sequence = static_cast<int>(seq);
                      k.vio = pose(v);
                      out->push_back(k);
                      return true;
                    },
                    error);
}

bool parseCandidates(const std::string& text, const std::string& name,
                     std::vector<ScenarioCandidate>* out, std::string* error) {
  out->clear();
  return parseTable(
      text, name, "query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label",
      [&](const std::vector<std::string>& f, std::string* what) {
        ScenarioCandidate c;
        double v[8];
        int64_t inliers = 0, label = 0;
        if (!integer(f, 0, &c.candidate.query_index, what) ||
            !integer(f, 1, &c.candidate.match_index, what) || !numbers(f, 2, 8, v, what) ||
            !integer(f, 10, &inliers, what) || !integer(f, 11, &label, what))
          return false;
        if (label < -1 || label > 1) {
          *what = "label must be 1, 0 or -1";
          return false;
        }
        const core::Pose p = pose(v);
        c.candidate.relative_t = p.t;
        c.candidate.relative_q = p.q;
        c.candidate.relative_yaw = v[7];
        c.candidate.inliers = inliers < -1 || inliers > 1000000000 ? -1 : static_cast<int>(inliers);
        c.label = static_cast<int>(label);
        out->push_back(c);
        return true;
      },
      error);
}

bool parseGroundTruth(const std::string& text, const std::string& name,
                      std::vector<int64_t>* index, std::vector<core::Pose>* out, std::string* error) {
  index->clear();
  out->clear();
  return parseTable(text, name, "index,x,y,z,qx,qy,qz,qw",
                    [&](const std::vector<std::string>& f, std::string* what) {
                      int64_t i = 0;
                      double v[7];
                      if (!integer(f, 0, &i, what) || !numbers(f, 1, 7, v, what)) return false;
                      index->push_back(i);
                      out->push_back(pose(v));
                      return true;
                    },
                    error);
}

bool loadScenario(const std::string& dir, Scenario* s, std::string* error) {
  std::string text;
  if (!readFile(dir + "/keyframes.csv", &text, error) ||
      !parseKeyframes(text, "keyframes.csv", &s->keyframes, error))
    return false;
  if (!readFile(dir + "/candidates.csv", &text, error) ||
      !parseCandidates(text, "candidates.csv", &s->candidates, error))
    return false;
  s->truth.clear();
  s->truth_index.clear();
  std::ifstream gt(dir + "/groundtruth.csv");
  if (gt) {
    if (!readFile(dir + "/groundtruth.csv", &text, error) ||
        !parseGroundTruth(text, "groundtruth.csv", &s->truth_index, &s->truth, error))
      return false;
  }
  return true;
}

}  // namespace sim
}  // namespace rover_loop_fusion
