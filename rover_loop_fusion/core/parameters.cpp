#include "rover_loop_fusion/core/parameters.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <regex>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

std::string formatNumber(double v) {
  char buf[40];
  if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 1e15) {
    std::snprintf(buf, sizeof buf, "%.0f", v);
    return buf;
  }
  for (int digits = 6; digits <= 17; ++digits) {
    std::snprintf(buf, sizeof buf, "%.*g", digits, v);
    if (!std::isfinite(v) || std::strtod(buf, nullptr) == v) break;
  }
  return buf;
}

namespace {

std::string shortNumber(double v) { return formatNumber(v); }

/// A value as the user wrote it, so that a refusal shows why: text quoted, a number read from
/// text as written ("1e7"), a floating-point number with an integer value with its point ("60.0").
std::string writtenValue(const ParameterValue& v) {
  switch (v.type) {
    case ParameterValue::Type::kText: return "'" + v.text + "'";
    case ParameterValue::Type::kBoolean: return v.toString();
    case ParameterValue::Type::kNumber: break;
  }
  if (!v.text.empty()) return v.text;
  const std::string n = formatNumber(v.number);
  return !v.integral && std::isfinite(v.number) && n.find_first_of(".e") == std::string::npos ? n + ".0" : n;
}

std::string withUnit(const std::string& text, const std::string& unit) {
  return unit.empty() ? text : text + " " + unit;
}

/// YAML 1.1 (PyYAML, what roslaunch reads parameter files with) plain scalars that are numbers.
const std::regex& yamlInteger() {
  static const std::regex r("[-+]?(0|[1-9][0-9]*)");
  return r;
}
const std::regex& yamlFloat() {
  static const std::regex r("[-+]?([0-9]+\\.[0-9]*|\\.[0-9]+)([eE][-+][0-9]+)?");
  return r;
}

/// A plain scalar of a parameter file, resolved as YAML 1.1 would, or an error for forms we do
/// not read (the same text could mean something else to ROS).
bool yamlScalar(const std::string& s, ParameterValue* v, std::string* error) {
  if (s[0] == '"' || s[0] == '\'') {
    if (s.size() < 2 || s.back() != s[0] || s.find(s[0], 1) != s.size() - 1) {
      *error = "unsupported quoting in " + s;
      return false;
    }
    *v = ParameterValue::Text(s.substr(1, s.size() - 2));
    return true;
  }
  if (std::string("[]{}&*!|>%@`'\"").find(s[0]) != std::string::npos) {
    *error = "'" + s + "' is not a plain value (lists, mappings, anchors and tags are not read)";
    return false;
  }
  if (std::regex_match(s, yamlInteger()) || std::regex_match(s, yamlFloat())) {
    *v = ParameterValue::parse(s);
    return true;
  }
  const ParameterValue cli = ParameterValue::parse(s);
  if (cli.type == ParameterValue::Type::kNumber) {
    *error = "'" + s + "' is text to YAML 1.1 (what ROS reads the file with), not a number: write it "
             "with a decimal point and a signed exponent, e.g. 1.0e-4";
    return false;
  }
  *v = cli;
  return true;
}

std::string trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return std::string();
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

}  // namespace

// ---- values -----------------------------------------------------------------------------------

ParameterValue ParameterValue::Number(double v, bool integral) {
  ParameterValue p;
  p.type = Type::kNumber;
  p.number = v;
  p.integral = integral;
  return p;
}

ParameterValue ParameterValue::Boolean(bool b) {
  ParameterValue p;
  p.type = Type::kBoolean;
  p.boolean = b;
  return p;
}

ParameterValue ParameterValue::Text(std::string s) {
  ParameterValue p;
  p.text = std::move(s);
  return p;
}

ParameterValue ParameterValue::parse(const std::string& scalar) {
  const std::string s = trim(scalar);
  if (s == "true" || s == "True" || s == "TRUE") return Boolean(true);
  if (s == "false" || s == "False" || s == "FALSE") return Boolean(false);
  if (!s.empty() && std::string("+-.0123456789").find(s[0]) != std::string::npos) {
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(s.c_str(), &end);
    // ERANGE: overflow (+-HUGE_VAL, not a usable value) or underflow (a tiny value, kept).
    const bool overflow = errno == ERANGE && std::isinf(v);
    if (end == s.c_str() + s.size() && !overflow) {
      const bool integral = s.find_first_not_of("+-0123456789") == std::string::npos;
      ParameterValue n = Number(v, integral);
      n.text = s;  // as written, for messages
      return n;
    }
  }
  if (s.size() >= 2 && (s[0] == '"' || s[0] == '\'') && s.back() == s[0]) return Text(s.substr(1, s.size() - 2));
  return Text(s);
}

std::string ParameterValue::toString() const {
  switch (type) {
    case Type::kNumber: return integral ? std::to_string(static_cast<long long>(number)) : shortNumber(number);
    case Type::kBoolean: return boolean ? "true" : "false";
    case Type::kText: return text;
  }
  return text;
}

// ---- rows -------------------------------------------------------------------------------------

std::string Parameter::range() const {
  switch (type) {
    case Type::kNumber:
    case Type::kInteger:
      return withUnit((min_open ? "(" : "[") + shortNumber(min) + ", " + shortNumber(max) + "]", unit);
    case Type::kBoolean: return "true|false";
    case Type::kChoice: {
      std::string s;
      for (const std::string& c : choices) s += (s.empty() ? "" : "|") + c;
      return s;
    }
  }
  return std::string();
}

std::string Parameter::defaultText() const { return get(VerifierConfig()).toString(); }

