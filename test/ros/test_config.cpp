// The shipped verifier YAMLs document every parameter: each name of verifierParameterNames()
// is a key of config/rover_template.yaml with a comment right above it, or named in a comment
// line "# name: value" of it (no effect at the defaults: test/python/test_shipped_keys.py), and
// nothing else is; except the ones the host sets (hostDerivedVerifierParameters), which must not
// be there (the plugin ignores them with an ERROR). The overrides (rover_indoor.yaml,
// rover_outdoor.yaml, rover_paper.yaml) set template keys only, each commented. (That the files load cleanly through the parameter server
// is checked in test_adapter.cpp, under rostest.)
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/ros/verifier_host.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

using namespace rover_loop_fusion;

namespace {

struct YamlKey {
  std::string value;
  bool named = false;      ///< only in a comment line "# key: value"
  bool commented = false;  ///< a comment line right above, or a comment after the value
  int count = 0;
};

/// Top-level `key: value` lines of a flat YAML file.
std::map<std::string, YamlKey> readKeys(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::map<std::string, YamlKey> keys;
  const std::regex key_line("^([A-Za-z_][A-Za-z0-9_]*):[ \t]*([^#]*?)[ \t]*(#.*)?$");
  const std::regex named_line("^# ([a-z_0-9]+): ([^ \t#]+)([ \t]+#.*)?$");
  std::string line, previous;
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_match(line, m, named_line) && !keys.count(m[1])) {
      YamlKey& k = keys[m[1]];
      k.value = m[2];
      k.named = true;
    } else if (std::regex_match(line, m, key_line)) {
      YamlKey& k = keys[m[1]];
      k.value = m[2];
      k.commented = m[3].matched || previous.compare(0, 1, "#") == 0;
      ++k.count;
    }
    previous = line;
  }
  return keys;
}

/// The key lines of `keys` (not the ones only named in comments).
std::map<std::string, YamlKey> setKeys(const std::map<std::string, YamlKey>& keys) {
  std::map<std::string, YamlKey> set;
  for (const auto& k : keys)
    if (!k.second.named) set.insert(k);
  return set;
}

const std::string kConfigDir = std::string(ROVER_SOURCE_DIR) + "/config/";

void checkTemplate() {
  const std::map<std::string, YamlKey> keys = readKeys(kConfigDir + "rover_template.yaml");
  const std::vector<std::string>& derived = hostDerivedVerifierParameters();
  for (const std::string& name : verifierParameterNames()) {
    auto it = keys.find(name);
    if (std::find(derived.begin(), derived.end(), name) != derived.end()) {
      EXPECT_EQ(it, keys.end()) << "the template sets " << name << ", which the host sets";
      continue;
    }
    ASSERT_NE(it, keys.end()) << "the template neither sets nor names " << name;
    if (it->second.named) continue;
    EXPECT_EQ(it->second.count, 1) << "the template sets " << name << " more than once";
    EXPECT_TRUE(it->second.commented) << "the template: " << name << " has no comment";
  }
  for (const auto& k : keys)
    EXPECT_NE(std::find(verifierParameterNames().begin(), verifierParameterNames().end(), k.first),
              verifierParameterNames().end())
        << "the template names " << k.first << ", which is not a verifier parameter";
  ASSERT_TRUE(keys.count("threshold"));
  EXPECT_EQ(keys.at("threshold").value, "0.2");
}

void checkOverride(const std::string& file, const std::string& threshold) {
  const std::map<std::string, YamlKey> base = setKeys(readKeys(kConfigDir + "rover_template.yaml"));
  const std::map<std::string, YamlKey> keys = setKeys(readKeys(kConfigDir + file));
  for (const auto& k : keys) {
    EXPECT_TRUE(base.count(k.first)) << file << " sets " << k.first << ", which the template does not";
    EXPECT_EQ(k.second.count, 1) << file << " sets " << k.first << " more than once";
    EXPECT_TRUE(k.second.commented) << file << ": " << k.first << " has no comment";
  }
  if (threshold.empty()) {
    EXPECT_FALSE(keys.count("threshold")) << file;
  } else {
    ASSERT_TRUE(keys.count("threshold")) << file;
    EXPECT_EQ(keys.at("threshold").value, threshold) << file;
  }
}

}  // namespace

TEST(ConfigFiles, TemplateDocumentsEveryParameter) { checkTemplate(); }

TEST(ConfigFiles, IndoorYamlOverridesNothing) { checkOverride("rover_indoor.yaml", ""); }

TEST(ConfigFiles, OutdoorYamlOverridesTemplateKeys) { checkOverride("rover_outdoor.yaml", "1.0"); }

TEST(ConfigFiles, PaperYamlOverridesTemplateKeys) { checkOverride("rover_paper.yaml", "0.5"); }

TEST(ConfigFiles, ReaderSeesUndocumentedKeys) {
  // The check above must be able to fail: a key without a comment is reported as such.
  const std::string path = ::testing::TempDir() + "rover_undocumented.yaml";
  {
    std::ofstream out(path);
    out << "# documented\nthreshold: 0.5\n\nmode: auto\nalignment: se3  # trailing comment\n"
           "# drift_z: 0.025  # named\n# decision: chi2 (prose, not a named key)\n";
  }
  const std::map<std::string, YamlKey> keys = readKeys(path);
  ASSERT_EQ(keys.size(), 4u);
  EXPECT_TRUE(keys.at("drift_z").named);
  EXPECT_FALSE(keys.at("threshold").named);
  EXPECT_TRUE(keys.at("threshold").commented);
  EXPECT_FALSE(keys.at("mode").commented);
  EXPECT_TRUE(keys.at("alignment").commented);
  EXPECT_EQ(keys.at("alignment").value, "se3");
  std::remove(path.c_str());
}
