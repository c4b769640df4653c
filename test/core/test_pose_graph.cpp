// core::KeyframeGraph on its own: loop_fusion's stand-in graph (rover_verifier_node's ~pose_graph_path,
// rover_replay's accept-all baseline) collects loops without solving and solves once, like
// loop_fusion, to the same result as a verifier that committed the same loops.
#include "rover_loop_fusion/core/place_graph.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>
#include <random>
#include <utility>
#include <vector>

using namespace rover_loop_fusion;

namespace {

sim::Scene corridor() {
  sim::LapsOptions o;
  o.laps = 2;
  o.sigma_yaw = 0.004;
  return sim::makeLapsScene(o);
}

}  // namespace

TEST(KeyframeGraph, StandInCollectsLoopsAndSolvesLikeLoopFusionOnce) {
  const sim::Scene s = corridor();
  core::KeyframeGraph graph;
  core::Verifier verifier;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    ASSERT_TRUE(graph.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
    ASSERT_TRUE(verifier.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  }
  size_t loops = 0;
  for (const sim::SimCandidate& c : s.candidates) {
    if (!c.is_true) continue;
    ASSERT_TRUE(graph.addLoop(c.candidate).ok);
    ASSERT_TRUE(verifier.commit(c.candidate).ok);
    ++loops;
  }
  ASSERT_GT(loops, 5u);
  EXPECT_EQ(graph.loopCount(), loops);
  EXPECT_EQ(graph.solveCount(), 0u) << "addLoop does not solve";
  // The estimate X stays the VIO trajectory; loop_fusion's batch solve uses the loops.
  const std::vector<core::TrajectoryPoint> t = graph.trajectory();
  EXPECT_EQ((t.back().estimate.t - t.back().vio.t).norm(), 0.0);
  const core::BatchSolveResult a = graph.solveLikeLoopFusion(5), b = verifier.solveLikeLoopFusion(5);
  ASSERT_TRUE(a.ok) << a.message;
  EXPECT_EQ(graph.solveCount(), 1u);
  ASSERT_EQ(a.poses.size(), b.poses.size());
  for (size_t i = 0; i < a.poses.size(); ++i) EXPECT_EQ(a.poses[i].t, b.poses[i].t) << i;
  std::vector<core::Pose> truth;
  for (const sim::SimKeyframe& kf : s.keyframes) truth.push_back(kf.truth);
  std::vector<core::Pose> vio;
  for (const core::TrajectoryPoint& p : t) vio.push_back(p.vio);
  EXPECT_LT(sim::ate(a.poses, truth), 0.7 * sim::ate(vio, truth));
}

TEST(KeyframeGraph, AddLoopRefusesWhatCannotBeAnEdge) {
  const sim::Scene s = corridor();
  core::KeyframeGraph graph;
  for (const sim::SimKeyframe& kf : s.keyframes) ASSERT_TRUE(graph.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q).ok);
  core::LoopCandidate c = s.candidates.front().candidate;
  ASSERT_TRUE(graph.addLoop(c).ok);
  const core::Status twice = graph.addLoop(c);
  EXPECT_FALSE(twice.ok);
  EXPECT_NE(twice.message.find("already in the graph"), std::string::npos) << twice.message;
  c.match_index = 100000;
  EXPECT_NE(graph.addLoop(c).message.find("unknown match keyframe"), std::string::npos);
  c = s.candidates.front().candidate;
  c.relative_t.x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(graph.addLoop(c).message.find("not finite"), std::string::npos);
  EXPECT_EQ(graph.loopCount(), 1u);
  EXPECT_EQ(graph.revision(), 1u);
}