std::string Parameter::check(const ParameterValue& v) const {
  const std::string got = " (got " + writtenValue(v) + ")";
  switch (type) {
    case Type::kNumber:
    case Type::kInteger: {
      const bool is_integer = type == Type::kInteger;
      const bool ok = v.type == ParameterValue::Type::kNumber && (!is_integer || v.integral) &&
                      (min_open ? v.number > min : v.number >= min) && v.number <= max;
      if (ok) return std::string();
      if (is_integer) {
        const bool fraction = v.type == ParameterValue::Type::kNumber && !v.integral;
        return "must be an integer in [" + shortNumber(min) + ", " + shortNumber(max) + "]" +
               (fraction ? " (got " + writtenValue(v) + ", not an integer: write it without a point or exponent)"
                         : got);
      }
      if (min_open && min == 0.0) return "must be a positive number up to " + withUnit(shortNumber(max), unit) + got;
      return "must be a number in " + range() + got;
    }
    case Type::kBoolean:
      return v.type == ParameterValue::Type::kBoolean ? std::string() : "must be true or false" + got;
    case Type::kChoice: {
      if (v.type == ParameterValue::Type::kText &&
          std::find(choices.begin(), choices.end(), v.text) != choices.end())
        return std::string();
      std::string s;
      for (size_t i = 0; i < choices.size(); ++i)
        s += (i == 0 ? "" : i + 1 == choices.size() ? " or " : ", ") + choices[i];
      return "must be " + s + got;
    }
  }
  return "has an unknown type";
}

const Parameter* findParameter(const std::string& name) {
  for (const Parameter& p : verifierParameters())
    if (p.name == name) return &p;
  return nullptr;
}

bool assignParameter(const Parameter& p, const ParameterValue& value, VerifierConfig* config,
                     std::string* error, bool host_uses_imu) {
  const std::string why = p.check(value);
  if (!why.empty()) {
    *error = p.name + " " + why;
    return false;
  }
  p.set(config, value, host_uses_imu);
  return true;
}

std::string describe(const VerifierConfig& config) {
  std::string s;
  for (const Parameter& p : verifierParameters())
    s += (s.empty() ? "" : " ") + p.name + "=" + p.get(config).toString();
  return s;
}

std::string VerifierConfig::validate() const {
  std::string s;
  for (const Parameter& p : verifierParameters()) {
    ParameterValue v = p.get(*this);
    // A field kept in radians comes back from degrees within rounding of what was set.
    if (p.unit == "deg" && v.number > p.max && v.number <= p.max * (1.0 + 1e-12)) v.number = p.max;
    const std::string why = p.check(v);
    if (!why.empty()) s += (s.empty() ? "" : "; ") + p.name + " " + why;
  }
  return s;
}

// ---- parameter files --------------------------------------------------------------------------

bool parseParameterText(const std::string& text, const std::string& name, VerifierConfig* config,
                        std::string* error, std::vector<std::string>* keys, bool host_uses_imu) {
  static const std::regex key_line("([A-Za-z_][A-Za-z0-9_]*):(?:[ \t]+(.*))?");
  std::istringstream in(text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? text.substr(3) : text);
  std::vector<std::string> seen;
  std::string line;
  int lineno = 0;
  bool content = false;
  while (std::getline(in, line)) {
    ++lineno;
    auto fail = [&](const std::string& what) {
      *error = name + ":" + std::to_string(lineno) + ": " + what;
      return false;
    };
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::string t = trim(line);
    if (t.empty() || t[0] == '#') continue;
    if (t == "---" && !content) continue;  // a document start before any key
    content = true;
    if (line[0] == ' ' || line[0] == '\t') return fail("indented line: only flat 'key: value' lines are read");
    std::smatch m;
    if (!std::regex_match(t, m, key_line)) return fail("expected 'key: value'");
    const std::string key = m[1];
    // The value: a quoted text, or everything before a comment ('#' after whitespace).
    std::string raw = m[2];
    if (!raw.empty() && (raw[0] == '"' || raw[0] == '\'')) {
      const size_t close = raw.find(raw[0], 1);
      const std::string after = close == std::string::npos ? "?" : trim(raw.substr(close + 1));
      if (!after.empty() && after[0] != '#') return fail(key + ": unsupported quoting in " + raw);
      raw = raw.substr(0, close + 1);
    } else {
      for (size_t i = 1; i < raw.size(); ++i)
        if (raw[i] == '#' && (raw[i - 1] == ' ' || raw[i - 1] == '\t')) {
          raw.resize(i);
          break;
        }
      raw = trim(raw);
    }
    const Parameter* p = findParameter(key);
    if (!p) return fail("unknown key '" + key + "' (not a verifier parameter; a typo?)");
    if (std::find(seen.begin(), seen.end(), key) != seen.end()) return fail("'" + key + "' set twice");
    if (raw.empty() || raw[0] == '#') return fail(key + " has no value");
    ParameterValue v;
    std::string why;
    if (!yamlScalar(raw, &v, &why)) return fail(key + ": " + why);
    if (!assignParameter(*p, v, config, &why, host_uses_imu)) return fail(why);
    seen.push_back(key);
  }
  if (keys) *keys = seen;
  return true;
}

bool readParameterFile(const std::string& path, VerifierConfig* config, std::string* error,
                       std::vector<std::string>* keys, bool host_uses_imu) {
  std::ifstream f(path);
  if (!f) {
    *error = "cannot read " + path;
    return false;
  }
  std::ostringstream ss;
  ss << f.rdbuf();
  return parseParameterText(ss.str(), path, config, error, keys, host_uses_imu);
}

}  // namespace core
}  // namespace rover_loop_fusion
