// Revocation (revoke_group, core/verifier.h): a candidate rejected for contradicting the graph
// that is inconsistent with an accepted loop of its stretch is held as a rival (the hold stage,
// core/stage_hold.cpp); a confirmed group of rivals is decided here against the graph without
// the loops it contradicts (asking the accepted loops, core/accepted_loops.h).
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

/// Which of the two fits the graph without the `loops` better, decisively: empty if the rivals
/// of `group` do, else why not (`what`: the group, as its verdicts name it). The larger group
/// alone is no reason: a row of look-alikes can outnumber a true revisit, and after long drift the
/// prior cannot tell them apart. The misfit of a loop: its innovation's squared Mahalanobis
/// distance under the drift model (both decisions, 4-DoF and 6-DoF); the rivals' median must
/// be within the chi-square gate (gate_probability: they fit at all) and lower than the loops'
/// by revoke_margin (2 ln of the likelihood ratio, as the look-alike test's lookalike_margin). Without a
/// covariance nothing is revoked.
std::string fitsWorse(const KeyframeGraph& graph, const VerifierConfig& config, double drift_scale,
                      const HeldGroup& group, const std::vector<LoopCandidate>& loops, const std::string& what) {
  auto misfit = [&](const LoopCandidate& c) {
    size_t q = 0, m = 0;
    Eigen::Matrix4d C;
    if (!graph.find(c.query_index, &q) || !graph.find(c.match_index, &m) ||
        !graph.relativeCovariance(m, q, drift_scale, &C))
      return std::numeric_limits<double>::infinity();
    return mahalanobis(graph.innovationVector(c, q, m), C + graph.loopCovariance());
  };
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  std::vector<double> fit_loops, fit_rivals;
  for (const LoopCandidate& l : loops) fit_loops.push_back(misfit(l));
  for (const HeldCandidate& h : group) fit_rivals.push_back(misfit(h.candidate));
  const double misfit_loops = median(fit_loops), misfit_rivals = median(fit_rivals);
  const double gate = chiSquareQuantile(config.chi2.gate_probability, 4);
  if (std::isfinite(misfit_loops) && misfit_rivals <= gate && misfit_rivals + config.hold.revoke_margin < misfit_loops)
    return std::string();
  std::ostringstream s;
  s.precision(3);
  s << what << ", but they do not fit the graph without the " << loops.size()
    << " accepted loop(s) they contradict decisively better than those loops (median squared Mahalanobis "
    << "distance " << misfit_rivals << " vs " << misfit_loops << "; needed: within the gate " << gate
    << " and lower by revoke_margin " << config.hold.revoke_margin << "): nothing revoked";
  return s.str();
}

}  // namespace

void Verifier::settleRivals(const HeldGroup& group, const std::vector<LoopCandidate>& loops) {
  pending_.valid = false;  // the graph changes below
  auto dropAll = [&](const std::vector<const HeldCandidate*>& hs, const std::string& why) {
    for (const HeldCandidate* h : hs)
      emit_.drop(h->candidate, why);
  };
  std::vector<const HeldCandidate*> all;
  for (const HeldCandidate& h : group) all.push_back(&h);

  std::ostringstream what;
  what << group.size() << " rivals (loops " << group.front().candidate.query_index << "->"
       << group.front().candidate.match_index << " .. " << group.back().candidate.query_index << "->"
       << group.back().candidate.match_index << ") agree with each other";
  if (loops.empty()) {
    dropAll(all, what.str() + ", but the accepted loops they contradicted are no longer in the graph");
    return;
  }

  // The graph without those loops, and the rivals decided again against it.
  const std::vector<KeyframeState> saved = graph_.estimates();
  size_t first = group.front().match_pos, newest = group.front().query_pos;
  for (const HeldCandidate& h : group) {
    first = std::min(first, h.match_pos);
    newest = std::max(newest, h.query_pos);
  }
  for (const LoopCandidate& l : loops) {
    graph_.removeLoop(l.query_index, l.match_index);
    size_t m = 0;
    if (graph_.find(l.match_index, &m)) first = std::min(first, m);
  }
  rule_->updateEstimate(first, newest, 0.0);
  std::vector<const HeldCandidate*> passed, failed;
  auto putBack = [&](const std::string& why) {
    for (const HeldCandidate* h : passed) graph_.removeLoop(h->candidate.query_index, h->candidate.match_index);
    for (const LoopCandidate& l : loops) graph_.addLoop(l);
    graph_.restoreEstimates(saved);
    dropAll(all, why);
  };

  const std::string worse = fitsWorse(graph_, config_, rule_->driftScale(), group, loops, what.str());
  if (!worse.empty()) {
    putBack(worse);
    return;
  }

  for (const HeldCandidate& h : group) {
    Decided decided;
    const bool ok = rule_->recheck(h.candidate, h.query_pos, h.match_pos, &decided) && graph_.addLoop(h.candidate).ok;
    if (ok) rule_->adoptDecided(decided, h.query_pos, true);
    (ok ? passed : failed).push_back(&h);
  }

  if (passed.size() >= static_cast<size_t>(config_.hold.revoke_group) && passed.size() > loops.size()) {
    std::ostringstream revoked;
    revoked << what.str() << ", contradict it and pass against the graph without it (" << passed.size() << " of "
            << group.size() << "; revoke_group=" << config_.hold.revoke_group << ")";
    for (const LoopCandidate& l : loops) emit_.revoke(l, revoked.str());
    std::ostringstream released;
    released << what.str() << ": " << loops.size() << " accepted loop(s) they contradicted revoked ("
             << loops.front().query_index << "->" << loops.front().match_index << (loops.size() > 1 ? ", ..." : "")
             << ")";
    for (const HeldCandidate* h : passed) emit_.release(h->candidate, released.str());
    dropAll(failed, what.str() + " and revoked the loops they contradict, but this one does not pass against the graph without them");
    return;
  }
  // Not enough of them pass: the graph as it was.
  std::ostringstream s;
  s << what.str() << ", but only " << passed.size() << " of them pass against the graph without the "
    << loops.size() << " accepted loop(s) they contradict (revoke_group=" << config_.hold.revoke_group << "): nothing revoked";
  putBack(s.str());
}

}  // namespace core
}  // namespace rover_loop_fusion
