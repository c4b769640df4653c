// The one parameter table (core/parameters.h): every row is wired to its own field and has a
// range; the shipped YAMLs set exactly the table's keys and load with the strict reader that
// rover_replay --config uses; the docs name every key; values are parsed strictly
// (rover_replay --max_innovation abc is an error, not 0).
#include "rover_loop_fusion/core/parameters.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>
#include <sstream>

using namespace rover_loop_fusion::core;

namespace {

const std::string kSource = ROVER_SOURCE_DIR;
/// The page that documents every verifier parameter.
const std::string kParameterDoc = "docs/ros-api.md";

std::string readText(const std::string& path) {
  std::ifstream f(path);
  EXPECT_TRUE(f.good()) << path;
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

std::set<std::string> tableNames(bool with_host_set = true) {
  std::set<std::string> n;
  for (const Parameter& p : verifierParameters())
    if (with_host_set || !p.host_set) n.insert(p.name);
  return n;
}

/// A value of the row's type that lies outside its range (or is of the wrong kind).
ParameterValue outside(const Parameter& p) {
  switch (p.type) {
    case Parameter::Type::kNumber: return ParameterValue::Number(p.max * 2 + 1, false);
    case Parameter::Type::kInteger: return ParameterValue::Number(p.max + 1, true);
    case Parameter::Type::kBoolean: return ParameterValue::Text("maybe");
    case Parameter::Type::kChoice: return ParameterValue::Text("none_of_these");
  }
  return ParameterValue();
}

/// A value inside the row's range that differs from the default.
ParameterValue otherInside(const Parameter& p) {
  const ParameterValue d = p.get(VerifierConfig());
  switch (p.type) {
    case Parameter::Type::kNumber: return ParameterValue::Number(d.number == p.max ? p.max / 2 : p.max, false);
    case Parameter::Type::kInteger: return ParameterValue::Number(d.number == p.max ? p.min : p.max, true);
    case Parameter::Type::kBoolean: return ParameterValue::Boolean(!d.boolean);
    case Parameter::Type::kChoice:
      for (const std::string& c : p.choices)
        if (c != d.text && c != "auto") return ParameterValue::Text(c);
  }
  return ParameterValue();
}

int run(const std::string& command, std::string* output) {
  std::FILE* f = popen((command + " 2>&1").c_str(), "r");
  if (!f) return -1;
  char buf[4096];
  output->clear();
  while (size_t n = std::fread(buf, 1, sizeof buf, f)) output->append(buf, n);
  const int status = pclose(f);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

}  // namespace

TEST(ParameterTable, EveryRowHasItsOwnFieldARangeAndADoc) {
  ASSERT_GE(verifierParameters().size(), 19u);
  EXPECT_EQ(tableNames().size(), verifierParameters().size()) << "duplicate names";
  EXPECT_EQ(VerifierConfig().validate(), "") << "the defaults lie in their ranges";
  for (const Parameter& p : verifierParameters()) {
    SCOPED_TRACE(p.name);
    EXPECT_FALSE(p.doc.empty());
    EXPECT_FALSE(p.range().empty());
    EXPECT_EQ(findParameter(p.name), &p);
    // Setting this row changes this row's value and no other.
    VerifierConfig c;
    std::string error;
    const ParameterValue v = otherInside(p);
    ASSERT_TRUE(assignParameter(p, v, &c, &error)) << error;
    EXPECT_EQ(c.validate(), "");
    for (const Parameter& q : verifierParameters()) {
      const std::string now = q.get(c).toString(), before = q.get(VerifierConfig()).toString();
      if (&q == &p) EXPECT_NE(now, before) << "set does not reach get";
      else EXPECT_EQ(now, before) << "setting " << p.name << " changed " << q.name;
    }
    // Out of range: refused with the name, the config unchanged; validate() names it too.
    const ParameterValue bad = outside(p);
    VerifierConfig untouched;
    EXPECT_FALSE(assignParameter(p, bad, &untouched, &error));
    EXPECT_EQ(error.compare(0, p.name.size() + 1, p.name + " "), 0) << error;
    EXPECT_EQ(describe(untouched), describe(VerifierConfig()));
    if (bad.type == ParameterValue::Type::kNumber) {
      VerifierConfig forced;
      p.set(&forced, bad, true);
      EXPECT_NE(forced.validate().find(p.name), std::string::npos) << forced.validate();
    }
  }
  EXPECT_EQ(findParameter("treshold"), nullptr);
}

TEST(ParameterTable, RangesRefuseWhatTheRedTeamFound) {
  VerifierConfig c;
  std::string error;
  // function_tolerance >= 0.5 made every trial solve "converge" at once and let false loops in.
  EXPECT_FALSE(assignParameter(*findParameter("function_tolerance"), ParameterValue::parse("0.5"), &c, &error));
  EXPECT_NE(error.find("function_tolerance"), std::string::npos) << error;
  EXPECT_FALSE(assignParameter(*findParameter("odometry_neighbours"), ParameterValue::parse("1e8"), &c, &error));
  EXPECT_FALSE(assignParameter(*findParameter("odometry_neighbours"), ParameterValue::parse("100000000"), &c, &error));
  EXPECT_FALSE(assignParameter(*findParameter("max_innovation"), ParameterValue::parse("abc"), &c, &error));
  EXPECT_NE(error.find("got 'abc'"), std::string::npos) << error;
  EXPECT_FALSE(assignParameter(*findParameter("threshold"), ParameterValue::parse("nan"), &c, &error));
  EXPECT_FALSE(assignParameter(*findParameter("threshold"), ParameterValue::parse("-1"), &c, &error));
  EXPECT_NE(error.find("threshold must be a positive number"), std::string::npos) << error;
  EXPECT_FALSE(assignParameter(*findParameter("max_iterations"), ParameterValue::parse("5.5"), &c, &error));
  EXPECT_FALSE(assignParameter(*findParameter("mode"), ParameterValue::parse("7dof"), &c, &error));
  EXPECT_NE(error.find("must be auto, 4dof or 6dof"), std::string::npos) << error;
  EXPECT_EQ(describe(c), describe(VerifierConfig())) << "refused values change nothing";
  c.trial.function_tolerance = 0.5;
  c.trial.odometry_neighbours = 100000000;
  EXPECT_NE(c.validate().find("function_tolerance"), std::string::npos);
  EXPECT_NE(c.validate().find("odometry_neighbours"), std::string::npos);
  // mode: auto follows the host.
  ASSERT_TRUE(assignParameter(*findParameter("mode"), ParameterValue::parse("auto"), &c, &error, false));
  EXPECT_EQ(c.mode, Mode::kSixDof);
  ASSERT_TRUE(assignParameter(*findParameter("mode"), ParameterValue::parse("auto"), &c, &error, true));
  EXPECT_EQ(c.mode, Mode::kFourDof);
  // Degrees in, radians stored; the largest allowed value passes validate() after the round trip.
  ASSERT_TRUE(assignParameter(*findParameter("max_relative_yaw_deg"), ParameterValue::parse("180"), &c, &error));
  EXPECT_DOUBLE_EQ(c.input.max_relative_yaw, M_PI);
  EXPECT_EQ(VerifierConfig(c).validate().find("max_relative_yaw"), std::string::npos) << c.validate();
}

TEST(ParameterValues, AreParsedStrictly) {
  EXPECT_EQ(ParameterValue::parse("abc").type, ParameterValue::Type::kText);
  EXPECT_EQ(ParameterValue::parse("0.5abc").type, ParameterValue::Type::kText);
  EXPECT_EQ(ParameterValue::parse("").type, ParameterValue::Type::kText);
  const ParameterValue tiny = ParameterValue::parse("1e-320");  // denormal: strtod says ERANGE
  ASSERT_EQ(tiny.type, ParameterValue::Type::kNumber);
  EXPECT_GT(tiny.number, 0.0);
  EXPECT_EQ(ParameterValue::parse("1e999").type, ParameterValue::Type::kText) << "overflow is no number";
  EXPECT_TRUE(ParameterValue::parse("12").integral);
  EXPECT_FALSE(ParameterValue::parse("12.0").integral);
  EXPECT_FALSE(ParameterValue::parse("1e2").integral);
  EXPECT_TRUE(ParameterValue::parse("True").boolean);
  EXPECT_EQ(ParameterValue::parse("yes").type, ParameterValue::Type::kText);
  EXPECT_EQ(ParameterValue::parse("'se3'").text, "se3");
}

TEST(ParameterFiles, ShippedYamlsSetTableKeysInTiers) {
  // config/rover_template.yaml sets table keys (not the host-set ones) at the core's defaults;
  // each override sets only keys of the template, read after it (test_config.cpp: each commented;
  // test/python/test_config_tiers.py: the template names the rest, the sets are as before).
  VerifierConfig t;
  std::string error;
  std::vector<std::string> template_keys;
  ASSERT_TRUE(readParameterFile(kSource + "/config/rover_template.yaml", &t, &error, &template_keys)) << error;
  EXPECT_EQ(describe(t), describe(VerifierConfig())) << "the template holds the core's defaults";
  const std::set<std::string> table = tableNames(/*with_host_set=*/false);
  for (const std::string& k : template_keys) EXPECT_TRUE(table.count(k)) << k;
  EXPECT_GT(template_keys.size(), 20u);
  for (const char* file : {"rover_indoor.yaml", "rover_outdoor.yaml", "rover_paper.yaml"}) {
    SCOPED_TRACE(file);
    VerifierConfig c = t;
    std::vector<std::string> keys;
    ASSERT_TRUE(readParameterFile(kSource + "/config/" + file, &c, &error, &keys)) << error;
    for (const std::string& k : keys)
      EXPECT_NE(std::find(template_keys.begin(), template_keys.end(), k), template_keys.end()) << k;
    EXPECT_EQ(c.validate(), "");
  }
  VerifierConfig indoor = t, outdoor = t;
  ASSERT_TRUE(readParameterFile(kSource + "/config/rover_indoor.yaml", &indoor, &error)) << error;
  ASSERT_TRUE(readParameterFile(kSource + "/config/rover_outdoor.yaml", &outdoor, &error)) << error;
  EXPECT_EQ(describe(indoor), describe(VerifierConfig())) << "template + indoor: the core's defaults";
  EXPECT_DOUBLE_EQ(outdoor.metric.threshold, 1.0);
}

TEST(ParameterFiles, TheDocsNameEveryKey) {
  const std::string doc = readText(kSource + "/" + kParameterDoc);
  for (const Parameter& p : verifierParameters())
    EXPECT_NE(doc.find("`" + p.name + "`"), std::string::npos) << kParameterDoc << " does not name " << p.name;
}

TEST(ParameterFiles, TheReaderIsStrictAndSaysWhere) {
  VerifierConfig c;
  std::string e;
  std::vector<std::string> keys;
  // What the shipped files use: comments, blank lines, a document start, CRLF, a BOM, quotes.
  ASSERT_TRUE(parseParameterText("\xEF\xBB\xBF# c\n---\n\nthreshold: 0.3  # trailing\r\nmode: '6dof'\n"
                                 "robust_candidate: true\nfunction_tolerance: 1.0e-5\nmax_iterations: 20\n",
                                 "p.yaml", &c, &e, &keys))
      << e;
  EXPECT_DOUBLE_EQ(c.metric.threshold, 0.3);
  EXPECT_EQ(c.mode, Mode::kSixDof);
  EXPECT_TRUE(c.trial.robust_candidate);
  EXPECT_DOUBLE_EQ(c.trial.function_tolerance, 1e-5);
  EXPECT_EQ(c.trial.max_iterations, 20);
  EXPECT_EQ(keys.size(), 5u);
  auto refused = [&](const std::string& text, const std::string& words) {
    VerifierConfig d;
    std::string error;
    EXPECT_FALSE(parseParameterText(text, "p.yaml", &d, &error)) << text;
    EXPECT_NE(error.find(words), std::string::npos) << text << " -> " << error;
  };
  refused("threshold: 0.3\ntreshold: 0.2\n", "p.yaml:2: unknown key 'treshold'");
  refused("threshold: 0.3\nthreshold: 0.2\n", "p.yaml:2: 'threshold' set twice");
  refused("threshold: abc\n", "threshold must be a positive number");
  refused("max_innovation: -1\n", "max_innovation must be a number in [0, 100] m (got -1)");
  refused("function_tolerance: 1e-4\n", "text to YAML 1.1");  // ROS would read a string
  refused("function_tolerance: 0.5\n", "function_tolerance must be");
  refused("odometry_neighbours: 4.0\n", "must be an integer");
  // Issue 45 item 8: the real bound and the value as written, so that the refusal says why
  // (before: "must be a number in [0.5, 1] (got 1)", "must be an integer in [1, 100000] (got 60)").
  refused("gate_probability: 1.0\n", "gate_probability must be a number in [0.5, 0.999999999999] (got 1.0)");
  refused("revisit_window: 60.0\n", "must be an integer in [1, 100000] (got 60.0, not an integer");
  refused("global_window: 1.0e+7\n", "must be an integer in [1, 10000000] (got 1.0e+7, not an integer");
  refused("robust_candidate: yes\n", "must be true or false");
  refused("threshold:\n  nested: 0.2\n", "p.yaml:1: threshold has no value");
  refused("threshold: 0.2\n  max_iterations: 3\n", "p.yaml:2: indented");
  refused("threshold: [0.2]\n", "not a plain value");
  refused("threshold 0.2\n", "expected 'key: value'");
  refused("mode: \"4dof\n", "quoting");
}

TEST(RoverReplay, FlagsComeFromTheTableAndAreStrict) {
  const std::string tool = ROVER_REPLAY;
  const std::string scenario = kSource + "/data/corridor";
  const std::string out = ::testing::TempDir() + "rover_replay_flags";
  std::string text;
  EXPECT_EQ(run(tool + " --scenario " + scenario + " --out " + out + " --max_innovation abc", &text), 2);
  EXPECT_NE(text.find("max_innovation must be a number"), std::string::npos) << text;
  EXPECT_EQ(run(tool + " --scenario " + scenario + " --out " + out + " --function_tolerance 0.5", &text), 2);
  EXPECT_EQ(run(tool + " --scenario " + scenario + " --out " + out + " --config " + kSource +
                    "/config/nonexistent.yaml", &text), 2);
  EXPECT_NE(text.find("cannot read"), std::string::npos) << text;
  ASSERT_EQ(run(tool + " --help", &text), 0);
  for (const Parameter& p : verifierParameters()) EXPECT_NE(text.find("--" + p.name + " "), std::string::npos) << p.name;
  // --config then a flag: the flag wins; the run says which values it used.
  ASSERT_EQ(run(tool + " --scenario " + scenario + " --out " + out + " --config " + kSource +
                    "/config/rover_template.yaml --config " + kSource +
                    "/config/rover_outdoor.yaml --threshold 0.3 --robust_candidate --quiet --snapshots 0", &text), 0)
      << text;
  EXPECT_NE(text.find("threshold 0.30 m"), std::string::npos) << text;
  ASSERT_EQ(run(tool + " --scenario " + scenario + " --out " + out + " --config " + kSource +
                    "/config/rover_template.yaml --config " + kSource +
                    "/config/rover_outdoor.yaml --threshold 0.3 --robust_candidate", &text), 0) << text;
  EXPECT_NE(text.find(" threshold=0.3 "), std::string::npos) << text;
  EXPECT_NE(text.find("max_innovation=1 max_innovation_per_metre=0.03 "), std::string::npos) << text;
  EXPECT_NE(text.find("robust_candidate=true"), std::string::npos) << text;
}
