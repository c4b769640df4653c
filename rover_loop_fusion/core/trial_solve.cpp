// Trials of the pose graph (KeyframeGraph::solveWindow, scoredPositions, adopt): the Ceres
// problem over a window [match - window_margin, newest] of the query's component, warm-started
// from X, with the candidate as an extra loop edge; its solve within a time budget (the
// deadline callback and the learnt cost per keyframe: core/trial_budget.h); the scoring
// positions; and X := a solution. Windows above condense_min_window go to the condensed trial
// (core/condensed_trial.cpp) first.
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/geometry.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>

namespace rover_loop_fusion {
namespace core {

void KeyframeGraph::Impl::addBlocks(Trial& tr, KeyframeState& s, bool constant) {
  if (fourDof()) {
    tr.problem.AddParameterBlock(&s.yaw, 1);
    compat::setManifold(tr.problem, &s.yaw, angle_manifold.get());
  } else {
    tr.problem.AddParameterBlock(s.q, 4);
    compat::setManifold(tr.problem, s.q, quaternion_manifold.get());
  }
  tr.problem.AddParameterBlock(s.t, 3);
  if (constant) {
    tr.problem.SetParameterBlockConstant(fourDof() ? &s.yaw : s.q);
    tr.problem.SetParameterBlockConstant(s.t);
  }
}

KeyframeState* KeyframeGraph::Impl::stateFor(Trial& tr, size_t p) {
  if (p >= tr.first && tr.local[p - tr.first] >= 0) return &tr.states[tr.local[p - tr.first]];
  tr.constants.push_back(x[p]);
  KeyframeState* s = &tr.constants.back();
  addBlocks(tr, *s, true);
  return s;
}

void KeyframeGraph::Impl::addEdge(Trial& tr, size_t from, size_t to, ceres::CostFunction* cost,
                                  ceres::LossFunction* loss) {
  KeyframeState* a = stateFor(tr, from);
  KeyframeState* b = stateFor(tr, to);
  tr.problem.AddResidualBlock(cost, loss, rotBlock(*a), a->t, rotBlock(*b), b->t);
}

void KeyframeGraph::Impl::buildTrial(Trial& tr, size_t first, int component, bool from_vio,
                                     const std::vector<Edge>& extra, ceres::LossFunction* extra_loss) {
  tr.first = first;
  tr.local.assign(kfs.size() - first, -1);
  for (size_t p = first; p < kfs.size(); ++p) {
    if (component != kEverySegment && root(kfs[p].segment) != component) continue;
    tr.local[p - first] = static_cast<int>(tr.positions.size());
    tr.positions.push_back(p);
    tr.states.push_back(from_vio ? stateFromPose(kfs[p].vio) : x[p]);
  }
  for (size_t i = 0; i < tr.positions.size(); ++i)
    addBlocks(tr, tr.states[i], i == 0 || kfs[tr.positions[i]].sequence == 0);
  auto inWindow = [&](size_t p) { return p >= first && tr.local[p - first] >= 0; };
  auto firstOdom = std::lower_bound(odometry.begin(), odometry.end(), first,
                                    [](const OdometryEdge& e, size_t f) { return e.to < f; });
  for (auto it = firstOdom; it != odometry.end(); ++it) {
    if (!inWindow(it->from) || !inWindow(it->to)) continue;
    tr.costs.push_back(odometryCost(*it));
    addEdge(tr, it->from, it->to, tr.costs.back().get(), nullptr);
  }
  for (const Edge& e : loops) {
    if (inWindow(e.to)) addEdge(tr, e.from, e.to, e.cost.get(), huber.get());
  }
  for (const Edge& e : extra) addEdge(tr, e.from, e.to, e.cost.get(), extra_loss);
}

SolveSummary KeyframeGraph::Impl::solve(Trial& tr, int max_iterations, double time_budget_ms,
                                    Clock::time_point start, DeadlineCallback* callback) {
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = std::max(1, max_iterations);
  if (time_budget_ms > 0) {
    options.max_solver_time_in_seconds = std::max(0.0, time_budget_ms - msSince(start)) / 1000.0;
    if (callback) options.callbacks.push_back(callback);
    options.update_state_every_iteration = true;  // a stopped solve keeps its last iterate
  }
  options.num_threads = 1;
  options.function_tolerance = cfg.trial.function_tolerance;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  const auto t0 = Clock::now();
  ceres::Solve(options, &tr.problem, &summary);
  ++solves;
  SolveSummary o;
  o.solve_ms = msSince(t0);
  // summary.iterations holds iteration 0 (the initial evaluation) too.
  o.iterations = std::max(0, static_cast<int>(summary.iterations.size()) - 1);
  o.converged = summary.termination_type == ceres::CONVERGENCE;
  const bool stopped = callback && !callback->stop_reason.empty();
  o.timed_out = stopped || (summary.termination_type == ceres::NO_CONVERGENCE && time_budget_ms > 0 &&
                            summary.message.find("time") != std::string::npos);
  o.message = stopped ? callback->stop_reason : summary.message;
  o.finite = true;
  if (!fourDof())  // the yaw of a 6-DoF state follows its q (setYaw)
    for (KeyframeState& s : tr.states)
      s.yaw = rotationToYawPitchRoll(
          Eigen::Quaterniond(s.q[0], s.q[1], s.q[2], s.q[3]).normalized().toRotationMatrix())[0];
  for (const KeyframeState& s : tr.states) {
    if (!std::isfinite(s.t[0]) || !std::isfinite(s.t[1]) || !std::isfinite(s.t[2]) ||
        !std::isfinite(s.yaw) || !std::isfinite(s.q[0] + s.q[1] + s.q[2] + s.q[3])) {
      o.finite = false;
      break;
    }
  }
  return o;
}

void KeyframeGraph::Impl::learnCost(size_t window, double total_ms, const DeadlineCallback& callback) {
  if (window < 500 || callback.longest_ms <= 0) return;
  setup_cost.learn(std::max(0.0, total_ms - callback.iterations_ms) / window);
  iteration_cost.learn(callback.longest_ms / window);
}

size_t KeyframeGraph::Impl::windowStart(size_t match_pos) const {
  const size_t margin = static_cast<size_t>(std::max(0, cfg.trial.window_margin));
  return match_pos > margin ? match_pos - margin : 0;
}

void KeyframeGraph::Impl::adopt(const std::vector<size_t>& positions,
                            const std::vector<KeyframeState>& states) {
  if (positions.empty()) return;
  const size_t last = positions.back();
  const Correction c = correctionBetween(x[last], states.back(), kfs[last]);
  for (size_t i = 0; i < positions.size(); ++i) x[positions[i]] = states[i];
  const int comp = root(kfs[last].segment);
  for (size_t p = last + 1; p < kfs.size(); ++p) {
    if (root(kfs[p].segment) == comp) x[p] = applyCorrection(c, x[p], kfs[p]);
  }
}

// ---------------------------------------------------------------------------------------

TrialSolution KeyframeGraph::solveWindow(size_t mpos, size_t qpos, const LoopCandidate* candidate,
                                         bool robust_candidate, int max_iterations, double time_budget_ms,
                                         int condense_min_window) {
  TrialLoop loop;
  loop.match_pos = mpos;
  loop.query_pos = qpos;
  loop.candidate = candidate;
  return impl_->solveTrial({loop}, robust_candidate, max_iterations, time_budget_ms, condense_min_window);
}

TrialSolution KeyframeGraph::solveWindow(const std::vector<LoopCandidate>& candidates, bool robust_candidate,
                                         int max_iterations, double time_budget_ms) {
  std::vector<TrialLoop> loops;
  for (const LoopCandidate& c : candidates) {
    TrialLoop l;
    if (!impl_->find(c.query_index, &l.query_pos) || !impl_->find(c.match_index, &l.match_pos)) continue;
    l.candidate = &c;
    loops.push_back(l);
  }
  if (loops.empty()) {
    TrialSolution out;
    out.summary.message = "no candidate of the trial is in the graph";
    return out;
  }
  return impl_->solveTrial(loops, robust_candidate, max_iterations, time_budget_ms, -1);
}

TrialSolution KeyframeGraph::Impl::solveTrial(const std::vector<TrialLoop>& loops, bool robust_candidate,
                                              int max_iterations, double time_budget_ms, int condense_min_window) {
  const auto start = Clock::now();
  Impl& m = *this;
  TrialSolution out;
  // The window from the earliest match on; the component of the last query.
  size_t mpos = loops.front().match_pos;
  for (const TrialLoop& l : loops) mpos = std::min(mpos, l.match_pos);
  const size_t qpos = loops.back().query_pos;
  const size_t first = m.windowStart(mpos);
  const size_t window = m.kfs.size() - first;  // the trial's keyframes, at most
  const int condense_above = condense_min_window >= 0 ? condense_min_window : m.cfg.trial.condense_min_window;
  if (m.condensable() && condense_above > 0 && window > static_cast<size_t>(condense_above) &&
      m.solveCondensed(first, m.root(m.kfs[qpos].segment), loops, robust_candidate, max_iterations, &out))
    return out;
  out = TrialSolution();
  const double first_iteration_ms = window * m.iteration_cost.predict();
  const double solve_budget_ms = (1.0 - kBudgetAfterSolve) * time_budget_ms;
  if (time_budget_ms > 0) {
    // Neither building the problem nor one Ceres iteration can be interrupted: a trial that
    // cannot reach the end of its first iteration within the budget is not started.
    const double predicted = window * m.setup_cost.predict() + first_iteration_ms;
    if (predicted > solve_budget_ms) {
      std::ostringstream s;
      s.precision(3);
      s << "not started: a trial over " << window << " keyframes would need ~" << predicted
        << " ms to the end of its first iteration (" << 1e3 * predicted / window << " us per keyframe, "
        << (m.iteration_cost.measured ? "measured on this graph's solves" : "a cautious guess before the first solve")
        << "), more than the " << solve_budget_ms << " ms left for the solve";
      out.summary.timed_out = true;
      out.summary.finite = true;
      out.summary.message = s.str();
      // A refusal measures nothing: without this, one slow solve (a load spike) would keep
      // every trial of its size out for good. Halving the deviations lets a trial that fits
      // the average be tried again after a few refusals.
      m.setup_cost.deviation *= 0.5;
      m.iteration_cost.deviation *= 0.5;
      return out;
    }
  }
  std::vector<Edge> extra;
  for (const TrialLoop& l : loops) {
    if (!l.candidate) continue;
    Edge e;
    e.from = l.match_pos;
    e.to = l.query_pos;
    e.loop = *l.candidate;
    m.setLoopCost(e);
    extra.push_back(e);
  }
  DeadlineCallback callback(start + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double, std::milli>(std::max(0.0, solve_budget_ms))),
                            first_iteration_ms);
  {
    Trial tr;
    m.buildTrial(tr, first, m.root(m.kfs[qpos].segment), false, extra, robust_candidate ? m.huber.get() : nullptr);
    out.summary = m.solve(tr, max_iterations, time_budget_ms, start, &callback);
    out.positions = std::move(tr.positions);
    out.states = std::move(tr.states);
  }  // the problem's teardown is part of the trial's cost
  if (time_budget_ms > 0) m.learnCost(window, msSince(start), callback);
  return out;
}

int KeyframeGraph::scoredPositions(const TrialSolution& solution, Eigen::Matrix3Xd* before,
                               Eigen::Matrix3Xd* after) const {
  const Impl& m = *impl_;
  if (solution.condensed) {
    size_t n = 0;
    for (const auto& range : m.windowRanges(solution, true)) n += range.second - range.first;
    const size_t stride = std::max<size_t>(1, (n + kCondensedScoredKeyframes - 1) / kCondensedScoredKeyframes);
    const std::vector<size_t> targets = m.windowPositions(solution, stride, true);
    const std::vector<KeyframeState> states = m.expand(solution, targets, true);
    before->resize(3, targets.size());
    after->resize(3, targets.size());
    for (size_t k = 0; k < targets.size(); ++k) {
      const KeyframeState& b = m.x[targets[k]];
      before->col(k) << b.t[0], b.t[1], b.t[2];
      after->col(k) << states[k].t[0], states[k].t[1], states[k].t[2];
    }
    return static_cast<int>(targets.size());
  }
  std::vector<size_t> scored;
  for (size_t i = 0; i < solution.positions.size(); ++i)
    if (m.kfs[solution.positions[i]].sequence != 0) scored.push_back(i);
  before->resize(3, scored.size());
  after->resize(3, scored.size());
  for (size_t k = 0; k < scored.size(); ++k) {
    const size_t i = scored[k];
    const KeyframeState& b = m.x[solution.positions[i]];
    const KeyframeState& a = solution.states[i];
    before->col(k) << b.t[0], b.t[1], b.t[2];
    after->col(k) << a.t[0], a.t[1], a.t[2];
  }
  return static_cast<int>(scored.size());
}

void KeyframeGraph::adopt(const TrialSolution& solution) {
  if (solution.condensed) {
    const std::vector<size_t> targets = impl_->windowPositions(solution, 1, false);
    impl_->adopt(targets, impl_->expand(solution, targets));
    return;
  }
  impl_->adopt(solution.positions, solution.states);
}

size_t KeyframeGraph::solveCount() const { return impl_->solves; }

}  // namespace core
}  // namespace rover_loop_fusion
