#include "rover_loop_fusion/core/decision.h"

#include "rover_loop_fusion/core/alignment.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

Check fail(Reason reason, std::string detail) {
  Check c;
  c.passed = false;
  c.reason = reason;
  c.detail = std::move(detail);
  return c;
}

}  // namespace

double scoreThreshold(const VerifierConfig& config, double path_length) {
  double threshold = config.metric.threshold;
  if (config.metric.threshold_per_metre > 0 && std::isfinite(path_length)) {
    threshold += config.metric.threshold_per_metre * path_length;
    if (config.metric.max_threshold > 0) threshold = std::min(threshold, config.metric.max_threshold);
  }
  return threshold;
}

Check innovationGate(const VerifierConfig& config, double innovation, double path_length) {
  if (!(config.metric.max_innovation > 0)) return Check();
  const double bound = config.metric.max_innovation + config.metric.max_innovation_per_metre * path_length;
  std::ostringstream s;
  s.precision(3);
  if (!std::isfinite(innovation) || !std::isfinite(path_length) || !std::isfinite(bound)) {
    s << "innovation gate cannot decide: innovation " << innovation << " m, path length " << path_length
      << " m (not finite): rejected";
    return fail(Reason::kInvalidInput, s.str());
  }
  if (innovation <= bound) return Check();
  s << std::fixed << "innovation " << innovation << " m > " << bound << " m (" << config.metric.max_innovation
    << " m + " << config.metric.max_innovation_per_metre << " x " << path_length
    << " m of path): more than drift can explain";
  return fail(Reason::kInnovationAboveBound, s.str());
}

double deformationScore(const Eigen::Matrix3Xd& before, const Eigen::Matrix3Xd& after,
                        Alignment alignment) {
  const AlignmentResult al = alignPositions(before, after, alignment == Alignment::kSim3);
  return al.ok ? al.rmse : std::numeric_limits<double>::quiet_NaN();
}

Check scoreTest(const SolveSummary& trial, double score, double threshold, int window_size,
                double time_budget_ms) {
  std::ostringstream s;
  s.precision(3);
  if (trial.timed_out) {
    s << "trial optimisation stopped by time_budget_ms " << time_budget_ms << ": " << trial.message;
    return fail(Reason::kTimeBudgetExceeded, s.str());
  }
  if (!trial.converged || !trial.finite || !std::isfinite(score)) {
    s << "trial optimisation did not converge after " << trial.iterations << " iterations ("
      << (trial.finite ? trial.message : "non-finite solution") << ")";
    return fail(Reason::kNotConverged, s.str());
  }
  const bool above = score > threshold;
  s << "score " << std::fixed << score << (above ? " m > threshold " : " m <= threshold ") << threshold
    << " m over " << window_size << " keyframes";
  if (above) return fail(Reason::kScoreAboveThreshold, s.str());
  Check passed;
  passed.detail = s.str();
  return passed;
}

