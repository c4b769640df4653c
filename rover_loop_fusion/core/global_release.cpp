// Decision revisit's global pass on the verifier's side (global_check; the solve itself:
// core/global_pass.cpp). What the per-candidate test rejects for contradicting the graph, and
// the members of revisit hypotheses that were dropped, wait in a pool; every global_period
// keyframes the pool is judged against every loop at once, and an inlier that the other loops
// pin down, that the prior of the accepted loops does not rule out and that no rival of its
// revisit could replace (global_compete) is released (kRelease, as a group). A candidate that
// waited global_window keyframes,
// or the oldest one when the pool is full, is dropped (kDrop, reason unconfirmed).
#include "rover_loop_fusion/core/verifier.h"

#include "rover_loop_fusion/core/decision.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

bool contradictsTheGraph(Reason reason) {
  return reason == Reason::kInnovationAboveBound || reason == Reason::kScoreAboveThreshold ||
         reason == Reason::kInconsistentWithDrift;
}

}  // namespace

bool Verifier::holdForGlobal(const LoopCandidate& c, size_t qpos, size_t mpos, Reason reason, std::string* detail) {
  if (!config_.global.global_check || config_.decision != Decision::kRevisit || !contradictsTheGraph(reason))
    return false;
  HeldCandidate h = heldFor(c);
  h.query_pos = qpos;
  h.match_pos = mpos;
  h.kind = HoldKind::kGlobal;
  if (!addToGlobalPool(h)) return false;
  emit_.held(c);
  *detail += "; held for the global pass (global_check)";
  return true;
}

bool Verifier::addToGlobalPool(const HeldCandidate& held) {
  if (!config_.global.global_check || config_.decision != Decision::kRevisit) return false;
  if (held.kind != HoldKind::kRevisit && held.kind != HoldKind::kGlobal) return false;
  if (!graph_.connected(held.query_pos, held.match_pos)) return false;
  HeldCandidate h = held;
  h.kind = HoldKind::kGlobal;
  h.arrived = graph_.keyframeCount();
  if (global_pool_.size() >= static_cast<size_t>(config_.global.global_max_held)) {
    const HeldCandidate oldest = global_pool_.front();
    global_pool_.erase(global_pool_.begin());
    emit_.drop(oldest.candidate, "dropped from the global pass's pool: global_max_held=" +
                                     std::to_string(config_.global.global_max_held) + " newer candidates wait");
  }
  global_pool_.push_back(h);
  ++global_pool_revision_;
  return true;
}

