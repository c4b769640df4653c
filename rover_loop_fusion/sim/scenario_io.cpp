#include "rover_loop_fusion/sim/scenario_io.h"

#include <Eigen/Cholesky>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <algorithm>
#include <fstream>
#include <limits>
#include <map>
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

/// A row of these files is a few hundred bytes; a longer line is refused without being held in
/// memory (a 60 MB line cost 417 MB before the error when whole files and lines were copied).
const size_t kMaxLine = 65536;

/// The lines of a file's text, read from a string (without copying it) or a stream (one line at
/// a time, at most kMaxLine bytes of it held). A leading UTF-8 byte order mark is skipped.
class Lines {
 public:
  explicit Lines(const std::string& text) : text_(&text) {}
  explicit Lines(std::istream& in) : in_(&in) {}
  /// The next line without its '\n'; false at the end. *too_long: longer than kMaxLine (the
  /// line is cut there, the rest of it skipped).
  bool next(std::string* line, bool* too_long) {
    line->clear();
    *too_long = false;
    bool got = text_ ? fromText(line, too_long) : fromStream(line, too_long);
    if (got && first_) {
      first_ = false;
      // A UTF-8 byte order mark (spreadsheets write one) is not part of the header.
      if (line->compare(0, 3, "\xEF\xBB\xBF") == 0) line->erase(0, 3);
    }
    return got;
  }

 private:
  bool fromText(std::string* line, bool* too_long) {
    if (pos_ >= text_->size()) return false;
    size_t end = text_->find('\n', pos_);
    if (end == std::string::npos) end = text_->size();
    const size_t n = end - pos_;
    *too_long = n > kMaxLine;
    line->assign(*text_, pos_, std::min(n, kMaxLine));
    pos_ = end + 1;
    return true;
  }
  bool fromStream(std::string* line, bool* too_long) {
    std::streambuf* buf = in_->rdbuf();
    bool any = false;
    for (;;) {
      const int c = buf->sbumpc();
      if (c == std::char_traits<char>::eof()) return any;
      any = true;
      if (c == '\n') return true;
      if (line->size() < kMaxLine) line->push_back(static_cast<char>(c));
      else *too_long = true;
    }
  }

  const std::string* text_ = nullptr;
  std::istream* in_ = nullptr;
  size_t pos_ = 0;
  bool first_ = true;
};

/// Calls row(fields, error) for every data line after checking the header.
template <class Row>
bool parseTable(Lines& in, const std::string& name, const std::string& header, Row row, std::string* error) {
  std::string line;
  bool too_long = false;
  int lineno = 0;
  bool have_header = false;
  const size_t columns = split(header).size();
  while (in.next(&line, &too_long)) {
    ++lineno;
    auto fail = [&](const std::string& what) {
      *error = name + ":" + std::to_string(lineno) + ": " + what;
      return false;
    };
    if (too_long)
      return fail("a line longer than " + std::to_string(kMaxLine) + " bytes (not a row of " + name + ")");
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
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

}  // namespace

bool parseKeyframes(Lines& text, const std::string& name, std::vector<ScenarioKeyframe>* out,
                    std::string* error) {
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

bool parseCandidates(Lines& text, const std::string& name, std::vector<ScenarioCandidate>* out,
                     std::string* error) {
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
        if (inliers < -1 || inliers > std::numeric_limits<int>::max()) {
          *what = "inliers " + f[10] + " out of range (-1: unknown, or 0 to " +
                  std::to_string(std::numeric_limits<int>::max()) + ")";
          return false;
        }
        c.candidate.inliers = static_cast<int>(inliers);
        c.label = static_cast<int>(label);
        out->push_back(c);
        return true;
      },
      error);
}

bool parseGroundTruth(Lines& text, const std::string& name, std::vector<int64_t>* index,
                      std::vector<core::Pose>* out, std::string* error) {
  index->clear();
  out->clear();
  std::map<int64_t, size_t> seen;  // index -> its row (1-based among the data rows)
  return parseTable(text, name, "index,x,y,z,qx,qy,qz,qw",
                    [&](const std::vector<std::string>& f, std::string* what) {
                      int64_t i = 0;
                      double v[7];
                      if (!integer(f, 0, &i, what) || !numbers(f, 1, 7, v, what)) return false;
                      // Ground truth is what everything is measured against: no NaN, no second
                      // pose for a keyframe (ATE and evaluate.py would use either, or fail).
                      for (int j = 0; j < 7; ++j)
                        if (!std::isfinite(v[j])) {
                          *what = "field " + std::to_string(j + 2) + " '" + f[j + 1] + "' is not finite";
                          return false;
                        }
                      if (!seen.emplace(i, index->size() + 1).second) {
                        *what = "keyframe " + f[0] + " has a ground-truth pose already (data row " +
                                std::to_string(seen[i]) + ")";
                        return false;
                      }
                      index->push_back(i);
                      out->push_back(pose(v));
                      return true;
                    },
                    error);
}

