#include "rover_loop_fusion/core/held_candidates.h"

#include <sstream>

namespace rover_loop_fusion {
namespace core {

void HeldCandidates::add(const HeldCandidate& h, const HoldTests& tests) {
  const size_t window = static_cast<size_t>(h.kind == HoldKind::kRevisit ? config_.revisit.revisit_stretch : config_.hold.confirm_stretch);
  const size_t k = static_cast<size_t>(config_.hold.confirm_count);
  for (HeldGroup& g : groups_) {
    const HeldCandidate& f = g.front();
    if (f.kind != h.kind || f.query_segment != h.query_segment || f.match_segment != h.match_segment) continue;
    bool ok = true;
    for (size_t i = g.size() > k ? g.size() - k : 0; ok && i < g.size(); ++i)
      ok = keyframeDistance(g[i].query_pos, h.query_pos) <= window && tests.consistent(g[i], h);
    if (ok) {
      g.push_back(h);
      return;
    }
  }
  groups_.push_back({h});
}

void HeldCandidates::wait(const HeldCandidate& h, const std::string& why) { waiting_.emplace_back(h, why); }

void HeldCandidates::beginWaiting() {
  checking_.clear();
  checking_.swap(waiting_);  // a member given out may be made to wait again
  checked_ = 0;
}

bool HeldCandidates::nextWaiting(size_t now, uint64_t revision, HeldCandidate* h, std::string* why) {
  const size_t window = static_cast<size_t>(config_.revisit.revisit_window);
  while (checked_ < checking_.size()) {
    auto& w = checking_[checked_++];
    if (w.first.revision != revision) {  // tested alone against the graph with the new loops
      *h = w.first;
      *why = w.second;
      return true;
    }
    if (now > w.first.arrived + window) {
      std::ostringstream s;
      s << w.second << "; no loop was committed within revisit_window=" << window
        << " keyframes to test it alone again";
      *h = w.first;
      *why = s.str();
      return true;
    }
    waiting_.push_back(std::move(w));
  }
  checking_.clear();
  return false;
}

size_t HeldCandidates::groupedCount() const {
  size_t n = 0;
  for (const HeldGroup& g : groups_) n += g.size();
  return n;
}

bool HeldCandidates::addToPool(const HeldCandidate& h, size_t max_held, HeldCandidate* evicted) {
  const bool full = pool_.size() >= max_held;
  if (full) {
    *evicted = pool_.front();
    pool_.erase(pool_.begin());
  }
  pool_.push_back(h);
  ++pool_revision_;
  return full;
}

void HeldCandidates::keepInPool(std::vector<HeldCandidate> waiting) {
  if (waiting.size() != pool_.size()) ++pool_revision_;
  pool_.swap(waiting);
}

void HeldCandidates::takeReleased(size_t i, const std::string& why,
                                  const std::function<bool(const HeldGroup&, const HeldGroup&)>& contradicts,
                                  Due* due) {
  *due = Due();
  due->action = Due::Action::kRelease;
  due->group.swap(groups_[i]);
  groups_.erase(groups_.begin() + i);
  due->dropped_why = why;
  for (size_t j = 0; j < groups_.size();) {
    if (contradicts(groups_[j], due->group)) {
      due->dropped.push_back(std::move(groups_[j]));
      groups_.erase(groups_.begin() + j);
    } else {
      ++j;
    }
  }
}

void HeldCandidates::takeDropped(size_t i, const std::string& why, Due* due) {
  *due = Due();
  due->action = Due::Action::kDrop;
  due->group.swap(groups_[i]);
  groups_.erase(groups_.begin() + i);
  due->why = why;
}

void HeldCandidates::beginSettle(size_t now, bool revisit) {
  now_ = now;
  revisit_ = revisit;
  cursor_ = 0;
}

bool HeldCandidates::nextDue(HoldTests& tests, Due* due) {
  const size_t k = static_cast<size_t>(config_.hold.confirm_count);
  const size_t window = static_cast<size_t>(config_.hold.confirm_window);    // expiry
  const size_t stretch = static_cast<size_t>(config_.hold.confirm_stretch);  // how close rival groups are
  while (cursor_ < groups_.size()) {
    const size_t i = cursor_;
    HeldGroup& g = groups_[i];
    if (g.front().kind == HoldKind::kRevisit) {
      if (revisit_ && dueRevisit(i, tests, due)) {
        cursor_ = 0;  // the graph may change
        return true;
      }
      ++cursor_;
      continue;
    }
    if (g.front().kind == HoldKind::kRival) {
      // Confirmed once revoke_group agree and they outnumber the loops they contradict (until
      // then more rivals may join, or the window runs out).
      std::vector<LoopCandidate> targets;
      if (g.size() >= static_cast<size_t>(config_.hold.revoke_group) && g.size() > (targets = tests.rivalTargets(g)).size()) {
        *due = Due();
        due->action = Due::Action::kSettleRivals;
        due->group.swap(g);
        due->targets = std::move(targets);
        groups_.erase(groups_.begin() + i);
        cursor_ = 0;  // the graph may change
        return true;
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
        takeReleased(i, "a larger group of candidates of the same stretch contradicts it",
                     [&](const HeldGroup& other, const HeldGroup& released) {
                       return keyframeDistance(other.back().query_pos, released.back().query_pos) <= stretch &&
                              other.front().kind != HoldKind::kRival && other.front().kind != HoldKind::kRevisit;
                     },
                     due);
        cursor_ = 0;  // the graph changes: look at the rest again
        return true;
      }
    }
    if (now_ > g.front().arrived + window) {
      std::ostringstream s;
      if (g.front().kind == HoldKind::kRival)
        s << "a rival of accepted loops, not confirmed by revoke_group=" << config_.hold.revoke_group
          << " agreeing candidates within confirm_window=" << window << " keyframes: nothing revoked";
      else
        s << "not confirmed by " << k << " agreeing candidates within confirm_window=" << window << " keyframes";
      takeDropped(i, s.str(), due);  // the pass goes on at the group after it
      return true;
    }
    ++cursor_;
  }
  return false;
}

bool HeldCandidates::dueRevisit(size_t i, HoldTests& tests, Due* due) {
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
    if (!tests.judge(g, &why)) {
      takeDropped(i, why, due);
      return true;
    }
    // Rival hypotheses of the same revisit compete by fit and support: the release waits until
    // this one is better than every rival by revisit_margin (or the window runs out).
    auto misfit = [&](const HeldGroup& h) {
      return tests.misfit(h) - config_.revisit.revisit_member_weight * static_cast<double>(h.size() - 1);
    };
    const double mine = misfit(g);
    bool blocked = false;
    for (size_t j = 0; j < groups_.size() && !blocked; ++j)
      if (j != i && groups_[j].front().kind == HoldKind::kRevisit && near(groups_[j], g) &&
          !(mine + config_.revisit.revisit_margin < misfit(groups_[j])))
        blocked = true;
    if (!blocked) {
      // The rivals of the released hypothesis contradict it: dropped.
      takeReleased(i, "a larger hypothesis of the same revisit was released",
                   [&](const HeldGroup& other, const HeldGroup& released) {
                     return other.front().kind == HoldKind::kRevisit && near(other, released);
                   },
                   due);
      due->why = why;
      return true;
    }
  }
  if (now_ > g.front().arrived + now_window) {
    std::ostringstream s;
    s << "its revisit hypothesis (" << g.size() << " of revisit_support=" << config_.revisit.revisit_support
      << " members) was not released within revisit_window=" << now_window << " keyframes";
    takeDropped(i, s.str(), due);
    return true;
  }
  return false;
}

}  // namespace core
}  // namespace rover_loop_fusion
