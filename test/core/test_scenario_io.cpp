#include "rover_loop_fusion/sim/scenario_io.h"

#include <gtest/gtest.h>

#include <cmath>

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
