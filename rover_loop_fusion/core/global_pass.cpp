// Decision revisit's global pass (KeyframeGraph::globalConsistency): candidate loops judged
// against every loop at once, for the revisits that yield a single candidate after long drift
// (city-scale routes), where neither the per-candidate trial nor a revisit hypothesis can.
//
// On the condensed graph of a component (core/condensed.h: the accepted loops, the drift
// model's or the data's covariance for the odometry between anchors) the candidates are added
// as loop edges with loopCovariance() and solved by graduated non-convexity with a truncated
// quadratic loss (Yang et al., "Graduated Non-Convexity for Robust Spatial Perception", 2020):
// weighted Gauss-Newton, each candidate's weight from its residual, the loss sharpened from
// convex to truncated step by step. Accepted loops keep their weight (they passed their own
// test). A candidate with weight > 0.5 and its residual within the inlier quantile at the end is
// an inlier.
//
// An inlier of a robust solve is not yet evidence: a loop that nothing else constrains fits
// any drift. So each inlier is also tested against the others alone (leave one out): the
// graph without it is solved again, and the relative pose its ends get there is compared with
// the candidate in units of that relative pose's covariance (the marginal through the graph)
// plus the loop's. How tightly the others pin it down (sigma) is reported; the caller bounds it.
// And the odometry's loss is not robust: a row of look-alikes that agree with each other can be
// absorbed by bending it. An inlier whose cycle (the chains of odometry between its ends) the
// solution bends beyond the tear quantile is marked torn.
//
// What this cannot tell apart (measured: docs/results.md, "The global pass"): a revisit of
// look-alikes that agree with each other and lie within the prior's uncertainty (near rows,
// a consistently shifted stretch). The verifier adds the prior test (core/global_release.cpp).
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/decision.h"
#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <vector>

