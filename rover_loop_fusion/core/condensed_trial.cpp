// The condensed graph (core/condensed.h) of one component of the pose graph: the accepted
// loops as representative edges (merged within a revisit, capped), the chains of odometry
// between anchors from the prefix moments (core/drift.h), new anchor states spread back onto
// every keyframe (the chi2 estimate), and the condensed trial (condense_min_window): a window
// solved on its anchors under loop_fusion's unit weighting, its keyframes placed by each
// chain's conditional mean (expand) for scoring and adoption. 4-DoF here; the 6-DoF graph and
// trial: condensed_trial6.cpp.
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <sstream>
#include <tuple>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

namespace {
/// Loops whose query and match are each within this many keyframes of the first loop of a
/// cluster join it: one edge in the condensed graph (the middle loop, with the information of
/// all of them). A long revisit becomes one edge per kMergeKeyframes.
constexpr size_t kMergeKeyframes = 10;
/// Chain edges kept for the next condensed graphs at most (condense(); ~330 bytes each): a
/// whole-run trial has up to 2 trial_loop_anchors + 3 of them.
constexpr size_t kChainEdgeCache = 8192;
/// A commit re-places the keyframes of a chain only if one of its ends moved more than this.
constexpr double kSpreadTranslation = 1e-4;  // m
constexpr double kSpreadYaw = 1e-6;          // rad
/// A condensed trial has converged when no anchor moves by more than this in an iteration
/// (metres; radians for yaw).
constexpr double kCondensedTolerance = 1e-6;
/// A trial's Gauss-Newton reuses its last factorisation while the steps at least halve
/// (CondensedGraph::solve's chord): the robust loops' reweighting converges linearly anyway,
/// and a whole-run trial factorises once or twice instead of four or five times.
constexpr double kTrialChord = 0.5;
/// A condensed trial's solution: the solved anchors from the window's head on, and its summary
/// (all but the time).
void condensedSolution(size_t head, int component, const std::vector<size_t>& anchors,
                       const std::vector<KeyframeState>& solved, int iterations, bool converged, size_t window,
                       size_t edges, TrialSolution* out) {
  out->condensed = true;
  out->first = head;
  out->component = component;
  out->positions.clear();
  out->states.clear();
  for (size_t i = 0; i < anchors.size(); ++i) {
    if (anchors[i] < head) continue;  // held fixed outside the window
    out->positions.push_back(anchors[i]);
    out->states.push_back(solved[i]);
  }
  SolveSummary& o = out->summary;
  o.iterations = iterations;
  o.converged = converged;
  o.finite = true;
  for (const KeyframeState& st : out->states)
    if (!std::isfinite(st.t[0] + st.t[1] + st.t[2] + st.yaw + st.q[0] + st.q[1] + st.q[2] + st.q[3])) o.finite = false;
  std::ostringstream msg;
  msg << "condensed trial of " << window << " keyframes: " << anchors.size() << " anchors, " << edges
      << " edges; scored on evenly spaced keyframes";
  o.message = msg.str();
}

}  // namespace

// ---- the condensed graph of a component ------------------------------------------------

Eigen::Matrix4d KeyframeGraph::Impl::unitLoopCovariance() const {
  Eigen::Matrix4d C = Eigen::Matrix4d::Identity();
  const double yaw = 1.0 / (kYawResidualScale * kLoopYawWeight);
  C(3, 3) = yaw * yaw;
  return C;
}

double KeyframeGraph::Impl::stepStiffness() const {
  double stiffness = 0.0;
  for (int k = 1; k <= cfg.trial.odometry_neighbours; ++k) stiffness += k * k;
  return stiffness;
}

Eigen::Matrix4d KeyframeGraph::Impl::unitStepCovariance() const {
  Eigen::Matrix4d C = Eigen::Matrix4d::Identity() / stepStiffness();
  C(3, 3) /= kYawResidualScale * kYawResidualScale;
  return C;
}

