// Every verifier parameter in one table: its name (the YAML key, the ROS parameter and
// rover_replay's flag), unit, default, range and a one-line doc. The table drives
// VerifierConfig::validate(), the reading of the verifier keys on the ROS parameter server
// (ros/params.cpp), rover_replay's flags and its --config file, describe() (logged at start-up)
// and the test that the shipped YAMLs and the docs list every key.
//
// The rows are in parameter_table.cpp; the values, checks and parameter files in parameters.cpp.
// Adding a parameter: a field of VerifierConfig (core/types.h), one row in parameter_table.cpp,
// and a commented line in config/rover_template.yaml: a key, or "# name: default" in its last
// block if it has no effect at the defaults (test/python/test_shipped_keys.py).
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <functional>
#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace core {

/// A number as messages print it: an integer value in full ("10000000"), otherwise the fewest
/// significant digits that read back as the same value ("0.2", "0.999999999999").
std::string formatNumber(double v);

/// A value as a reader found it: a number (an integer if written as one), a boolean, or text.
struct ParameterValue {
  enum class Type { kNumber, kBoolean, kText };
  Type type = Type::kText;
  double number = 0.0;
  bool integral = false;  ///< a number written as an integer (no '.', exponent, inf or nan)
  bool boolean = false;
  std::string text;  ///< the text; for a number parse() read, as written (messages)

  static ParameterValue Number(double v, bool integral);
  static ParameterValue Boolean(bool b);
  static ParameterValue Text(std::string s);
  /// A scalar as written in a YAML file or on a command line: true/false (also True, TRUE, ...),
  /// a number (strtod's syntax, the whole text), else text (one pair of quotes removed).
  static ParameterValue parse(const std::string& scalar);
  /// As a YAML scalar ("0.2", "true", "se3").
  std::string toString() const;
};

struct Parameter {
  enum class Type { kNumber, kInteger, kBoolean, kChoice };
  std::string name;  ///< YAML key, ROS parameter, rover_replay --flag
  Type type = Type::kNumber;
  std::string unit;  ///< "m", "m/m", "deg", "ms", "s", "keyframes" or "" (none)
  double min = 0.0, max = 0.0;  ///< inclusive range of kNumber / kInteger, in `unit`
  bool min_open = false;        ///< (min, max]: min itself is not allowed
  std::vector<std::string> choices;  ///< kChoice
  std::string doc;                   ///< one line
  /// Set by the host (the loop_fusion adapter or rover_verifier_node), never from a verifier
  /// YAML: a value there is ignored with an ERROR (ros/plugins.cpp), and the shipped YAMLs do
  /// not list it. rover_replay takes it as a flag.
  bool host_set = false;

  /// The value in a config, in `unit` (the 4-DoF/6-DoF mode as "4dof"/"6dof").
  std::function<ParameterValue(const VerifierConfig&)> get;
  /// Stores a value that passed check() (`host_uses_imu` resolves mode: auto).
  std::function<void(VerifierConfig*, const ParameterValue&, bool host_uses_imu)> set;

  /// Empty if `value` has the right type and lies in the range; else "must be ... (got ...)".
  std::string check(const ParameterValue& value) const;
  /// The range as text: "(0, 10] m", "[1, 10]", "true|false", "auto|4dof|6dof".
  std::string range() const;
  /// The default (VerifierConfig's) as text.
  std::string defaultText() const;
};

/// The table, in the order of its rows (parameter_table.cpp).
const std::vector<Parameter>& verifierParameters();
/// The row of `name`; nullptr if none.
const Parameter* findParameter(const std::string& name);

/// Checks a value against its row and stores it in `config`. False (and `error` says what is
/// wrong, naming the parameter) leaves the config unchanged.
bool assignParameter(const Parameter& p, const ParameterValue& value, VerifierConfig* config,
                     std::string* error, bool host_uses_imu = true);

/// Every parameter and its value in one line, in the YAML's units ("mode=4dof alignment=se3
/// threshold=0.2 ..."): what the hosts log at start-up.
std::string describe(const VerifierConfig& config);

/// Reads a verifier parameter file: flat YAML, `key: value` per line, `#` comments, blank
/// lines. Strict: an unknown or repeated key, a value of the wrong type or out of range, or
/// anything else YAML would read differently (indentation, lists, mappings, anchors) is an
/// error "name:line: what". Keys present are assigned in file order; absent keys keep their
/// value. `keys` (optional) receives the keys read, in file order. On error `config` may hold
/// the keys before the bad line.
bool parseParameterText(const std::string& text, const std::string& name, VerifierConfig* config,
                        std::string* error, std::vector<std::string>* keys = nullptr,
                        bool host_uses_imu = true);
bool readParameterFile(const std::string& path, VerifierConfig* config, std::string* error,
                       std::vector<std::string>* keys = nullptr, bool host_uses_imu = true);

}  // namespace core
}  // namespace rover_loop_fusion
