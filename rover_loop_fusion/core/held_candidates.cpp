#include "rover_loop_fusion/core/held_candidates.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

void HeldCandidates::add(const HeldCandidate& h,
                         const std::function<bool(const HeldCandidate&, const HeldCandidate&)>& consistent) {
  const size_t window = static_cast<size_t>(h.kind == HoldKind::kRevisit ? config_.revisit.revisit_stretch : config_.hold.confirm_stretch);
  const size_t k = static_cast<size_t>(config_.hold.confirm_count);
  for (HeldGroup& g : groups_) {
    const HeldCandidate& f = g.front();
    if (f.kind != h.kind || f.query_segment != h.query_segment || f.match_segment != h.match_segment) continue;
    bool ok = true;
    for (size_t i = g.size() > k ? g.size() - k : 0; ok && i < g.size(); ++i)
      ok = keyframeDistance(g[i].query_pos, h.query_pos) <= window && consistent(g[i], h);
    if (ok) {
      g.push_back(h);
      return;
    }
  }
  groups_.push_back({h});
}

void HeldCandidates::wait(const HeldCandidate& h, const std::string& why) { waiting_.emplace_back(h, why); }

void HeldCandidates::settleWaiting(size_t now, const std::function<uint64_t()>& revision,
                                   const std::function<void(const HeldCandidate&, const std::string&)>& drop_member) {
  const size_t window = static_cast<size_t>(config_.revisit.revisit_window);
  std::vector<std::pair<HeldCandidate, std::string>> waiting;
  waiting.swap(waiting_);  // drop_member() may make a member wait again
  for (auto& w : waiting) {
    const HeldCandidate& h = w.first;
    if (h.revision != revision()) {
      drop_member(h, w.second);  // tested alone against the graph with the new loops
    } else if (now > h.arrived + window) {
      std::ostringstream s;
      s << w.second << "; no loop was committed within revisit_window=" << window
        << " keyframes to test it alone again";
      drop_member(h, s.str());
    } else {
      waiting_.push_back(std::move(w));
    }
  }
}

size_t HeldCandidates::size() const {
  size_t n = waiting_.size();
  for (const HeldGroup& g : groups_) n += g.size();
  return n;
}

void HeldCandidates::releaseDropping(size_t i, const Actions& act, const std::string& why,
                                     const std::function<bool(const HeldGroup&, const HeldGroup&)>& contradicts) {
  HeldGroup released;
  released.swap(groups_[i]);
  groups_.erase(groups_.begin() + i);
  act.release(released);
  for (size_t j = 0; j < groups_.size();) {
    if (contradicts(groups_[j], released)) {
      act.drop(groups_[j], why, true);
      groups_.erase(groups_.begin() + j);
    } else {
      ++j;
    }
  }
}