std::vector<KeyframeGraph::Impl::LoopRep> KeyframeGraph::Impl::loopReps(int component, size_t first, int cap) const {
  if (reps_revision != revision) {
    reps_cache.clear();
    reps_revision = revision;
  }
  const auto key = std::make_tuple(component, first, cap);
  auto it = reps_cache.find(key);
  if (it == reps_cache.end()) {
    if (reps_cache.size() > 64) reps_cache.clear();  // trials of many windows between two loops
    it = reps_cache.emplace(key, computeLoopReps(component, first, cap)).first;
  }
  return it->second;
}

std::vector<KeyframeGraph::Impl::LoopRep> KeyframeGraph::Impl::computeLoopReps(int component, size_t first,
                                                                               int cap_loops) const {
  std::vector<const Edge*> in;
  for (const Edge& e : loops)
    if (e.to >= first && componentOf(e.to) == component) in.push_back(&e);
  std::sort(in.begin(), in.end(), [](const Edge* a, const Edge* b) { return a->to < b->to; });
  std::vector<std::vector<const Edge*>> clusters;
  for (const Edge* e : in) {
    if (!clusters.empty()) {
      const Edge* head = clusters.back().front();  // a cluster spans at most kMergeKeyframes
      const size_t dq = e->to - head->to;
      const size_t dm = e->from > head->from ? e->from - head->from : head->from - e->from;
      if (dq <= kMergeKeyframes && dm <= kMergeKeyframes) {
        clusters.back().push_back(e);
        continue;
      }
    }
    clusters.push_back({e});
  }
  std::vector<LoopRep> reps;
  for (const auto& cl : clusters) {
    const Edge* mid = cl[cl.size() / 2];
    reps.push_back(LoopRep{mid->from, mid->to, &mid->loop, static_cast<int>(cl.size())});
  }
  const size_t cap = static_cast<size_t>(std::max(2, cap_loops));
  if (reps.size() > cap) {
    const size_t keep_new = cap / 2, keep_old = cap - keep_new;
    const size_t n_old = reps.size() - keep_new;
    std::vector<LoopRep> thinned;
    for (size_t i = 0; i < keep_old; ++i) {
      const size_t k = keep_old == 1 ? 0 : (i * (n_old - 1)) / (keep_old - 1);
      if (thinned.empty() || thinned.back().to != reps[k].to) thinned.push_back(reps[k]);
    }
    thinned.insert(thinned.end(), reps.end() - keep_new, reps.end());
    reps.swap(thinned);
  }
  return reps;
}

std::vector<KeyframeGraph::Impl::LoopRep> KeyframeGraph::Impl::condensedAnchors(int component,
                                                                                const std::vector<size_t>& extra,
                                                                                const CondenseOptions& o,
                                                                                std::vector<size_t>* anchors) const {
  std::vector<LoopRep> reps = o.trial ? loopReps(component, o.first, cfg.trial.trial_loop_anchors)
                                      : loopReps(component, 0, cfg.chi2.max_loop_anchors);
  std::vector<size_t>& a = *anchors;
  a = extra;
  for (const LoopRep& r : reps) {
    a.push_back(r.from);
    a.push_back(r.to);
  }
  std::sort(a.begin(), a.end());
  a.erase(std::unique(a.begin(), a.end()), a.end());
  return reps;
}