// The path length (the gate's and the threshold's "metres of odometry between match and
// query") is the shortest path along the sequences' odometry with every loop as a shortcut of
// length 0: checked against a plain Dijkstra over every keyframe, on two sequences, as loops
// come and go.
TEST(KeyframeGraph, PathLengthIsTheShortestOdometryPathThroughTheLoops) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> step(0.05, 0.5), unit(-1.0, 1.0);
  core::KeyframeGraph graph;
  const int n1 = 300, n = 500;  // keyframes 0..299: sequence 1; 300..499: sequence 2
  std::vector<double> arc(n, 0.0);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    if (i == n1) t = Eigen::Vector3d(50, 0, 0);
    const Eigen::Vector3d d(unit(rng), unit(rng), 0.1 * unit(rng));
    const double len = step(rng);
    if (i != 0 && i != n1) {
      t += len * d.normalized();
      arc[i] = arc[i - 1] + len;
    }
    ASSERT_TRUE(graph.addKeyframe(i, 0.1 * i, i < n1 ? 1 : 2, t, Eigen::Quaterniond::Identity()).ok) << i;
  }
  // A plain Dijkstra over all keyframes: odometry between neighbours of one sequence, loops 0.
  std::vector<std::pair<int, int>> loops;
  auto reference = [&](int from, int to) {
    std::vector<std::vector<std::pair<int, double>>> adj(n);
    for (int i = 1; i < n; ++i)
      if (i != n1) {
        adj[i - 1].push_back({i, arc[i] - arc[i - 1]});
        adj[i].push_back({i - 1, arc[i] - arc[i - 1]});
      }
    for (const auto& l : loops) {
      adj[l.first].push_back({l.second, 0.0});
      adj[l.second].push_back({l.first, 0.0});
    }
    std::vector<double> dist(n, std::numeric_limits<double>::infinity());
    std::priority_queue<std::pair<double, int>, std::vector<std::pair<double, int>>, std::greater<std::pair<double, int>>> q;
    dist[from] = 0;
    q.push({0.0, from});
    while (!q.empty()) {
      const auto top = q.top();
      q.pop();
      if (top.first > dist[top.second]) continue;
      for (const auto& nb : adj[top.second])
        if (top.first + nb.second < dist[nb.first]) {
          dist[nb.first] = top.first + nb.second;
          q.push({dist[nb.first], nb.first});
        }
    }
    return dist[to];
  };
  std::uniform_int_distribution<int> any(0, n - 1);
  auto check = [&](const char* when) {
    int finite = 0, infinite = 0;
    for (int k = 0; k < 300; ++k) {
      const int a = any(rng), b = any(rng);
      const double want = reference(a, b), got = graph.pathLength(a, b);
      if (std::isinf(want)) {
        EXPECT_TRUE(std::isinf(got)) << when << ": " << a << " -> " << b << " has no path, got " << got;
        ++infinite;
      } else {
        EXPECT_NEAR(got, want, 1e-9) << when << ": " << a << " -> " << b;
        EXPECT_NEAR(graph.pathLength(b, a), got, 1e-9) << when << ": " << b << " -> " << a;
        ++finite;
      }
    }
    return std::make_pair(finite, infinite);
  };
  EXPECT_EQ(check("no loops").second > 0, true) << "the two sequences are apart until a loop joins them";
  core::LoopCandidate c;
  c.relative_q = Eigen::Quaterniond::Identity();
  c.relative_yaw = 0.0;
  c.relative_t = Eigen::Vector3d(0.1, 0, 0);
  // Loops come (ends shared: a few keyframes end several loops), are checked on the way, go,
  // and come again after the removal (on top of a rebuilt index).
  auto addLoops = [&](size_t until, int ends) {
    std::uniform_int_distribution<int> end(0, ends - 1);
    while (loops.size() < until) {
      int a = 5 * end(rng), b = 5 * end(rng);
      if (a == b) continue;
      if (a > b) std::swap(a, b);
      c.query_index = b;
      c.match_index = a;
      if (!graph.addLoop(c).ok) continue;  // the same loop twice
      loops.push_back({a, b});
      if (loops.size() == until / 2) check("half of the loops");
    }
  };
  addLoops(60, n / 5);
  const auto joined = check("60 loops");
  EXPECT_EQ(joined.second, 0) << "the loops join the sequences";
  EXPECT_GT(joined.first, 0);
  for (int k = 0; k < 20; ++k) {
    const auto l = loops[static_cast<size_t>(k) * 2];
    ASSERT_TRUE(graph.removeLoop(l.second, l.first).ok);
  }
  for (int k = 19; k >= 0; --k) loops.erase(loops.begin() + 2 * k);
  check("40 loops after 20 removed");
  addLoops(70, n / 5);
  check("30 more loops after the removal");
  EXPECT_EQ(graph.pathLength(42, 42), 0.0);
}

