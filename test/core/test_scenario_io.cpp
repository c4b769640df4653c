#include "rover_loop_fusion/sim/scenario_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>

using namespace rover_loop_fusion::sim;

TEST(ScenarioIo, ParsesKeyframesAndCandidates) {
  std::vector<ScenarioKeyframe> k;
  std::string err;
  ASSERT_TRUE(parseKeyframes("# a comment\nindex,stamp,sequence,x,y,z,qx,qy,qz,qw\n"
                             "0,1.5,1,0,0,0,0,0,0,1\n\n1,2.5,1,1.0,-2,3e-1,0,0,0.7071068,0.7071068\n",
                             "k", &k, &err))
      << err;
  ASSERT_EQ(k.size(), 2u);
  EXPECT_EQ(k[1].index, 1);
  EXPECT_DOUBLE_EQ(k[1].stamp, 2.5);
  EXPECT_DOUBLE_EQ(k[1].vio.t.z(), 0.3);
  EXPECT_NEAR(k[1].vio.q.w(), 0.7071068, 1e-12);
  std::vector<ScenarioCandidate> c;
  ASSERT_TRUE(parseCandidates("query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label\n"
                              "120,4,0.1,0,0,0,0,0,1,0.02,31,1\n121,9,nan,0,0,0,0,0,1,0,-1,0\n",
                              "c", &c, &err))
      << err;
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].candidate.query_index, 120);
  EXPECT_EQ(c[0].candidate.inliers, 31);
  EXPECT_EQ(c[0].label, 1);
  EXPECT_TRUE(std::isnan(c[1].candidate.relative_t.x()));  // parsed, judged by the verifier
}

TEST(ScenarioIo, ReadsAByteOrderMarkAndDenormalValues) {
  // Red team: rover_replay refused 1e-320 (strtod's ERANGE on underflow) and a file saved with
  // a UTF-8 byte order mark (the header did not match).
  std::vector<ScenarioKeyframe> k;
  std::string err;
  ASSERT_TRUE(parseKeyframes("\xEF\xBB\xBFindex,stamp,sequence,x,y,z,qx,qy,qz,qw\n0,1.5,1,1e-320,0,0,0,0,0,1\n", "k",
                             &k, &err))
      << err;
  ASSERT_EQ(k.size(), 1u);
  EXPECT_GT(k[0].vio.t.x(), 0.0);
  EXPECT_LT(k[0].vio.t.x(), 1e-300);
  std::vector<ScenarioCandidate> c;
  ASSERT_TRUE(parseCandidates("\xEF\xBB\xBFquery_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label\n"
                              "120,4,1e-320,0,0,0,0,0,1,4.9e-324,31,1\n",
                              "c", &c, &err))
      << err;
  EXPECT_EQ(c.size(), 1u);
  // Beyond the range of double is still an error, saying where.
  EXPECT_FALSE(parseKeyframes("index,stamp,sequence,x,y,z,qx,qy,qz,qw\n0,1.5,1,1e999,0,0,0,0,0,1\n", "k", &k, &err));
  EXPECT_NE(err.find("k:2"), std::string::npos) << err;
  // A byte order mark anywhere but at the start is not skipped.
  EXPECT_FALSE(parseKeyframes("# c\n\xEF\xBB\xBFindex,stamp,sequence,x,y,z,qx,qy,qz,qw\n", "k", &k, &err));
}

TEST(ScenarioIo, MalformedInputSaysWhereAndWhat) {
  std::vector<ScenarioKeyframe> k;
  std::string err;
  EXPECT_FALSE(parseKeyframes("", "keyframes.csv", &k, &err));
  EXPECT_NE(err.find("empty"), std::string::npos) << err;
  EXPECT_FALSE(parseKeyframes("index,stamp\n", "keyframes.csv", &k, &err));
  EXPECT_NE(err.find("keyframes.csv:1"), std::string::npos) << err;
  EXPECT_FALSE(parseKeyframes("index,stamp,sequence,x,y,z,qx,qy,qz,qw\n0,1,1,0,0,0,0,0,0\n", "k", &k, &err));
  EXPECT_NE(err.find("k:2: expected 10 fields, got 9"), std::string::npos) << err;
  EXPECT_FALSE(parseKeyframes("index,stamp,sequence,x,y,z,qx,qy,qz,qw\n0,1,1,0,0,zero,0,0,0,1\n", "k", &k, &err));
  EXPECT_NE(err.find("'zero' is not a number"), std::string::npos) << err;
  EXPECT_FALSE(parseKeyframes("index,stamp,sequence,x,y,z,qx,qy,qz,qw\n1.5,1,1,0,0,0,0,0,0,1\n", "k", &k, &err));
  EXPECT_NE(err.find("not an integer"), std::string::npos) << err;
  std::vector<ScenarioCandidate> c;
  EXPECT_FALSE(parseCandidates("query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label\n"
                               "1,0,0,0,0,0,0,0,1,0,10,7\n", "c", &c, &err));
  EXPECT_NE(err.find("label"), std::string::npos) << err;
  Scenario s;
  EXPECT_FALSE(loadScenario("/nonexistent/dir", &s, &err));
  EXPECT_NE(err.find("cannot read"), std::string::npos) << err;
}