bool KeyframeGraph::Impl::condense(int component, const std::vector<size_t>& extra, const CondenseOptions& o,
                                   CondensedGraph* cg, std::vector<size_t>* anchors) const {
  const std::vector<LoopRep> reps = condensedAnchors(component, extra, o, anchors);
  const std::vector<size_t>& a = *anchors;
  for (size_t p : a) {
    AnchorState st;
    st.p = Eigen::Vector3d(x[p].t[0], x[p].t[1], x[p].t[2]);
    st.yaw = x[p].yaw;
    cg->addAnchor(st, kfs[p].pitch, kfs[p].roll, kfs[p].sequence == 0 || (o.trial && p <= o.first));
  }
  auto id = [&](size_t p) { return static_cast<int>(std::lower_bound(a.begin(), a.end(), p) - a.begin()); };
  for (size_t i = 1; i < a.size(); ++i) {
    const Keyframe& ka = kfs[a[i - 1]];
    const Keyframe& kb = kfs[a[i]];
    if (ka.segment != kb.segment || (o.trial && a[i - 1] < o.first)) continue;
    const ChainEdgeKey key(a[i - 1], a[i], o.trial, o.trial ? 0.0 : o.variance_scale);
    auto cached = chain_edges.find(key);
    if (cached == chain_edges.end()) {
      SequenceChain& ch = chains.at(ka.segment);
      ChainEdge c;
      const Eigen::Matrix3d Ra = ka.vio.q.toRotationMatrix();
      c.t = Ra.transpose() * (kb.vio.t - ka.vio.t);
      c.yaw = wrapAngle(kb.yaw - ka.yaw);
      c.covariance = o.trial ? unitOf(ch).relative(a[i - 1] - ch.start, a[i] - ch.start, Ra)
                             : o.variance_scale * momentsOf(ch).relative(a[i - 1] - ch.start, a[i] - ch.start, Ra);
      if (!CondensedGraph::sqrtInformation(c.covariance, &c.sqrt_info)) return false;
      if (chain_edges.size() >= kChainEdgeCache) chain_edges.clear();
      cached = chain_edges.emplace(key, c).first;
    }
    CondensedEdge e;
    e.from = static_cast<int>(i - 1);
    e.to = static_cast<int>(i);
    e.t = cached->second.t;
    e.yaw = cached->second.yaw;
    e.covariance = cached->second.covariance;
    cg->addEdge(e, cached->second.sqrt_info);
  }
  const Eigen::Matrix4d L = o.trial ? unitLoopCovariance() : loopCovariance();
  for (const LoopRep& r : reps) {
    CondensedEdge e;
    e.from = id(r.from);
    e.to = id(r.to);
    e.t = r.loop->relative_t;
    e.yaw = r.loop->relative_yaw;
    e.covariance = L / r.count;
    e.count = r.count;
    if (o.trial) e.huber = cfg.trial.loop_huber;
    if (!cg->addEdge(e)) return false;
  }
  return true;
}