double chiSquareQuantile(double p, int dof) {
  if (!(p > 0.0 && p < 1.0) || dof < 2 || dof % 2 != 0) return std::numeric_limits<double>::quiet_NaN();
  // CDF of an even dof: 1 - exp(-x/2) sum_{i < dof/2} (x/2)^i / i!  (increasing): bisection.
  auto cdf = [dof](double x) {
    double term = 1.0, sum = 1.0;
    for (int i = 1; i < dof / 2; ++i) {
      term *= 0.5 * x / i;
      sum += term;
    }
    return 1.0 - std::exp(-0.5 * x) * sum;
  };
  double lo = 0.0, hi = 1.0;
  while (cdf(hi) < p) hi *= 2.0;
  for (int it = 0; it < 200 && hi - lo > 1e-12 * hi; ++it) {
    const double mid = 0.5 * (lo + hi);
    (cdf(mid) < p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

std::string probabilityText(double p) {
  std::ostringstream s;
  s.precision(12);
  s << p;
  return s.str();
}

double mahalanobis(const Eigen::Vector4d& nu, const Eigen::Matrix4d& S) {
  const Eigen::LLT<Eigen::Matrix4d> llt(0.5 * (S + S.transpose()));
  if (llt.info() != Eigen::Success || !nu.allFinite()) return std::numeric_limits<double>::infinity();
  const double d2 = nu.dot(llt.solve(nu));
  return std::isfinite(d2) ? d2 : std::numeric_limits<double>::infinity();
}

double lookalikeMargin(const Eigen::Vector4d& nu, const Eigen::Matrix4d& S, double horizontal,
                       double vertical) {
  const double inf = std::numeric_limits<double>::infinity();
  if (!(horizontal > 0) && !(vertical > 0)) return inf;
  const Eigen::LLT<Eigen::Matrix4d> llt(0.5 * (S + S.transpose()));
  if (llt.info() != Eigen::Success) return inf;
  const Eigen::Matrix4d A = llt.solve(Eigen::Matrix4d::Identity());
  const Eigen::Vector4d Anu = A * nu;
  // d2(nu - o) - d2(nu) = -2 o^T A nu + o^T A o
  auto delta = [&](const Eigen::Vector4d& o) { return -2.0 * o.dot(Anu) + o.dot(A * o); };
  double best = inf;
  if (vertical > 0) {
    const Eigen::Vector4d up(0, 0, vertical, 0);
    best = std::min({best, delta(up), delta(-up)});
  }
  if (horizontal > 0) {
    // A smooth function of the direction on a circle: a fine grid, then golden-section refinement.
    const int n = 72;
    auto at = [&](double th) { return delta(Eigen::Vector4d(horizontal * std::cos(th), horizontal * std::sin(th), 0, 0)); };
    int k_best = 0;
    double f_best = inf;
    for (int k = 0; k < n; ++k) {
      const double f = at(2.0 * M_PI * k / n);
      if (f < f_best) {
        f_best = f;
        k_best = k;
      }
    }
    double a = 2.0 * M_PI * (k_best - 1) / n, b = 2.0 * M_PI * (k_best + 1) / n;
    const double g = 0.5 * (std::sqrt(5.0) - 1.0);
    double c = b - g * (b - a), d = a + g * (b - a), fc = at(c), fd = at(d);
    for (int it = 0; it < 40; ++it) {
      if (fc < fd) {
        b = d; d = c; fd = fc; c = b - g * (b - a); fc = at(c);
      } else {
        a = c; c = d; fc = fd; d = a + g * (b - a); fd = at(d);
      }
    }
    best = std::min({best, f_best, fc, fd});
  }
  return best;
}

Check chi2Test(const VerifierConfig& config, const Eigen::Vector4d& nu, const Eigen::Matrix4d& S,
               Chi2Numbers* numbers) {
  Chi2Numbers& n = *numbers;
  n.d2 = mahalanobis(nu, S);
  n.gate = chiSquareQuantile(config.chi2.gate_probability, 4);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (S.topLeftCorner<3, 3>() + S.topLeftCorner<3, 3>().transpose()));
  n.sigma = std::sqrt(std::max(0.0, eig.eigenvalues().maxCoeff()));
  n.margin = lookalikeMargin(nu, S, config.chi2.lookalike_distance, config.chi2.lookalike_distance_vertical);
  std::ostringstream s;
  s.precision(3);
  s << std::fixed << "innovation " << nu.head<3>().norm() << " m, " << std::abs(nu[3]) * 180.0 / M_PI
    << " deg; Mahalanobis d2 " << n.d2 << (n.d2 <= n.gate ? " <= " : " > ") << n.gate << " (chi2 "
    << probabilityText(config.chi2.gate_probability) << "); relative position std up to " << n.sigma << " m";
  if (!(n.d2 <= n.gate)) return fail(Reason::kInconsistentWithDrift, s.str() + ": more than drift explains");
  if (std::isfinite(n.margin)) s << "; look-alike margin " << n.margin;
  if (!(n.margin >= config.chi2.lookalike_margin)) {
    s << " < " << config.chi2.lookalike_margin << ": a look-alike " << config.chi2.lookalike_distance << " m (horizontal) / "
      << config.chi2.lookalike_distance_vertical << " m (vertical) away explains it as well";
    return fail(Reason::kLookalikeCloser, s.str());
  }
  Check passed;
  passed.detail = s.str();
  return passed;
}

}  // namespace core
}  // namespace rover_loop_fusion