TEST(ScenarioIo, RefusesInliersOutOfRangeAndBadGroundTruthSayingWhere) {
  // Inliers 99999999999 silently became -1; ground truth with NaN or a second
  // pose for a keyframe was accepted (evaluate.py then failed: "SVD did not converge").
  const std::string header = "query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label\n";
  std::vector<ScenarioCandidate> c;
  std::string err;
  EXPECT_FALSE(parseCandidates(header + "120,4,0.1,0,0,0,0,0,1,0.02,99999999999,1\n", "c", &c, &err));
  EXPECT_EQ(err, "c:2: inliers 99999999999 out of range (-1: unknown, or 0 to 2147483647)");
  EXPECT_FALSE(parseCandidates(header + "120,4,0.1,0,0,0,0,0,1,0.02,-2,1\n", "c", &c, &err));
  EXPECT_NE(err.find("c:2: inliers -2 out of range"), std::string::npos) << err;
  ASSERT_TRUE(parseCandidates(header + "120,4,0.1,0,0,0,0,0,1,0.02,2147483647,1\n1,0,0,0,0,0,0,0,1,0,-1,0\n", "c",
                              &c, &err))
      << err;
  EXPECT_EQ(c[0].candidate.inliers, 2147483647);
  EXPECT_EQ(c[1].candidate.inliers, -1);

  std::vector<int64_t> index;
  std::vector<rover_loop_fusion::core::Pose> gt;
  const std::string gt_header = "index,x,y,z,qx,qy,qz,qw\n";
  EXPECT_FALSE(parseGroundTruth(gt_header + "0,0,0,0,0,0,0,1\n1,nan,0,0,0,0,0,1\n", "g", &index, &gt, &err));
  EXPECT_EQ(err, "g:3: field 2 'nan' is not finite");
  EXPECT_FALSE(parseGroundTruth(gt_header + "0,0,0,0,0,0,0,1\n1,1,0,0,0,0,inf,1\n", "g", &index, &gt, &err));
  EXPECT_EQ(err, "g:3: field 7 'inf' is not finite");
  EXPECT_FALSE(parseGroundTruth(gt_header + "0,0,0,0,0,0,0,1\n1,1,0,0,0,0,0,1\n1,1,0,0,0,0,0,1\n", "g", &index, &gt,
                                &err));
  EXPECT_EQ(err, "g:4: keyframe 1 has a ground-truth pose already (data row 2)");
  EXPECT_TRUE(parseGroundTruth(gt_header + "0,0,0,0,0,0,0,1\n1,1,0,0,0,0,0,1\n", "g", &index, &gt, &err)) << err;
  EXPECT_EQ(index.size(), 2u);
}

TEST(ScenarioIo, AVeryLongLineIsRefusedAsSuch) {
  // A single 60 MB line cost rover_replay 417 MB before the error (whole files
  // and lines copied); lines are now read one at a time and at most 64 kB of one is held. Here
  // (1 MB) from text and from a scenario directory on disk.
  const std::string header = "query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label\n";
  const std::string long_line(1 << 20, '1');
  std::vector<ScenarioCandidate> c;
  std::string err;
  EXPECT_FALSE(parseCandidates(header + long_line + "\n", "c", &c, &err));
  EXPECT_EQ(err, "c:2: a line longer than 65536 bytes (not a row of c)");
  const std::string dir = ::testing::TempDir() + "rover_long_line_scenario";
  ASSERT_EQ(std::system(("rm -rf " + dir + " && mkdir -p " + dir).c_str()), 0);
  {
    std::ofstream k(dir + "/keyframes.csv");
    k << "index,stamp,sequence,x,y,z,qx,qy,qz,qw\n0,1,1,0,0,0,0,0,0,1\n";
    std::ofstream f(dir + "/candidates.csv");
    f << header << long_line << "\n";
  }
  Scenario s;
  EXPECT_FALSE(loadScenario(dir, &s, &err));
  EXPECT_EQ(err, "candidates.csv:2: a line longer than 65536 bytes (not a row of candidates.csv)");
  // A line just within the limit is read (and refused for what it holds).
  EXPECT_FALSE(parseCandidates(header + std::string(65536, '1') + "\n", "c", &c, &err));
  EXPECT_NE(err.find("expected 12 fields"), std::string::npos) << err;
  std::system(("rm -rf " + dir).c_str());
}
