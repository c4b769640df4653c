// The one store of the candidates the verifier holds (deferred verdicts) until a later
// decision, whatever the reason they wait, by kind and revisit:
//   kNoPrior    between sequences nothing ties together yet (confirm_without_prior): released
//               once confirm_count of one stretch agree with each other;
//   kWeakPrior  passed the chi2 tests on a prior too weak to trust alone (hold_sigma): the same;
//   kRival      rejected for contradicting an accepted loop of its stretch (revoke_group): a
//               group that outnumbers those loops is decided against the graph without them;
//   kRevisit    decision revisit: not accepted alone, not ruled out by the drift model; a
//               hypothesis of revisit_support members that passes its joint test against the
//               prior (HoldTests::judge) and that no rival hypothesis of its stretch competes with
//               is released; one that fails its test or waits longer than revisit_window is
//               dropped. A member of a dropped hypothesis is tested alone first, on keyframe
//               arrival, against the loops committed since it was held; until then it waits
//               (wait(), nextWaiting()): for a commit, up to revisit_window keyframes after its
//               arrival, or for a keyframe with revisit_retest_budget_ms left.
//   kGlobal     decision revisit with global_check: rejected for contradicting the graph, or a
//               member of a dropped hypothesis, held in the global pass's pool until the pass
//               (core/global_release.cpp) releases it or global_window expires.
// This unit owns the bookkeeping: which held candidates form a group (same kind, same segments,
// queries within confirm_stretch (revisit: revisit_stretch), every pair of the last confirm_count consistent), which group
// is due (confirmed, expired, blocked by a rival group of its stretch) and in which order. It
// answers what is due, one item at a time (nextDue(), nextWaiting()), and takes it out of the
// store; what a release, a drop or a revocation does to the graph is the verifier's, which acts
// on each item before it asks for the next (an action may change the graph). The tests the store
// needs to tell what is due (HoldTests) are asked of the accepted loops (core/accepted_loops.h),
// never of the verifier.
#pragma once

#include "rover_loop_fusion/core/types.h"

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

enum class HoldKind { kNoPrior, kWeakPrior, kRival, kRevisit, kGlobal };

struct HeldCandidate {
  LoopCandidate candidate;
  size_t query_pos = 0, match_pos = 0;
  int query_segment = 0, match_segment = 0;
  size_t arrived = 0;  ///< keyframes in the graph when it was held
  HoldKind kind = HoldKind::kNoPrior;
  double d2 = 0.0;     ///< kRevisit: its innovation's Mahalanobis distance when it was held
  uint64_t revision = 0;  ///< the graph's revision (its loops) when it was held
};
using HeldGroup = std::vector<HeldCandidate>;

/// Keyframes between two positions in the graph.
inline size_t keyframeDistance(size_t x, size_t y) { return x > y ? x - y : y - x; }

/// What the store asks while it works out what is due (against the graph as it is now).
class HoldTests {
 public:
  virtual ~HoldTests() = default;
  /// The cycle test of two held candidates passes.
  virtual bool consistent(const HeldCandidate& a, const HeldCandidate& b) const = 0;
  /// The accepted loops a group of rivals contradicts.
  virtual std::vector<LoopCandidate> rivalTargets(const HeldGroup& group) const = 0;
  /// kRevisit: whether a hypothesis passes its joint test against the prior now (why (not) in
  /// *why).
  virtual bool judge(const HeldGroup& group, std::string* why) = 0;
  /// kRevisit: the median Mahalanobis distance of a hypothesis' members now.
  virtual double misfit(const HeldGroup& group) = 0;
};

class HeldCandidates {
 public:
  /// Reads confirm_count, confirm_window (expiry), confirm_stretch, revoke_group and revisit_*.
  explicit HeldCandidates(const VerifierConfig& config) : config_(config) {}