void KeyframeGraph::Impl::spread(int component, const std::vector<size_t>& anchors, const CondensedGraph& cg) {
  auto stateOf = [&](int i) {
    KeyframeState s = x[anchors[i]];
    const AnchorState& a = cg.state(i);
    for (int k = 0; k < 3; ++k) s.t[k] = a.p[k];
    setYaw(s, a.yaw);
    return s;
  };
  auto rigid = [&](size_t from, size_t to, size_t anchor, const KeyframeState& now) {
    const Correction c = correctionBetween(x[anchor], now, kfs[anchor]);
    for (size_t p = from; p < to; ++p) x[p] = applyCorrection(c, x[p], kfs[p]);
  };
  for (auto& kv : chains) {
    const int seg = kv.first;
    SequenceChain& ch = kv.second;
    if (componentOf(ch.start) != component) continue;
    const size_t end = ch.start + ch.count;
    std::vector<int> in;  // anchor indices in this segment
    for (size_t i = 0; i < anchors.size(); ++i)
      if (kfs[anchors[i]].segment == seg) in.push_back(static_cast<int>(i));
    if (in.empty()) continue;
    std::vector<KeyframeState> now(in.size());
    std::vector<bool> moved(in.size());
    for (size_t j = 0; j < in.size(); ++j) {
      now[j] = stateOf(in[j]);
      const KeyframeState& old = x[anchors[in[j]]];
      moved[j] = std::abs(wrapAngle(now[j].yaw - old.yaw)) > kSpreadYaw ||
                 (Eigen::Vector3d(now[j].t[0] - old.t[0], now[j].t[1] - old.t[1], now[j].t[2] - old.t[2])).norm() > kSpreadTranslation;
    }
    if (moved.front()) rigid(ch.start, anchors[in.front()], anchors[in.front()], now.front());
    if (moved.back()) rigid(anchors[in.back()] + 1, end, anchors[in.back()], now.back());
    for (size_t j = 0; j + 1 < in.size(); ++j) {
      const size_t pa = anchors[in[j]], pb = anchors[in[j + 1]];
      // A chain whose ends (nearly) stayed keeps its keyframes: far from a new loop, the
      // estimate barely changes, and this keeps a commit from costing O(keyframes).
      if (pb > pa + 1 && (moved[j] || moved[j + 1])) {
        // Rigid prediction from a's new state, plus the chain's share of the gap at b.
        const KeyframeState& na = now[j];
        const KeyframeState& nb = now[j + 1];
        const double dyaw = wrapAngle(na.yaw - kfs[pa].yaw);
        const Eigen::Matrix3d Rd = yawPitchRollToRotation(dyaw, 0, 0);
        const Eigen::Vector3d Pa(na.t[0], na.t[1], na.t[2]), Pb(nb.t[0], nb.t[1], nb.t[2]);
        Eigen::Vector4d gap;
        gap.head<3>() = Rd.transpose() * (Pb - (Pa + Rd * (kfs[pb].vio.t - kfs[pa].vio.t)));
        gap[3] = wrapAngle(nb.yaw - (kfs[pb].yaw + dyaw));
        const size_t la = pa - ch.start, lb = pb - ch.start;
        const ChainMomentsView moments = momentsOf(ch);
        const ChainMoments::Sums prefix_a = moments.prefix(la);
        const Eigen::Matrix4d Cbb = moments.cross(prefix_a, la, lb, lb);
        const Eigen::Vector4d w = Cbb.ldlt().solve(gap);
        for (size_t p = pa + 1; p < pb; ++p) {
          const Eigen::Vector4d corr = moments.cross(prefix_a, la, p - ch.start, lb) * w;
          const Eigen::Vector3d t = Pa + Rd * (kfs[p].vio.t - kfs[pa].vio.t) + Rd * corr.head<3>();
          KeyframeState& s = x[p];
          for (int k = 0; k < 3; ++k) s.t[k] = t[k];
          setYaw(s, wrapAngle(kfs[p].yaw + dyaw + corr[3]));
        }
      }
    }
    for (size_t j = 0; j < in.size(); ++j) x[anchors[in[j]]] = now[j];
  }
}

// ---- condensed trials (condense_min_window) --------------------------------------------