// A circuit of 10 loop ends driven 50 times, each lap tied to the one before by loops: 10
// places, not 500, and the walks between them are the shortest stretches of any lap.
TEST(PlaceGraph, ACircuitDrivenManyTimesIsItsPlaces) {
  core::PlaceGraph places;
  const size_t per_lap = 10, laps = 50;
  auto length = [](size_t lap, size_t k) { return 1.0 + 0.01 * static_cast<double>((lap * 7 + k) % 13); };
  for (size_t lap = 0; lap < laps; ++lap)
    for (size_t k = 0; k < per_lap; ++k) {
      const size_t end = lap * per_lap + k;
      if (end > 0) places.addStretch(end - 1, end, length(lap, k));
      if (lap > 0) places.join(end - per_lap, end);
    }
  EXPECT_EQ(places.places(), per_lap);
  // From place 0 to place 3 forwards (the shortest of each stretch), or back round the circuit.
  std::vector<double> shortest(per_lap + 1, std::numeric_limits<double>::infinity());
  for (size_t lap = 0; lap < laps; ++lap)
    for (size_t k = 0; k < per_lap; ++k)
      if (lap * per_lap + k > 0) shortest[k] = std::min(shortest[k], length(lap, k));
  const double forwards = shortest[1] + shortest[2] + shortest[3];
  double backwards = shortest[0];
  for (size_t k = 4; k < per_lap; ++k) backwards += shortest[k];
  EXPECT_NEAR(places.shortest({{0, 0.0}}, {{3, 0.0}}, 1e9), std::min(forwards, backwards), 1e-12);
  // Ends of the last lap stand for their places; offsets add; the bound stops the search.
  EXPECT_NEAR(places.shortest({{490, 0.5}}, {{493, 0.25}}, 1e9), std::min(forwards, backwards) + 0.75, 1e-12);
  EXPECT_EQ(places.shortest({{0, 0.0}}, {{3, 0.0}}, 1.0), 1.0);
  EXPECT_EQ(places.shortest({{0, 0.0}}, {{12345, 0.0}}, 7.0), 7.0) << "an unknown end is no target";
}

// Moments kept from the start, from midway, or built on first use are the same moments: the
// same covariances along the chains and through the loops, on two sequences.
TEST(KeyframeGraph, KeptMomentsAreTheMomentsBuiltOnFirstUse) {
  core::VerifierConfig config;
  core::KeyframeGraph lazy(config), early(config), midway(config);
  early.keepMoments(true, true);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  const int n = 400;
  for (int i = 0; i < n; ++i) {
    if (i == 250) t = Eigen::Vector3d(30, 0, 0);
    t += Eigen::Vector3d(0.3 + 0.1 * unit(rng), 0.2 * unit(rng), 0.02 * unit(rng));
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3 * unit(rng), Eigen::Vector3d::UnitZ()));
    for (core::KeyframeGraph* g : {&lazy, &early, &midway})
      ASSERT_TRUE(g->addKeyframe(i, 0.1 * i, i < 250 ? 1 : 2, t, q).ok) << i;
    if (i == 120) midway.keepMoments(true, false);
  }
  core::LoopCandidate c;
  c.relative_q = Eigen::Quaterniond::Identity();
  c.relative_t = Eigen::Vector3d(0.1, 0, 0);
  for (int k = 0; k < 6; ++k) {
    c.query_index = 260 + 20 * k;
    c.match_index = 10 + 35 * k;
    for (core::KeyframeGraph* g : {&lazy, &early, &midway}) ASSERT_TRUE(g->addLoop(c).ok);
  }
  for (size_t from : {0u, 37u, 180u, 251u}) {
    const size_t to = from + 60;
    Eigen::Matrix4d a, b, m;
    ASSERT_TRUE(lazy.chainCovariance(from, to, 1.0, &a));
    ASSERT_TRUE(early.chainCovariance(from, to, 1.0, &b));
    ASSERT_TRUE(midway.chainCovariance(from, to, 1.0, &m));
    EXPECT_GT(a.trace(), 0.0);
    EXPECT_EQ(a, b) << from;
    EXPECT_EQ(a, m) << from;
    ASSERT_TRUE(lazy.relativeCovariance(from, 399 - from / 2, 1.0, &a));
    ASSERT_TRUE(early.relativeCovariance(from, 399 - from / 2, 1.0, &b));
    ASSERT_TRUE(midway.relativeCovariance(from, 399 - from / 2, 1.0, &m));
    EXPECT_EQ(a, b) << from;
    EXPECT_EQ(a, m) << from;
  }
}

