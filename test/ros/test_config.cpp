// The shipped verifier YAMLs document every parameter: each name of verifierParameterNames()
// is a key of config/rover_indoor.yaml and config/rover_outdoor.yaml with a comment right
// above it, and nothing else is; except the ones the host sets (hostDerivedVerifierParameters),
// which must not be there (the plugin ignores them with an ERROR). (That the files load cleanly through the parameter server
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
  bool commented = false;  ///< a comment line right above, or a comment after the value
  int count = 0;
};

/// Top-level `key: value` lines of a flat YAML file.
std::map<std::string, YamlKey> readKeys(const std::string& path) {
  std::ifstream in(path);
  EXPECT_TRUE(in.good()) << path;
  std::map<std::string, YamlKey> keys;
  const std::regex key_line("^([A-Za-z_][A-Za-z0-9_]*):[ \t]*([^#]*?)[ \t]*(#.*)?$");
  std::string line, previous;
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_match(line, m, key_line)) {
      YamlKey& k = keys[m[1]];
      k.value = m[2];
      k.commented = m[3].matched || previous.compare(0, 1, "#") == 0;
      ++k.count;
    }
    previous = line;
  }
  return keys;
}

void checkDocumented(const std::string& file, const std::string& threshold) {
  const std::string path = std::string(ROVER_SOURCE_DIR) + "/config/" + file;
  const std::map<std::string, YamlKey> keys = readKeys(path);
  const std::vector<std::string>& derived = hostDerivedVerifierParameters();
  for (const std::string& name : verifierParameterNames()) {
    auto it = keys.find(name);
    if (std::find(derived.begin(), derived.end(), name) != derived.end()) {
      EXPECT_EQ(it, keys.end()) << file << " sets " << name << ", which the host sets";
      continue;
    }
    ASSERT_NE(it, keys.end()) << file << " does not set " << name;
    EXPECT_EQ(it->second.count, 1) << file << " sets " << name << " more than once";
    EXPECT_TRUE(it->second.commented) << file << ": " << name << " has no comment";
  }
  for (const auto& k : keys)
    EXPECT_NE(std::find(verifierParameterNames().begin(), verifierParameterNames().end(), k.first),
              verifierParameterNames().end())
        << file << " sets " << k.first << ", which is not a verifier parameter";
  ASSERT_TRUE(keys.count("threshold"));
  EXPECT_EQ(keys.at("threshold").value, threshold) << file;
}

}  // namespace

TEST(ConfigFiles, IndoorYamlDocumentsEveryParameter) { checkDocumented("rover_indoor.yaml", "0.2"); }

TEST(ConfigFiles, OutdoorYamlDocumentsEveryParameter) { checkDocumented("rover_outdoor.yaml", "1.0"); }

TEST(ConfigFiles, PaperYamlDocumentsEveryParameter) { checkDocumented("rover_paper.yaml", "0.5"); }

TEST(ConfigFiles, ReaderSeesUndocumentedKeys) {
  // The check above must be able to fail: a key without a comment is reported as such.
  const std::string path = ::testing::TempDir() + "rover_undocumented.yaml";
  {
    std::ofstream out(path);
    out << "# documented\nthreshold: 0.5\n\nmode: auto\nalignment: se3  # trailing comment\n";
  }
  const std::map<std::string, YamlKey> keys = readKeys(path);
  ASSERT_EQ(keys.size(), 3u);
  EXPECT_TRUE(keys.at("threshold").commented);
  EXPECT_FALSE(keys.at("mode").commented);
  EXPECT_TRUE(keys.at("alignment").commented);
  EXPECT_EQ(keys.at("alignment").value, "se3");
  std::remove(path.c_str());
}