bool KeyframeGraph::Impl::solveCondensed(size_t first, int component, const std::vector<TrialLoop>& loops,
                                         bool robust_candidate, int max_iterations, TrialSolution* out) const {
  const auto t0 = Clock::now();
  // The window's first keyframe of the component is held fixed, as in the full trial.
  size_t head = first;
  while (head < kfs.size() && componentOf(head) != component) ++head;
  for (const TrialLoop& l : loops)
    if (head > l.match_pos) return false;
  CondenseOptions options;
  options.trial = true;
  options.first = head;
  std::vector<size_t> extra = {head};
  for (const TrialLoop& l : loops) {
    extra.push_back(l.match_pos);
    extra.push_back(l.query_pos);
  }
  std::vector<size_t> anchors;
  auto anchorOf = [&](size_t p) {
    return static_cast<int>(std::lower_bound(anchors.begin(), anchors.end(), p) - anchors.begin());
  };
  std::vector<KeyframeState> solved;  // per anchor
  int iterations = 0;
  bool ok = false, converged = false;
  size_t edges = 0;
  // The candidates' loops as edges (loopEdge: the measurement and covariance), the solve, and
  // every anchor's new state (stateOf(cg, i)); false if an edge was unusable.
  auto solveOn = [&](auto& cg, auto loopEdge, auto stateOf) {
    for (const TrialLoop& l : loops) {
      if (!l.candidate) continue;
      auto e = loopEdge(*l.candidate);
      e.from = anchorOf(l.match_pos);
      e.to = anchorOf(l.query_pos);
      if (robust_candidate) e.huber = cfg.trial.loop_huber;
      if (!cg.addEdge(e)) return false;
    }
    iterations = cg.solve(std::max(1, max_iterations), kCondensedTolerance, &ok, &converged, cfg.trial.function_tolerance,
                          kTrialChord);
    for (size_t i = 0; ok && i < anchors.size(); ++i) solved.push_back(stateOf(cg, static_cast<int>(i)));
    edges = cg.edgeCount();
    return true;
  };
  if (fourDof()) {
    CondensedGraph cg;
    if (!condense(component, extra, options, &cg, &anchors)) return false;
    const bool built = solveOn(
        cg,
        [&](const LoopCandidate& c) {
          CondensedEdge e;
          e.t = c.relative_t;
          e.yaw = c.relative_yaw;
          e.covariance = unitLoopCovariance();
          return e;
        },
        [&](const CondensedGraph& g, int i) {
          KeyframeState st = x[anchors[i]];
          for (int k = 0; k < 3; ++k) st.t[k] = g.state(i).p[k];
          st.yaw = g.state(i).yaw;
          return st;
        });
    if (!built) return false;
  } else {
    CondensedGraph6 cg;
    if (!condense6(component, extra, options, &cg, &anchors)) return false;
    const bool built = solveOn(
        cg,
        [&](const LoopCandidate& c) {
          CondensedEdge6 e;
          e.t = c.relative_t;
          e.q = c.relative_q;
          e.covariance = unitLoopCovariance6();
          return e;
        },
        [&](const CondensedGraph6& g, int i) { return stateWithPose(x[anchors[i]], g.state(i).p, g.state(i).q); });
    if (!built) return false;
  }
  if (!ok) return false;
  condensedSolution(head, component, anchors, solved, iterations, converged, kfs.size() - head, edges, out);
  out->summary.solve_ms = msSince(t0);
  return true;
}

std::vector<std::pair<size_t, size_t>> KeyframeGraph::Impl::windowRanges(const TrialSolution& s,
                                                                         bool skip_fixed_map) const {
  std::vector<std::pair<size_t, size_t>> out;
  for (const auto& kv : chains) {
    const SequenceChain& ch = kv.second;
    const size_t end = ch.start + ch.count;
    if (end <= s.first || componentOf(ch.start) != s.component) continue;
    if (skip_fixed_map && kfs[ch.start].sequence == 0) continue;
    out.emplace_back(std::max(ch.start, s.first), end);
  }
  return out;
}

std::vector<size_t> KeyframeGraph::Impl::windowPositions(const TrialSolution& s, size_t stride,
                                                         bool skip_fixed_map) const {
  std::vector<size_t> out;
  size_t k = 0;  // keyframes counted over the ranges before this one
  for (const auto& range : windowRanges(s, skip_fixed_map)) {
    for (size_t p = range.first + (stride - k % stride) % stride; p < range.second; p += stride) out.push_back(p);
    k += range.second - range.first;
  }
  std::sort(out.begin(), out.end());
  return out;
}

/// The 4-DoF chain model's conditional mean: per chain, the weights of the gap at its end.
class KeyframeGraph::Impl::FourDofPlacer : public ChainPlacer {
 public:
  FourDofPlacer(const Impl& m, const TrialSolution& s) : m_(m), s_(s) {}

