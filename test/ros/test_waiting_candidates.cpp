// The index of waiting candidates in rover_verifier_node (waiting_candidates.h): a keyframe
// wakes only the candidates it may resolve, in arrival order; the timeout takes the oldest;
// and the work per message does not grow with the number of candidates waiting (counted as
// index entries examined, not timed).
#include "rover_loop_fusion/ros/waiting_candidates.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

using rover_loop_fusion::WaitingCandidates;
typedef WaitingCandidates<std::string> Waiting;

TEST(WaitingCandidates, AKeyframeWakesOnlyWhatItMayResolveInArrivalOrder) {
  Waiting w;
  const uint64_t a = w.add("a", 0.0, {{true, 300}});
  const uint64_t b = w.add("b", 0.1, {{true, 100}});
  const uint64_t c = w.add("c", 0.2, {{false, 7}});
  const uint64_t d = w.add("d", 0.3, {{true, 500}, {true, 200}});  // query and match both waiting
  EXPECT_TRUE(w.wake(99, 6).empty());
  EXPECT_EQ(w.wake(250, 6), (std::vector<uint64_t>{b, d}));  // b's stamp, d's match
  w.rewait(d, {{true, 500}});  // d: the match arrived, the query still waits
  w.take(b);
  EXPECT_EQ(w.wake(300, 7), (std::vector<uint64_t>{a, c}));
  EXPECT_EQ(w.get(a), "a");
  w.take(a);
  w.take(c);
  EXPECT_EQ(w.size(), 1u);
  EXPECT_EQ(w.wake(1000, 1000), (std::vector<uint64_t>{d}));
}

TEST(WaitingCandidates, TheTimeoutTakesTheOldestFirst) {
  Waiting w;
  w.add("old", 1.0, {{true, 10}});
  w.add("new", 2.0, {{true, 5}});
  uint64_t id;
  EXPECT_FALSE(w.oldestBefore(1.0, &id));
  ASSERT_TRUE(w.oldestBefore(1.5, &id));
  EXPECT_EQ(w.take(id), "old");
  ASSERT_TRUE(w.oldestBefore(2.5, &id));
  EXPECT_EQ(w.take(id), "new");
  EXPECT_TRUE(w.empty());
  EXPECT_TRUE(w.wake(100, 100).empty()) << "taken candidates leave the index";
}

TEST(WaitingCandidates, WorkPerMessageDoesNotGrowWithTheCandidatesWaiting) {
  // 20000 candidates wait for keyframes that never come (the red team's case); 20000 keyframes
  // and candidates arrive meanwhile. Scanning every waiting candidate per message would examine
  // ~4e8 entries; the index examines only what a keyframe wakes.
  Waiting w;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    w.add("never", i * 1e-4, {{true, 1000000000 + i}});
    EXPECT_TRUE(w.wake(i, i).empty());
  }
  EXPECT_EQ(w.examined(), 0u);
  // One keyframe at stamp 2000 resolves the 10 candidates waiting up to there, and no more.
  Waiting v;
  for (int i = 0; i < n; ++i) v.add("c", 0.0, {{true, 100 * i}});
  EXPECT_EQ(v.wake(900, 0).size(), 10u);
  EXPECT_EQ(v.examined(), 10u);
}