void HeldCandidates::settle(size_t now, const Actions& act, bool revisit) {
  now_ = now;
  const size_t k = static_cast<size_t>(config_.hold.confirm_count);
  const size_t window = static_cast<size_t>(config_.hold.confirm_window);    // expiry
  const size_t stretch = static_cast<size_t>(config_.hold.confirm_stretch);  // how close rival groups are
  for (size_t i = 0; i < groups_.size();) {
    HeldGroup& g = groups_[i];
    if (g.front().kind == HoldKind::kRevisit) {
      if (revisit && settleRevisit(i, act)) {
        i = 0;  // the graph may have changed
        continue;
      }
      ++i;
      continue;
    }
    if (g.front().kind == HoldKind::kRival) {
      // Confirmed once revoke_group agree and they outnumber the loops they contradict (until
      // then more rivals may join, or the window runs out).
      std::vector<LoopCandidate> targets;
      if (g.size() >= static_cast<size_t>(config_.hold.revoke_group) && g.size() > (targets = act.rival_targets(g)).size()) {
        HeldGroup rivals;
        rivals.swap(g);
        groups_.erase(groups_.begin() + i);
        act.settle_rivals(rivals, targets);
        i = 0;  // the graph may have changed
        continue;
      }
    } else if (g.size() >= k) {
      // Rivals: other held groups of the same query stretch that did not join this one.
      bool blocked = false;
      for (size_t j = 0; j < groups_.size(); ++j) {
        if (j == i || groups_[j].front().kind == HoldKind::kRival || groups_[j].front().kind == HoldKind::kRevisit)
          continue;  // rivals contend with accepted loops
        if (keyframeDistance(groups_[j].back().query_pos, g.back().query_pos) <= stretch && 2 * groups_[j].size() >= g.size())
          blocked = true;
      }
      if (!blocked) {
        // Rivals too small to block are contradicted by the released group: dropped.
        releaseDropping(i, act, "a larger group of candidates of the same stretch contradicts it",
                        [&](const HeldGroup& other, const HeldGroup& released) {
                          return keyframeDistance(other.back().query_pos, released.back().query_pos) <= stretch &&
                                 other.front().kind != HoldKind::kRival && other.front().kind != HoldKind::kRevisit;
                        });
        i = 0;  // the graph changed: look at the rest again
        continue;
      }
    }
    if (now > g.front().arrived + window) {
      std::ostringstream s;
      if (g.front().kind == HoldKind::kRival)
        s << "a rival of accepted loops, not confirmed by revoke_group=" << config_.hold.revoke_group
          << " agreeing candidates within confirm_window=" << window << " keyframes: nothing revoked";
      else
        s << "not confirmed by " << k << " agreeing candidates within confirm_window=" << window << " keyframes";
      const HeldGroup expired = g;
      groups_.erase(groups_.begin() + i);
      act.drop(expired, s.str(), false);
      continue;
    }
    ++i;
  }
}

bool HeldCandidates::settleRevisit(size_t i, const Actions& act) {
  const size_t stretch = static_cast<size_t>(config_.revisit.revisit_stretch);
  const size_t now_window = static_cast<size_t>(config_.revisit.revisit_window);
  HeldGroup& g = groups_[i];
  auto near = [&](const HeldGroup& a, const HeldGroup& b) {
    // Two hypotheses of one revisit: some queries of the two lie within the stretch.
    const size_t a0 = a.front().query_pos, a1 = a.back().query_pos, b0 = b.front().query_pos, b1 = b.back().query_pos;
    return !(a1 + stretch < b0 || b1 + stretch < a0);
  };
  if (g.size() >= static_cast<size_t>(config_.revisit.revisit_support)) {
    std::string why;
    if (!act.judge(g, &why)) {
      const HeldGroup failed = g;
      groups_.erase(groups_.begin() + i);
      act.drop(failed, why, false);
      return true;
    }
    // Rival hypotheses of the same revisit compete by fit and support: the release waits until
    // this one is better than every rival by revisit_margin (or the window runs out).
    auto misfit = [&](const HeldGroup& h) {
      return act.misfit(h) - config_.revisit.revisit_member_weight * static_cast<double>(h.size() - 1);
    };
    const double mine = misfit(g);
    bool blocked = false;
    for (size_t j = 0; j < groups_.size() && !blocked; ++j)
      if (j != i && groups_[j].front().kind == HoldKind::kRevisit && near(groups_[j], g) &&
          !(mine + config_.revisit.revisit_margin < misfit(groups_[j])))
        blocked = true;
    if (!blocked) {
      // The rivals of the released hypothesis contradict it: dropped.
      releaseDropping(i, act, "a larger hypothesis of the same revisit was released",
                      [&](const HeldGroup& other, const HeldGroup& released) {
                        return other.front().kind == HoldKind::kRevisit && near(other, released);
                      });
      return true;
    }
  }
  if (now_ > g.front().arrived + now_window) {
    std::ostringstream s;
    s << "its revisit hypothesis (" << g.size() << " of revisit_support=" << config_.revisit.revisit_support
      << " members) was not released within revisit_window=" << now_window << " keyframes";
    const HeldGroup expired = g;
    groups_.erase(groups_.begin() + i);
    act.drop(expired, s.str(), false);
    return true;
  }
  return false;
}

}  // namespace core
}  // namespace rover_loop_fusion
