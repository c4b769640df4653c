// What a budgeted trial may spend (KeyframeGraph::solveWindow with time_budget_ms > 0):
// a Ceres callback that stops the solve before an iteration that would end past the deadline,
// and the cost per window keyframe learnt from the trials so far, which decides whether a
// trial is started at all (core/trial_solve.cpp).
//
// Internal to the pose graph (core/pose_graph_impl.h includes it); not part of the core's API.
#pragma once

#include <ceres/ceres.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <string>

namespace rover_loop_fusion {
namespace core {

using Clock = std::chrono::steady_clock;

inline double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// Stops a Ceres solve before an iteration that would end past the deadline. Ceres' own
/// max_solver_time_in_seconds only looks at the time already spent, so an iteration started
/// just before the limit runs to its end (531 ms on a 20k-keyframe window). The next
/// iteration is predicted as long as the last one, or, after Ceres' initial evaluation, as
/// `first_iteration_ms` (the first iteration also analyses the sparsity: the dearest one).
class DeadlineCallback : public ceres::IterationCallback {
 public:
  DeadlineCallback(Clock::time_point deadline, double first_iteration_ms)
      : deadline_(deadline), first_iteration_ms_(first_iteration_ms) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& it) override {
    double next = first_iteration_ms_;
    if (it.iteration > 0) {
      next = 1e3 * it.iteration_time_in_seconds;
      longest_ms = std::max(longest_ms, next);
      iterations_ms += next;
    }
    const double left = std::chrono::duration<double, std::milli>(deadline_ - Clock::now()).count();
    if (next <= left) return ceres::SOLVER_CONTINUE;
    std::ostringstream s;
    s.precision(3);
    s << "stopped after " << it.iteration << " iterations: the next one (~" << next << " ms) would end past the budget ("
      << std::max(0.0, left) << " ms left)";
    stop_reason = s.str();
    return ceres::SOLVER_ABORT;
  }

  std::string stop_reason;  ///< empty unless the callback stopped the solve
  double longest_ms = 0;    ///< longest iteration (without Ceres' initial evaluation)
  double iterations_ms = 0;

 private:
  Clock::time_point deadline_;
  double first_iteration_ms_;
};

/// A cost per window keyframe [ms], learned from measured trials as TCP learns a round-trip
/// time: a moving average and its mean deviation (25 % per measurement), predicting the
/// average + 2 deviations. The first measurement replaces the guess, with half its value as
/// deviation.
struct CostRate {
  explicit CostRate(double guess_ms) : mean(guess_ms) {}
  double mean;
  double deviation = 0;
  bool measured = false;
  double predict() const { return mean + 2 * deviation; }
  void learn(double observed) {
    if (!measured) {
      mean = observed;
      deviation = observed / 2;
      measured = true;
      return;
    }
    deviation = 0.75 * deviation + 0.25 * std::abs(observed - mean);
    mean = 0.75 * mean + 0.25 * observed;
  }
};

/// Part of a trial's time budget kept for what follows the solve: the problem's teardown
/// and the scoring (both grow with the window).
constexpr double kBudgetAfterSolve = 0.1;

}  // namespace core
}  // namespace rover_loop_fusion