using StepCovariances =
    std::vector<std::pair<int64_t, Eigen::Matrix4d>, Eigen::aligned_allocator<std::pair<int64_t, Eigen::Matrix4d>>>;

bool parseStepCovariances(Lines& text, const std::string& name, StepCovariances* out, std::string* error) {
  out->clear();
  std::map<int64_t, size_t> seen;
  return parseTable(text, name, "index,xx,xy,xz,xyaw,yy,yz,yyaw,zz,zyaw,yawyaw",
                    [&](const std::vector<std::string>& f, std::string* what) {
                      int64_t i = 0;
                      double v[10];
                      if (!integer(f, 0, &i, what) || !numbers(f, 1, 10, v, what)) return false;
                      for (int j = 0; j < 10; ++j)
                        if (!std::isfinite(v[j])) {
                          *what = "field " + std::to_string(j + 2) + " '" + f[j + 1] + "' is not finite";
                          return false;
                        }
                      Eigen::Matrix4d C;
                      int k = 0;
                      for (int r = 0; r < 4; ++r)
                        for (int c = r; c < 4; ++c) C(r, c) = C(c, r) = v[k++];
                      if (Eigen::LLT<Eigen::Matrix4d>(C).info() != Eigen::Success) {
                        *what = "the covariance of keyframe " + f[0] + " is not positive definite";
                        return false;
                      }
                      if (!seen.emplace(i, out->size() + 1).second) {
                        *what = "keyframe " + f[0] + " has a step covariance already (data row " +
                                std::to_string(seen[i]) + ")";
                        return false;
                      }
                      out->emplace_back(i, C);
                      return true;
                    },
                    error);
}

bool parseStepCovariances(const std::string& text, const std::string& name, StepCovariances* out,
                          std::string* error) {
  Lines lines(text);
  return parseStepCovariances(lines, name, out, error);
}

bool parseKeyframes(const std::string& text, const std::string& name, std::vector<ScenarioKeyframe>* out,
                    std::string* error) {
  Lines lines(text);
  return parseKeyframes(lines, name, out, error);
}

bool parseCandidates(const std::string& text, const std::string& name, std::vector<ScenarioCandidate>* out,
                     std::string* error) {
  Lines lines(text);
  return parseCandidates(lines, name, out, error);
}

bool parseGroundTruth(const std::string& text, const std::string& name, std::vector<int64_t>* index,
                      std::vector<core::Pose>* out, std::string* error) {
  Lines lines(text);
  return parseGroundTruth(lines, name, index, out, error);
}

bool loadScenario(const std::string& dir, Scenario* s, std::string* error) {
  // Each file is read line by line (a line at most kMaxLine bytes), never whole.
  auto read = [&](const std::string& file, bool optional, auto parse) {
    std::ifstream in(dir + "/" + file, std::ios::binary);
    if (!in) {
      if (optional) return true;
      *error = "cannot read " + dir + "/" + file;
      return false;
    }
    Lines lines(in);
    return parse(lines, file);
  };
  s->truth.clear();
  s->truth_index.clear();
  s->step_covariance.clear();
  return read("keyframes.csv", false,
              [&](Lines& l, const std::string& f) { return parseKeyframes(l, f, &s->keyframes, error); }) &&
         read("candidates.csv", false,
              [&](Lines& l, const std::string& f) { return parseCandidates(l, f, &s->candidates, error); }) &&
         read("groundtruth.csv", true, [&](Lines& l, const std::string& f) {
           return parseGroundTruth(l, f, &s->truth_index, &s->truth, error);
         }) &&
         read("odometry.csv", true,
              [&](Lines& l, const std::string& f) { return parseStepCovariances(l, f, &s->step_covariance, error); });
}

}  // namespace sim
}  // namespace rover_loop_fusion
