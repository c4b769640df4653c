// Decision revisit's global pass on the verifier's side (global_check; the solve itself:
// core/global_pass.cpp). What the per-candidate test rejects for contradicting the graph (held by
// the hold stage, core/stage_hold.cpp), and
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

/// What one global pass worked out over the pool, candidate by candidate (in pool order).
struct Pass {
  double c2 = 0.0, tear = 0.0, prior_gate = 0.0;  ///< the chi-square bounds of its tests
  std::vector<LoopCandidate> candidates;
  std::vector<double> prior_d2;  ///< against the prior of the accepted loops alone
  std::vector<bool> eligible;    ///< passed that test: tested further alone
  std::vector<GlobalLoop> found;
  std::vector<bool> releasable;
  std::vector<long> rival;  ///< global_compete: the rival that passes instead, or -1
  bool stopped = false;     ///< global_budget_ms ran out: nothing is decided
  bool passes(const GlobalConfig& g, const GlobalLoop& r, size_t i) const {
    return eligible[i] && r.inlier && !r.torn && r.pinned && r.d2 <= c2 && (g.global_max_sigma <= 0 || r.sigma <= g.global_max_sigma);
  }
};

/// Each candidate against the prior alone (the accepted loops, not the pool): a world of
/// look-alikes that agree with each other (floors of a deck, a shifted stretch) passes every
/// test among themselves, but not this one. Only those that pass it are tested further alone.
void testPrior(const KeyframeGraph& graph, double drift_scale, const std::vector<HeldCandidate>& pool, Pass* p) {
  p->prior_d2.assign(pool.size(), std::numeric_limits<double>::infinity());
  p->eligible.assign(pool.size(), false);
  for (size_t i = 0; i < pool.size(); ++i) {
    const HeldCandidate& h = pool[i];
    p->candidates.push_back(h.candidate);
    Eigen::Matrix4d C;
    if (graph.connected(h.query_pos, h.match_pos) && graph.relativeCovariance(h.match_pos, h.query_pos, drift_scale, &C)) {
      const Eigen::Vector4d nu = graph.innovationVector(h.candidate, h.query_pos, h.match_pos);
      p->prior_d2[i] = mahalanobis(nu, C + graph.loopCovariance());
    }
    p->eligible[i] = p->prior_d2[i] <= p->prior_gate;
  }
}

/// Competition: solved again without the releasable ones, a rival of one of them is a pooled
/// candidate of the same revisit (queries within revisit_stretch) that the first solve
/// rejected and that now passes every test. A revisit that two incompatible sets of
/// candidates explain equally well is ambiguous: neither is released.
void compete(const KeyframeGraph& graph, const VerifierConfig& config, double drift_scale,
             const std::vector<HeldCandidate>& pool, std::chrono::steady_clock::time_point deadline, Pass* p) {
  std::vector<LoopCandidate> rest;
  std::vector<bool> rest_eligible;
  std::vector<size_t> rest_index;
  for (size_t i = 0; i < pool.size(); ++i) {
    if (p->releasable[i]) continue;
    rest.push_back(p->candidates[i]);
    rest_eligible.push_back(p->eligible[i]);
    rest_index.push_back(i);
  }
  std::vector<GlobalLoop> alt;
  graph.globalConsistency(rest, p->c2, p->tear, drift_scale, rest_eligible, &alt, deadline, &p->stopped);
  if (p->stopped) std::fill(p->releasable.begin(), p->releasable.end(), false);
  const size_t stretch = static_cast<size_t>(std::max(0, config.revisit.revisit_stretch));
  for (size_t k = 0; k < rest.size(); ++k) {
    const size_t j = rest_index[k];
    if (p->found[j].inlier || !p->passes(config.global, alt[k], j)) continue;
    for (size_t i = 0; i < pool.size(); ++i) {
      if (!p->releasable[i]) continue;
      const size_t qi = pool[i].query_pos, qj = pool[j].query_pos;
      if ((qi > qj ? qi - qj : qj - qi) <= stretch) p->rival[i] = static_cast<long>(j);
    }
  }
  for (size_t i = 0; i < pool.size(); ++i) p->releasable[i] = p->releasable[i] && p->rival[i] < 0;
}