  /// Holds `h`: it joins the first group of its kind and segments whose last confirm_count
  /// members lie within confirm_stretch (revisit_stretch) keyframes of it and are consistent with it, or starts
  /// a group of its own.
  void add(const HeldCandidate& h, const HoldTests& tests);
  /// kRevisit: `h`, a member of a dropped hypothesis, waits (with why it was dropped) to be
  /// tested alone on a later keyframe (nextWaiting()).
  void wait(const HeldCandidate& h, const std::string& why);
  /// Held, waiting and pooled candidates.
  size_t size() const { return groupedCount() + waiting_.size() + pool_.size(); }
  /// No held group and no waiting member (the pool aside): nothing for nextDue() or nextWaiting().
  bool settled() const { return groups_.empty() && waiting_.empty(); }

  /// A group taken out of the store because it is due, and what the verifier does with it.
  struct Due {
    enum class Action {
      kRelease,       ///< confirmed: released, then `dropped` are dropped (contradicted) with dropped_why
      kSettleRivals,  ///< a confirmed group of rivals, against the accepted loops it contradicts (`targets`)
      kDrop,          ///< given up, with `why` (not contradicted: a revisit member may be tested alone)
    };
    Action action = Action::kDrop;
    HeldGroup group;
    std::string why;  ///< kDrop: why; kRelease of a revisit hypothesis: what its judge found
    std::vector<LoopCandidate> targets;
    std::vector<HeldGroup> dropped;
    std::string dropped_why;
  };
  /// Starts a pass over the groups due at `now` keyframes; the revisit hypotheses (kRevisit)
  /// only if `revisit`.
  void beginSettle(size_t now, bool revisit);
  /// The next group due in this pass (confirmed groups, rival groups too small to block a
  /// released one, expired groups), taken out of the store, in *due; false when none is. After
  /// an item that may change the graph the pass looks at every group again.
  bool nextDue(HoldTests& tests, Due* due);

  /// Starts a pass over the waiting members, oldest first and each once.
  void beginWaiting();
  /// The next waiting member due, taken out of the store, with why it is to be tested alone now:
  /// a loop was committed since it was held (`revision`, the graph's revision now, differs from
  /// its own), or revisit_window has passed since it arrived (why says so); false when none is.
  /// The others go on waiting; a member may be made to wait again (wait()) meanwhile.
  bool nextWaiting(size_t now, uint64_t revision, HeldCandidate* h, std::string* why);

  // kGlobal: the global pass's pool, oldest first.
  const std::vector<HeldCandidate>& pool() const { return pool_; }
  /// Changes with every change of the pool.
  uint64_t poolRevision() const { return pool_revision_; }
  /// Pools `h`; when `max_held` are pooled already, the oldest leaves first, into *evicted (true).
  bool addToPool(const HeldCandidate& h, size_t max_held, HeldCandidate* evicted);
  /// After a pass: the pool keeps `waiting` (oldest first).
  void keepInPool(std::vector<HeldCandidate> waiting);

 private:
  size_t groupedCount() const;
  /// decision revisit: whether the kRevisit group at `i` is due (then taken out into *due).
  bool dueRevisit(size_t i, HoldTests& tests, Due* due);
  /// Takes the group at `i` out as released, with every group that `contradicts` it, to be
  /// dropped with `why`.
  void takeReleased(size_t i, const std::string& why,
                    const std::function<bool(const HeldGroup&, const HeldGroup&)>& contradicts, Due* due);
  /// Takes the group at `i` out to be dropped with `why`.
  void takeDropped(size_t i, const std::string& why, Due* due);
  const VerifierConfig& config_;
  std::vector<HeldGroup> groups_;  ///< by revisit, oldest first
  /// Members of dropped revisit hypotheses waiting to be tested alone, with why, oldest first.
  std::vector<std::pair<HeldCandidate, std::string>> waiting_;
  std::vector<std::pair<HeldCandidate, std::string>> checking_;  ///< the nextWaiting() pass's
  size_t checked_ = 0;
  std::vector<HeldCandidate> pool_;  ///< kGlobal, oldest first
  uint64_t pool_revision_ = 0;
  size_t now_ = 0;         ///< keyframes at the pass running
  bool revisit_ = false;   ///< the pass running looks at the revisit hypotheses
  size_t cursor_ = 0;      ///< the group the pass running looks at next
};

}  // namespace core
}  // namespace rover_loop_fusion