  KeyframeState place(size_t i, size_t p, bool position_only) override {
    const std::vector<size_t>& a = s_.positions;
    const auto& x = m_.x;
    const auto& kfs = m_.kfs;
    const size_t pa = a[i], pb = a[i + 1];
    auto& ch = m_.chains.at(kfs[p].segment);
    const size_t la = pa - ch.start, lb = pb - ch.start;
    ChainFit& f = fits_[i];
    if (!f.ready) {
      // The rigid move of a's correction, plus the chain's share of what is left at b
      // (expressed in the VIO frame of the moments: M maps it into the solution's).
      const KeyframeState& na = s_.states[i];
      const KeyframeState& nb = s_.states[i + 1];
      f.dyaw = wrapAngle(na.yaw - x[pa].yaw);
      f.D = yawPitchRollToRotation(f.dyaw, 0, 0);
      f.M = f.D * yawPitchRollToRotation(wrapAngle(x[pa].yaw - kfs[pa].yaw), 0, 0);
      const Eigen::Vector3d xa(x[pa].t[0], x[pa].t[1], x[pa].t[2]), xb(x[pb].t[0], x[pb].t[1], x[pb].t[2]);
      const Eigen::Vector3d Pa(na.t[0], na.t[1], na.t[2]), Pb(nb.t[0], nb.t[1], nb.t[2]);
      Eigen::Vector4d gap;
      gap.head<3>() = f.M.transpose() * (Pb - (Pa + f.D * (xb - xa)));
      gap[3] = wrapAngle(nb.yaw - x[pb].yaw - f.dyaw);
      f.unit.reset(new ChainMomentsView(m_.unitOf(ch)));
      f.prefix_a = f.unit->prefix(la);
      f.w = f.unit->cross(f.prefix_a, la, lb, lb).ldlt().solve(gap);
      f.ready = true;
    }
    const Eigen::Vector4d corr = f.unit->cross(f.prefix_a, la, p - ch.start, lb) * f.w;
    const KeyframeState& na = s_.states[i];
    const Eigen::Vector3d xa(x[pa].t[0], x[pa].t[1], x[pa].t[2]), xp(x[p].t[0], x[p].t[1], x[p].t[2]);
    const Eigen::Vector3d t = Eigen::Vector3d(na.t[0], na.t[1], na.t[2]) + f.D * (xp - xa) + f.M * corr.head<3>();
    KeyframeState st = x[p];
    for (int k = 0; k < 3; ++k) st.t[k] = t[k];
    if (!position_only) st.yaw = wrapAngle(x[p].yaw + f.dyaw + corr[3]);
    return st;
  }

 private:
  struct ChainFit {
    bool ready = false;
    double dyaw = 0;
    Eigen::Matrix3d D, M;
    Eigen::Vector4d w;
    ChainMoments::Sums prefix_a;  // the chain's moments up to a, for every keyframe placed
    std::unique_ptr<ChainMomentsView> unit;  // the chain's unit moments (unitOf once, not per keyframe placed)
  };
  const Impl& m_;
  const TrialSolution& s_;
  std::map<size_t, ChainFit> fits_;
};

std::unique_ptr<KeyframeGraph::Impl::ChainPlacer> KeyframeGraph::Impl::chainPlacer4(const TrialSolution& s) const {
  return std::unique_ptr<ChainPlacer>(new FourDofPlacer(*this, s));
}

std::vector<KeyframeState> KeyframeGraph::Impl::expand(const TrialSolution& s, const std::vector<size_t>& targets,
                                                       bool position_only) const {
  const std::vector<size_t>& a = s.positions;
  std::vector<KeyframeState> out;
  out.reserve(targets.size());
  const std::unique_ptr<ChainPlacer> between = fourDof() ? chainPlacer4(s) : chainPlacer6(s);
  auto rigid = [&](size_t anchor_i, size_t p) {
    const Correction c = correctionBetween(x[a[anchor_i]], s.states[anchor_i], kfs[a[anchor_i]]);
    return applyCorrection(c, x[p], kfs[p]);
  };
  for (size_t p : targets) {
    const size_t i = std::upper_bound(a.begin(), a.end(), p) - a.begin();  // anchors [0, i) are <= p
    const bool left = i > 0 && kfs[a[i - 1]].segment == kfs[p].segment;
    const bool right = i < a.size() && kfs[a[i]].segment == kfs[p].segment;
    if (left && a[i - 1] == p) {
      out.push_back(s.states[i - 1]);
    } else if (left && right) {
      out.push_back(between->place(i - 1, p, position_only));
    } else if (left) {
      out.push_back(rigid(i - 1, p));
    } else if (right) {
      out.push_back(rigid(i, p));
    } else {
      out.push_back(x[p]);
    }
  }
  return out;
}

}  // namespace core
}  // namespace rover_loop_fusion