TEST(KeyframeGraph, CondensedGraphsFromKeptChainEdgesEqualThoseBuiltAfresh) {
  // condense() keeps each chain edge it builds for the next condensed graphs. Two graphs of the
  // same keyframes and loops: `warm` asked for condensed graphs (both kinds: the drift model's
  // at two variance scales and the trials' unit weighting) before and between the loops, `cold`
  // only at the end. Every covariance and trial must be the same to the bit, also after the
  // first loop into sequence 2 has moved that sequence's VIO poses (anchoring it).
  core::VerifierConfig config;
  config.trial.condense_min_window = 50;
  core::KeyframeGraph warm(config), cold(config);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  double yaw = 0.0;
  const int n = 400;
  for (int i = 0; i < n; ++i) {
    if (i == 250) t = Eigen::Vector3d(30, 5, 0);
    yaw += 0.05 * unit(rng);
    t += Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::Vector3d(0.3, 0.05 * unit(rng), 0.01 * unit(rng));
    const Eigen::Quaterniond q(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()));
    for (core::KeyframeGraph* g : {&warm, &cold}) ASSERT_TRUE(g->addKeyframe(i, 0.1 * i, i < 250 ? 1 : 2, t, q).ok) << i;
  }
  core::LoopCandidate c;
  c.relative_q = Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ()));
  c.relative_yaw = 0.2;
  c.relative_t = Eigen::Vector3d(0.4, -0.3, 0.05);
  auto ask = [&](core::KeyframeGraph& g, std::vector<Eigen::Matrix4d>* out) {
    // (385, 395): two anchors of sequence 2 next to each other before and after the loops.
    for (const auto& pair : {std::make_pair(5, 397), std::make_pair(60, 379), std::make_pair(150, 349),
                             std::make_pair(255, 314), std::make_pair(385, 395)}) {
      for (double scale : {1.0, 2.5}) {
        Eigen::Matrix4d C;
        if (g.relativeCovariance(pair.first, pair.second, scale, &C)) out->push_back(C);
      }
    }
  };
  auto trial = [&](core::KeyframeGraph& g, size_t match, size_t query) {
    core::LoopCandidate cand = c;
    cand.match_index = static_cast<int64_t>(match);
    cand.query_index = static_cast<int64_t>(query);
    return g.solveWindow(match, query, &cand, false, 50, 0.0);
  };
  std::vector<Eigen::Matrix4d> unused;
  ask(warm, &unused);
  trial(warm, 20, 240);
  for (int k = 0; k < 6; ++k) {
    c.query_index = 230 + 30 * k;  // k >= 1: into sequence 2 (the first one anchors it)
    c.match_index = 10 + 35 * k;
    for (core::KeyframeGraph* g : {&warm, &cold}) ASSERT_TRUE(g->addLoop(c).ok) << k;
    ask(warm, &unused);
    trial(warm, 40 + 10 * k, 395);
  }
  std::vector<Eigen::Matrix4d> a, b;
  ask(warm, &a);
  ask(cold, &b);
  ASSERT_EQ(a.size(), 10u);
  ASSERT_EQ(b.size(), a.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_GT(a[i].trace(), 0.0);
    EXPECT_EQ(a[i], b[i]) << i;
  }
  for (size_t match : {40u, 95u, 180u}) {
    const core::TrialSolution sw = trial(warm, match, 395), sc = trial(cold, match, 395);
    ASSERT_TRUE(sw.summary.finite && sc.summary.finite) << match;
    ASSERT_TRUE(sw.condensed) << "a window of " << 395 - match << " keyframes is condensed";
    ASSERT_EQ(sw.positions, sc.positions);
    for (size_t i = 0; i < sw.states.size(); ++i) {
      for (int k = 0; k < 3; ++k) EXPECT_EQ(sw.states[i].t[k], sc.states[i].t[k]) << match << " anchor " << i;
      EXPECT_EQ(sw.states[i].yaw, sc.states[i].yaw) << match << " anchor " << i;
    }
  }
}