Status Verifier::globalPass() {
  const size_t now = graph_.keyframeCount();
  last_global_pass_ = now;
  // Nothing it depends on changed since the last pass (keyframes after the newest anchor do
  // not enter the condensed graph): that pass's outcome stands, unless a window ends.
  auto expired = [&](const HeldCandidate& h) {
    return now >= h.arrived + static_cast<size_t>(config_.global.global_window);
  };
  const GlobalInputs inputs{graph_.revision(), global_pool_revision_, rule_->driftScale()};
  if (inputs == last_global_inputs_ && std::none_of(global_pool_.begin(), global_pool_.end(), expired))
    return Status::Ok();
  last_global_inputs_ = inputs;
  // global_budget_ms, counted from here (the trials' time_budget_ms 0 lifts it: benchmarks).
  using Clock = std::chrono::steady_clock;
  using Ms = std::chrono::duration<double, std::milli>;
  const auto started = Clock::now();
  const double budget = arrivalBudgetMs(config_.global.global_budget_ms);
  const auto deadline = budget > 0 ? started + std::chrono::duration_cast<Clock::duration>(Ms(budget))
                                   : Clock::time_point::max();
  bool stopped = false;
  const double c2 = chiSquareQuantile(config_.global.global_inlier_probability, 4);
  const double tear = chiSquareQuantile(config_.global.global_tear_probability, 4);
  const double prior_gate = chiSquareQuantile(config_.global.global_prior_probability, 4);
  // Each candidate against the prior alone (the accepted loops, not the pool): a world of
  // look-alikes that agree with each other (floors of a deck, a shifted stretch) passes every
  // test among themselves, but not this one. Only those that pass it are tested further alone.
  std::vector<LoopCandidate> candidates;
  std::vector<double> prior_d2(global_pool_.size(), std::numeric_limits<double>::infinity());
  std::vector<bool> eligible(global_pool_.size(), false);
  for (size_t i = 0; i < global_pool_.size(); ++i) {
    const HeldCandidate& h = global_pool_[i];
    candidates.push_back(h.candidate);
    Eigen::Matrix4d C;
    if (graph_.connected(h.query_pos, h.match_pos) &&
        graph_.relativeCovariance(h.match_pos, h.query_pos, rule_->driftScale(), &C)) {
      const Eigen::Vector4d nu = graph_.innovationVector(h.candidate, h.query_pos, h.match_pos);
      prior_d2[i] = mahalanobis(nu, C + graph_.loopCovariance());
    }
    eligible[i] = prior_d2[i] <= prior_gate;
  }
  std::vector<GlobalLoop> found;
  graph_.globalConsistency(candidates, c2, tear, rule_->driftScale(), eligible, &found, deadline, &stopped);
  auto passes = [&](const GlobalLoop& r, size_t i) {
    return eligible[i] && r.inlier && !r.torn && r.pinned && r.d2 <= c2 &&
           (config_.global.global_max_sigma <= 0 || r.sigma <= config_.global.global_max_sigma);
  };
  std::vector<bool> releasable(global_pool_.size());
  bool any = false;
  for (size_t i = 0; !stopped && i < global_pool_.size(); ++i) any = (releasable[i] = passes(found[i], i)) || any;
  // Competition: solved again without the releasable ones, a rival of one of them is a pooled
  // candidate of the same revisit (queries within revisit_stretch) that the first solve
  // rejected and that now passes every test. A revisit that two incompatible sets of
  // candidates explain equally well is ambiguous: neither is released.
  std::vector<long> rival(global_pool_.size(), -1);
  if (any && config_.global.global_compete) {
    std::vector<LoopCandidate> rest;
    std::vector<bool> rest_eligible;
    std::vector<size_t> rest_index;
    for (size_t i = 0; i < global_pool_.size(); ++i) {
      if (releasable[i]) continue;
      rest.push_back(candidates[i]);
      rest_eligible.push_back(eligible[i]);
      rest_index.push_back(i);
    }
    std::vector<GlobalLoop> alt;
    graph_.globalConsistency(rest, c2, tear, rule_->driftScale(), rest_eligible, &alt, deadline, &stopped);
    if (stopped) std::fill(releasable.begin(), releasable.end(), false);
    const size_t stretch = static_cast<size_t>(std::max(0, config_.revisit.revisit_stretch));
    for (size_t k = 0; k < rest.size(); ++k) {
      const size_t j = rest_index[k];
      if (found[j].inlier || !passes(alt[k], j)) continue;
      for (size_t i = 0; i < global_pool_.size(); ++i) {
        if (!releasable[i]) continue;
        const size_t qi = global_pool_[i].query_pos, qj = global_pool_[j].query_pos;
        if ((qi > qj ? qi - qj : qj - qi) <= stretch) rival[i] = static_cast<long>(j);
      }
    }
    for (size_t i = 0; i < global_pool_.size(); ++i) releasable[i] = releasable[i] && rival[i] < 0;
  }
  HeldGroup released;
  std::vector<HeldCandidate> waiting;
  for (size_t i = 0; i < global_pool_.size(); ++i) {
    const HeldCandidate& h = global_pool_[i];
    const GlobalLoop& r = found[i];
    if (releasable[i]) {
      released.push_back(h);
    } else if (expired(h) || !graph_.connected(h.query_pos, h.match_pos)) {
      std::ostringstream s;
      s.precision(3);
      s << std::fixed << "not released by the global pass within global_window=" << config_.global.global_window
        << " keyframes (last pass: ";
      if (stopped)
        s << "stopped after global_budget_ms=" << std::defaultfloat << config_.global.global_budget_ms << std::fixed
          << " ms, nothing released";
      else if (rival[i] >= 0)
        s << "ambiguous: without it and the others that pass, the rival loop "
          << global_pool_[rival[i]].candidate.query_index << "->" << global_pool_[rival[i]].candidate.match_index
          << " of the same revisit passes every test instead (global_compete)";
      else if (!eligible[i])
        s << "ruled out by the prior of the accepted loops alone: d2 " << prior_d2[i] << " > " << prior_gate;
      else if (!std::isfinite(r.chi2))
        s << "not solved";
      else if (!r.inlier)
        s << "an outlier of the robust solve, residual chi2 " << r.chi2 << " (inliers <= " << c2 << ")";
      else if (r.torn)
        s << "an inlier of a solution that bends the odometry between its ends beyond chi2 " << tear;
      else if (!r.pinned)
        s << "an inlier, but the graph without it could not be solved";
      else
        s << "an inlier; without it the others predict it at d2 " << r.d2 << " (gate " << c2 << "), std " << r.sigma
          << " m (global_max_sigma " << config_.global.global_max_sigma << " m)";
      s << ")";
      emit_.drop(h.candidate, s.str());
    } else {
      waiting.push_back(h);
    }
  }
  if (waiting.size() != global_pool_.size()) ++global_pool_revision_;
  global_pool_.swap(waiting);
  if (stopped) {
    last_global_inputs_ = GlobalInputs();  // nothing was decided: the next pass runs again
    std::ostringstream s;
    s.precision(1);
    s << std::fixed << "the global pass over " << candidates.size() << " pooled candidates stopped after "
      << Ms(Clock::now() - started).count() << " ms (global_budget_ms=" << std::defaultfloat
      << config_.global.global_budget_ms << "): nothing released; the pool waits for the next pass";
    return Status::Warning(s.str());
  }
  if (released.empty()) return Status::Ok();
  std::sort(released.begin(), released.end(),
            [](const HeldCandidate& a, const HeldCandidate& b) { return a.query_pos < b.query_pos; });
  release(released);
  return Status::Ok();
}

}  // namespace core
}  // namespace rover_loop_fusion
