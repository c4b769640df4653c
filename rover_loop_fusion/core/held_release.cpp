// Verifier: settling the held candidates on keyframe arrival (settle), judging a revisit
// hypothesis before it is released (judgeRevisit) and releasing a group into the graph
// (release). Holding, deciding and dropping: verifier.cpp; rivals and revocation:
// revocation.cpp; the global pass's pool: global_release.cpp.
#include "rover_loop_fusion/core/verifier.h"

#include "rover_loop_fusion/core/cycle_test.h"
#include "rover_loop_fusion/core/decision.h"

#include <algorithm>
#include <sstream>
#include <string>
#include <vector>

namespace rover_loop_fusion {
namespace core {

void Verifier::settle(bool revisit) {
  HeldCandidates::Actions act;
  act.rival_targets = [this](const HeldGroup& g) { return rivalTargets(g); };
  act.settle_rivals = [this](const HeldGroup& g, const std::vector<LoopCandidate>& loops) { settleRivals(g, loops); };
  act.release = [this](const HeldGroup& g) { release(g); };
  act.drop = [this](const HeldGroup& g, const std::string& why, bool contradicted) { drop(g, why, contradicted); };
  act.judge = [this](const HeldGroup& g, std::string* why) { return judgeRevisit(g, why); };
  act.misfit = [this](const HeldGroup& g) { return rule_->misfit(g); };
  held_.settle(graph_.keyframeCount(), act, revisit);
}

bool Verifier::judgeRevisit(const HeldGroup& group, std::string* why) {
  // A hypothesis that contradicts accepted loops of its stretch is not released: the accepted
  // loops passed alone or with their own revisit, and a look-alike row contradicts them. Only
  // loops whose matches lie within the stretch too: where a revisit's matches jump across the
  // start of a loop run (lap 3's first loops match lap 1's start, lap 2's last its end), the
  // VIO odometry between the matches is a whole lap, whose drift the model underrates; found
  // inside loop_fusion, where it kept a third lap from closing (docs/vins-fusion.md).
  size_t contradicting = 0;
  LoopCandidate example;
  for (const HeldCandidate& h : group) {
    const std::vector<LoopCandidate> against = contradicted(h, static_cast<size_t>(config_.revisit.revisit_stretch), true);
    if (!against.empty()) {
      ++contradicting;
      example = against.front();
    }
  }
  if (2 * contradicting > group.size()) {
    std::ostringstream s;
    s << "revisit hypothesis of " << group.size() << ": " << contradicting
      << " of its members contradict accepted loops of their stretch (e.g. " << example.query_index << "->"
      << example.match_index << ")";
    *why = s.str();
    return false;
  }
  const bool passed = rule_->judge(group, why);
  // The rule's text opens with the hypothesis' size and loops, which the release names itself.
  const size_t body = why->find("): ");
  judged_ = passed && body != std::string::npos ? why->substr(body + 3) : std::string();
  return passed;
}

void Verifier::release(const HeldGroup& group) {
  std::ostringstream why;
  const bool revisit = group.front().kind == HoldKind::kRevisit;
  const bool global = group.front().kind == HoldKind::kGlobal;
  const std::string judged = revisit ? judged_ : std::string();
  judged_.clear();
  if (revisit)
    why << "released with its revisit hypothesis: " << group.size() << " mutually consistent candidates (loops ";
  else if (global)
    why << "released by the global pass: " << group.size()
        << " inliers of the robust solve over every loop, each pinned down by the others (loops ";
  else
    why << "confirmed: " << group.size() << " held candidates agree with each other (loops ";
  why << group.front().candidate.query_index << "->" << group.front().candidate.match_index << " .. "
      << group.back().candidate.query_index << "->" << group.back().candidate.match_index << ")";
  if (!judged.empty()) why << ": " << judged;
  std::vector<const HeldCandidate*> committed;
  size_t first_match = group.front().match_pos;
  for (const HeldCandidate& h : group) {
    // A candidate held on a weak prior must still pass the test against the graph as it is now
    // (a revisit hypothesis was judged as a whole just now).
    Decided decided;
    if (h.kind == HoldKind::kWeakPrior && graph_.connected(h.query_pos, h.match_pos) &&
        !rule_->recheck(h.candidate, h.query_pos, h.match_pos, &decided)) {
      decide(LoopDecision::Kind::kDrop, h.candidate,
             Verdict::Reject(Reason::kUnconfirmed, h.candidate, "confirmed with its revisit but no longer consistent with the graph"));
      continue;
    }
    const bool learn = revisit && rule_->recheck(h.candidate, h.query_pos, h.match_pos, &decided);
    pending_.valid = false;
    const Status s = commitLocked(h.candidate, false);
    if (!s.ok) {
      decide(LoopDecision::Kind::kDrop, h.candidate,
             Verdict::Reject(Reason::kUnconfirmed, h.candidate, "confirmed but not committed: " + s.message));
    } else {
      if (learn) rule_->learn(decided);  // what a confirmed revisit says about the drift
      decide(LoopDecision::Kind::kRelease, h.candidate, Verdict::Accept(h.candidate, why.str()));
      committed.push_back(&h);
      if (revisit || global) first_match = std::min(first_match, h.match_pos);
    }
  }
  if (committed.empty()) return;
  // One update of the estimate for the whole group; in the host's loop-closure path like a
  // commit: bounded when the group had no prior.
  size_t newest = committed.back()->query_pos;
  for (const HeldCandidate* h : committed) newest = std::max(newest, h->query_pos);
  rule_->updateEstimate(revisit || global ? first_match : committed.front()->match_pos, newest,
                        committed.front()->kind == HoldKind::kNoPrior ? config_.trial.time_budget_ms : 0.0);
}

}  // namespace core
}  // namespace rover_loop_fusion