namespace rover_loop_fusion {
namespace core {

namespace {

/// Graduated non-convexity: the factor by which the truncated loss sharpens per step, and how
/// many steps at most (from mu ~ 1e-3 to 1e6 takes ~60).
constexpr double kGncFactor = 1.4;
constexpr int kGncMaxSteps = 80;
constexpr double kGncMaxMu = 1e6;
/// Gauss-Newton iterations per step (warm-started from the previous step's solution).
constexpr int kStepIterations = 5;
constexpr double kTolerance = 1e-6;

/// The truncated least squares weight of a residual chi-square r2 at control parameter mu.
double tlsWeight(double r2, double c2, double mu) {
  if (r2 >= (mu + 1.0) / mu * c2) return 0.0;
  if (r2 <= mu / (mu + 1.0) * c2) return 1.0;
  return std::min(1.0, std::max(0.0, std::sqrt(c2 * mu * (mu + 1.0) / r2) - mu));
}

constexpr size_t kNoEdge = std::numeric_limits<size_t>::max();

enum class Outcome { kOk, kFailed, kLate };

/// cg solved by least squares, then graduated non-convexity (truncated least squares) from that
/// solution on: the weights *w of the loop edges `edge` (kNoEdge: not in the graph). kFailed: a
/// solve failed; kLate: the budget ran out.
Outcome graduate(CondensedGraph& cg, const std::vector<size_t>& edge, double inlier_chi2,
                 const std::function<bool()>& late, std::vector<double>* w) {
  bool ok = false;
  cg.solve(4 * kStepIterations, kTolerance, &ok);
  if (late()) return Outcome::kLate;
  if (!ok) return Outcome::kFailed;
  double max_r2 = 0.0;
  for (size_t e : edge)
    if (e != kNoEdge) max_r2 = std::max(max_r2, cg.chi2(e));
  w->assign(edge.size(), 1.0);
  if (!(max_r2 > inlier_chi2)) return Outcome::kOk;
  double mu = inlier_chi2 / std::max(1e-9, 2.0 * max_r2 - inlier_chi2);
  for (int step = 0; step < kGncMaxSteps && ok; ++step) {
    bool binary = true;
    for (size_t k = 0; k < edge.size(); ++k) {
      if (edge[k] == kNoEdge) continue;
      (*w)[k] = tlsWeight(cg.chi2(edge[k]), inlier_chi2, mu);
      cg.setWeight(edge[k], (*w)[k]);
      binary = binary && ((*w)[k] < 1e-6 || (*w)[k] > 1.0 - 1e-6);
    }
    cg.solve(kStepIterations, kTolerance, &ok);
    if (late()) return Outcome::kLate;
    if ((binary && step > 0) || mu > kGncMaxMu) break;
    mu *= kGncFactor;
  }
  return ok ? Outcome::kOk : Outcome::kFailed;
}

/// An inlier loop (edge k of cg, from anchor gm to gq) against the others: cg solved without it,
/// its innovation's Mahalanobis distance and the largest position std of the relative pose
/// (r->d2, r->sigma; r->pinned when both are finite). pitch, roll: the match keyframe's.
Outcome leaveOneOut(const CondensedGraph& cg, size_t k, int gm, int gq, size_t anchors, double pitch, double roll,
                    const Eigen::Matrix4d& loop_cov, const std::function<bool()>& late, GlobalLoop* r) {
  CondensedGraph without = cg;
  without.setWeight(k, 0.0);
  bool solved = false;
  without.solve(2 * kStepIterations, kTolerance, &solved);
  if (late()) return Outcome::kLate;
  if (!solved) return Outcome::kOk;
  const Eigen::Vector4d nu = without.residual(k);  // prediction minus the candidate (yaw wrapped)
  for (size_t i = 0; i < anchors; ++i) without.setFixed(static_cast<int>(i), false);
  const Eigen::Matrix3d Rm = yawPitchRollToRotation(without.state(gm).yaw, pitch, roll);
  Eigen::Matrix4d C;
  if (!without.marginal(gm, gq, Rm, &C)) return Outcome::kOk;
  r->d2 = mahalanobis(nu, C + loop_cov);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C.topLeftCorner<3, 3>());
  r->sigma = std::sqrt(std::max(0.0, eig.eigenvalues().maxCoeff()));
  r->pinned = std::isfinite(r->d2) && std::isfinite(r->sigma);
  return Outcome::kOk;
}

}  // namespace

bool KeyframeGraph::Impl::globalGraph(int component, const std::vector<size_t>& matches,
                                      const std::vector<size_t>& queries, const std::vector<const LoopCandidate*>& loops,
                                      double variance_scale, CondensedGraph* cg, std::vector<size_t>* anchors,
                                      std::vector<size_t>* edge, size_t* chains) const {
  std::vector<size_t> extra;
  for (size_t k = 0; k < matches.size(); ++k) {
    extra.push_back(matches[k]);
    extra.push_back(queries[k]);
  }
  CondenseOptions options;
  options.variance_scale = variance_scale;
  if (!condense(component, extra, options, cg, anchors)) return false;
  const std::vector<size_t>& a = *anchors;
  // condense() adds the chains of odometry first, then the accepted loops.
  *chains = cg->edgeCount() - loopReps(component, 0, cfg.chi2.max_loop_anchors).size();
  bool any_fixed = false;
  for (size_t p : a) any_fixed = any_fixed || kfs[p].sequence == 0;
  if (!any_fixed) cg->setFixed(0, true);  // the oldest anchor holds the gauge
  auto id = [&](size_t p) { return static_cast<int>(std::lower_bound(a.begin(), a.end(), p) - a.begin()); };
  const Eigen::Matrix4d loop_cov = loopCovariance();
  edge->assign(loops.size(), kNoEdge);
  for (size_t k = 0; k < loops.size(); ++k) {
    CondensedEdge e;
    e.from = id(matches[k]);
    e.to = id(queries[k]);
    e.t = loops[k]->relative_t;
    e.yaw = loops[k]->relative_yaw;
    e.covariance = loop_cov;
    if (cg->addEdge(e)) (*edge)[k] = cg->edgeCount() - 1;
  }
  return true;
}

bool KeyframeGraph::globalConsistency(const std::vector<LoopCandidate>& candidates, double inlier_chi2,
                                      double tear_chi2, double variance_scale, const std::vector<bool>& test_alone,
                                      std::vector<GlobalLoop>* out, std::chrono::steady_clock::time_point deadline,
                                      bool* timed_out) const {
  const Impl& m = *impl_;
  out->assign(candidates.size(), GlobalLoop());
  if (timed_out) *timed_out = false;
  // The budget (Verifier::globalPass): checked after every solve, the largest steps of a pass.
  const std::function<bool()> late = [&]() {
    if (deadline == std::chrono::steady_clock::time_point::max() || std::chrono::steady_clock::now() < deadline)
      return false;
    if (timed_out) *timed_out = true;
    return true;
  };
  struct Ends {
    size_t i, match, query;
  };
  std::map<int, std::vector<Ends>> by_component;
  for (size_t i = 0; i < candidates.size(); ++i) {
    size_t q = 0, mp = 0;
    if (!find(candidates[i].query_index, &q) || !find(candidates[i].match_index, &mp) || mp >= q) continue;
    const int comp = m.componentOf(q);
    if (m.componentOf(mp) != comp) continue;
    by_component[comp].push_back({i, mp, q});
  }
  bool all_ok = true;
  const Eigen::Matrix4d loop_cov = m.loopCovariance();
  for (const auto& kv : by_component) {
    const std::vector<Ends>& ends = kv.second;
    std::vector<size_t> matches, queries;
    std::vector<const LoopCandidate*> loops;
    for (const Ends& e : ends) {
      matches.push_back(e.match);
      queries.push_back(e.query);
      loops.push_back(&candidates[e.i]);
    }
    CondensedGraph cg;
    std::vector<size_t> a, edge;
    size_t chains = 0;
    if (!m.globalGraph(kv.first, matches, queries, loops, variance_scale, &cg, &a, &edge, &chains)) {
      all_ok = false;
      continue;
    }
    auto id = [&](size_t p) { return static_cast<int>(std::lower_bound(a.begin(), a.end(), p) - a.begin()); };
    // Least squares, then graduated non-convexity from its solution on.
    std::vector<double> w;
    const Outcome graduated = graduate(cg, edge, inlier_chi2, late, &w);
    if (graduated == Outcome::kLate) return false;
    if (graduated == Outcome::kFailed) {
      all_ok = false;
      continue;
    }
    // Where the solution tears the odometry: chains bent beyond tear_chi2 (a row of look-alikes
    // that agree with each other is absorbed by the odometry, whose loss is not robust).
    std::vector<bool> torn(chains, false);
    for (size_t e = 0; e < chains; ++e) torn[e] = !(cg.chi2(e) <= tear_chi2);
    // Inliers, each against the others (leave one out).
    for (size_t k = 0; k < ends.size(); ++k) {
      if (edge[k] == kNoEdge) continue;
      GlobalLoop& r = (*out)[ends[k].i];
      r.chi2 = cg.chi2(edge[k]);
      r.inlier = w[k] > 0.5 && r.chi2 <= inlier_chi2;
      if (!r.inlier) continue;
      // Its cycle: the chains between its ends along one segment; across segments, any chain.
      const bool one_segment = m.kfs[ends[k].match].segment == m.kfs[ends[k].query].segment;
      const int gm = id(ends[k].match), gq = id(ends[k].query);
      for (size_t e = 0; e < chains && !r.torn; ++e) {
        if (!torn[e]) continue;
        const CondensedEdge& ce = cg.edge(e);
        r.torn = !one_segment || (ce.from >= gm && ce.to <= gq);
      }
      if (r.torn || (!test_alone.empty() && !test_alone[ends[k].i])) continue;
      const Impl::Keyframe& km = m.kfs[ends[k].match];
      if (leaveOneOut(cg, edge[k], gm, gq, a.size(), km.pitch, km.roll, loop_cov, late, &r) == Outcome::kLate)
        return false;
    }
  }
  return all_ok;
}

}  // namespace core
}  // namespace rover_loop_fusion