/// Why the pooled candidate `i`, not released when its window ended, is dropped.
std::string notReleased(const GlobalConfig& g, const std::vector<HeldCandidate>& pool, const Pass& p, size_t i) {
  const GlobalLoop& r = p.found[i];
  std::ostringstream s;
  s.precision(3);
  s << std::fixed << "not released by the global pass within global_window=" << g.global_window
    << " keyframes (last pass: ";
  if (p.stopped)
    s << "stopped after global_budget_ms=" << std::defaultfloat << g.global_budget_ms << std::fixed
      << " ms, nothing released";
  else if (p.rival[i] >= 0)
    s << "ambiguous: without it and the others that pass, the rival loop "
      << pool[p.rival[i]].candidate.query_index << "->" << pool[p.rival[i]].candidate.match_index
      << " of the same revisit passes every test instead (global_compete)";
  else if (!p.eligible[i])
    s << "ruled out by the prior of the accepted loops alone: d2 " << p.prior_d2[i] << " > " << p.prior_gate;
  else if (!std::isfinite(r.chi2))
    s << "not solved";
  else if (!r.inlier)
    s << "an outlier of the robust solve, residual chi2 " << r.chi2 << " (inliers <= " << p.c2 << ")";
  else if (r.torn)
    s << "an inlier of a solution that bends the odometry between its ends beyond chi2 " << p.tear;
  else if (!r.pinned)
    s << "an inlier, but the graph without it could not be solved";
  else
    s << "an inlier; without it the others predict it at d2 " << r.d2 << " (gate " << p.c2 << "), std " << r.sigma
      << " m (global_max_sigma " << g.global_max_sigma << " m)";
  s << ")";
  return s.str();
}

}  // namespace

bool Verifier::addToGlobalPool(const HeldCandidate& held) {
  if (!config_.global.global_check || config_.decision != Decision::kRevisit) return false;
  if (held.kind != HoldKind::kRevisit && held.kind != HoldKind::kGlobal) return false;
  if (!graph_.connected(held.query_pos, held.match_pos)) return false;
  HeldCandidate h = held;
  h.kind = HoldKind::kGlobal;
  h.arrived = graph_.keyframeCount();
  HeldCandidate oldest;
  if (held_.addToPool(h, static_cast<size_t>(config_.global.global_max_held), &oldest))
    emit_.drop(oldest.candidate, "dropped from the global pass's pool: global_max_held=" +
                                     std::to_string(config_.global.global_max_held) + " newer candidates wait");
  return true;
}

Status Verifier::globalPass() {
  const size_t now = graph_.keyframeCount();
  last_global_pass_ = now;
  const std::vector<HeldCandidate>& pool = held_.pool();
  // Nothing it depends on changed since the last pass (keyframes after the newest anchor do
  // not enter the condensed graph): that pass's outcome stands, unless a window ends.
  auto expired = [&](const HeldCandidate& h) {
    return now >= h.arrived + static_cast<size_t>(config_.global.global_window);
  };
  const GlobalInputs inputs{graph_.revision(), held_.poolRevision(), rule_->driftScale()};
  if (inputs == last_global_inputs_ && std::none_of(pool.begin(), pool.end(), expired)) return Status::Ok();
  last_global_inputs_ = inputs;
  // global_budget_ms, counted from here (the trials' time_budget_ms 0 lifts it: benchmarks).
  using Clock = std::chrono::steady_clock;
  using Ms = std::chrono::duration<double, std::milli>;
  const auto started = Clock::now();
  const double budget = arrivalBudgetMs(config_.global.global_budget_ms);
  const auto deadline = budget > 0 ? started + std::chrono::duration_cast<Clock::duration>(Ms(budget))
                                   : Clock::time_point::max();
  Pass p;
  p.c2 = chiSquareQuantile(config_.global.global_inlier_probability, 4);
  p.tear = chiSquareQuantile(config_.global.global_tear_probability, 4);
  p.prior_gate = chiSquareQuantile(config_.global.global_prior_probability, 4);
  testPrior(graph_, rule_->driftScale(), pool, &p);
  graph_.globalConsistency(p.candidates, p.c2, p.tear, rule_->driftScale(), p.eligible, &p.found, deadline, &p.stopped);
  p.releasable.assign(pool.size(), false);
  p.rival.assign(pool.size(), -1);
  bool any = false;
  for (size_t i = 0; !p.stopped && i < pool.size(); ++i)
    any = (p.releasable[i] = p.passes(config_.global, p.found[i], i)) || any;
  if (any && config_.global.global_compete) compete(graph_, config_, rule_->driftScale(), pool, deadline, &p);
  HeldGroup released;
  std::vector<HeldCandidate> waiting;
  for (size_t i = 0; i < pool.size(); ++i) {
    const HeldCandidate& h = pool[i];
    if (p.releasable[i])
      released.push_back(h);
    else if (expired(h) || !graph_.connected(h.query_pos, h.match_pos))
      emit_.drop(h.candidate, notReleased(config_.global, pool, p, i));
    else
      waiting.push_back(h);
  }
  held_.keepInPool(std::move(waiting));
  if (p.stopped) {
    last_global_inputs_ = GlobalInputs();  // nothing was decided: the next pass runs again
    std::ostringstream s;
    s.precision(1);
    s << std::fixed << "the global pass over " << p.candidates.size() << " pooled candidates stopped after "
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
