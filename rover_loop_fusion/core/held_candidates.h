// Candidates the verifier holds (deferred verdicts) until a later decision, by kind and revisit:
//   kNoPrior    between sequences nothing ties together yet (confirm_without_prior): released
//               once confirm_count of one stretch agree with each other;
//   kWeakPrior  passed the chi2 tests on a prior too weak to trust alone (hold_sigma): the same;
//   kRival      rejected for contradicting an accepted loop of its stretch (revoke_group): a
//               group that outnumbers those loops is decided against the graph without them;
//   kRevisit    decision revisit: not accepted alone, not ruled out by the drift model; a
//               hypothesis of revisit_support members that passes its joint test against the
//               prior (Actions::judge) and that no rival hypothesis of its stretch competes with
//               is released; one that fails its test or waits longer than revisit_window is
//               dropped. A member of a dropped hypothesis is tested alone first, on keyframe
//               arrival, against the loops committed since it was held; until then it waits
//               (wait(), settleWaiting()): for a commit, up to revisit_window keyframes after its
//               arrival, or for a keyframe with revisit_retest_budget_ms left.
//   kGlobal     decision revisit with global_check: rejected for contradicting the graph, held
//               in the verifier's global pool (not here: core/global_release.cpp) until the global
//               pass releases it or global_window expires.
// This unit owns the bookkeeping: which held candidates form a group (same kind, same segments,
// queries within confirm_stretch (revisit: revisit_stretch), every pair of the last confirm_count consistent), which group
// is due (confirmed, expired, blocked by a rival group of its stretch) and in which order. What
// a release, a drop or a revocation does to the graph is the verifier's (the Actions).
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

class HeldCandidates {
 public:
  /// Reads confirm_count, confirm_window (expiry), confirm_stretch, revoke_group and revisit_*.
  explicit HeldCandidates(const VerifierConfig& config) : config_(config) {}

  /// Holds `h`: it joins the first group of its kind and segments whose last confirm_count
  /// members lie within confirm_stretch (revisit_stretch) keyframes of it and are `consistent` with it, or starts
  /// a group of its own.
  void add(const HeldCandidate& h, const std::function<bool(const HeldCandidate&, const HeldCandidate&)>& consistent);
  /// kRevisit: `h`, a member of a dropped hypothesis, waits (with why it was dropped) to be
  /// tested alone on a later keyframe (settleWaiting()).
  void wait(const HeldCandidate& h, const std::string& why);
  /// Held and waiting candidates.
  size_t size() const;
  bool empty() const { return groups_.empty() && waiting_.empty(); }

  /// What settle() asks the verifier to do with a group it has taken out.
  struct Actions {
    /// The accepted loops a group of rivals contradicts.
    std::function<std::vector<LoopCandidate>(const HeldGroup&)> rival_targets;
    /// A confirmed group of rivals against the loops it contradicts (may change the graph).
    std::function<void(const HeldGroup&, const std::vector<LoopCandidate>&)> settle_rivals;
    /// A confirmed group (may change the graph).
    std::function<void(const HeldGroup&)> release;
    /// A group given up, with why.
    /// `contradicted`: dropped because a released group contradicts it (a revisit member is
    /// then not tested alone again).
    std::function<void(const HeldGroup&, const std::string&, bool contradicted)> drop;
    /// kRevisit: whether a hypothesis passes its joint test against the prior now (why not in
    /// *why).
    std::function<bool(const HeldGroup&, std::string* why)> judge;
    /// kRevisit: the median Mahalanobis distance of a hypothesis' members now.
    std::function<double(const HeldGroup&)> misfit;
  };
  /// Acts on every group that is due at `now` keyframes: confirmed groups (released, or rivals
  /// settled), rival groups too small to block a released one (dropped), expired groups
  /// (dropped); after an action that may change the graph it looks at the rest again. The
  /// revisit hypotheses (kRevisit) only if `revisit`.
  void settle(size_t now, const Actions& act, bool revisit);

  /// Gives each waiting member, oldest first and once, to `drop_member` (which tests it alone,
  /// or makes it wait again) once a loop was committed since it was held (`revision()`, the
  /// graph's revision now, differs from its own), or when revisit_window has passed since it
  /// arrived (why says so); the others go on waiting.
  void settleWaiting(size_t now, const std::function<uint64_t()>& revision,
                     const std::function<void(const HeldCandidate&, const std::string& why)>& drop_member);

 private:
  /// decision revisit: settles the kRevisit group at `i`; true if it acted (the group is gone).
  bool settleRevisit(size_t i, const Actions& act);
  /// Releases the group at `i`, then drops (with `why`) every group that `contradicts` it.
  void releaseDropping(size_t i, const Actions& act, const std::string& why,
                       const std::function<bool(const HeldGroup&, const HeldGroup&)>& contradicts);
  const VerifierConfig& config_;
  std::vector<HeldGroup> groups_;  ///< by revisit, oldest first
  /// Members of dropped revisit hypotheses waiting to be tested alone, with why, oldest first.
  std::vector<std::pair<HeldCandidate, std::string>> waiting_;
  size_t now_ = 0;                 ///< keyframes at the settle() running
};

}  // namespace core
}  // namespace rover_loop_fusion
