#include "rover_loop_fusion/sim/scene.h"

#include "rover_loop_fusion/core/alignment.h"
#include "rover_loop_fusion/core/geometry.h"

#include <cmath>
#include <cstdio>

namespace rover_loop_fusion {
namespace sim {

using core::Pose;

double Gaussian::uniform() { return (rng_() + 0.5) / 4294967296.0; }

double Gaussian::operator()(double sigma) {
  const double u1 = uniform(), u2 = uniform();
  return sigma * std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

Pose relative(const Pose& a, const Pose& b) {
  return Pose(a.q.conjugate() * (b.t - a.t), (a.q.conjugate() * b.q).normalized());
}

Pose compose(const Pose& a, const Pose& b) {
  return Pose(a.t + a.q * b.t, (a.q * b.q).normalized());
}

namespace {

/// Integrates noisy relative motions into VIO poses (4-DoF drift: yaw + translation).
void integrateVio(std::vector<SimKeyframe>& kfs, double sigma_t, double sigma_yaw, Gaussian& g) {
  for (size_t k = 0; k < kfs.size(); ++k) {
    if (k == 0) {
      kfs[0].vio = kfs[0].truth;
      continue;
    }
    Pose rel = relative(kfs[k - 1].truth, kfs[k].truth);
    rel.t += Eigen::Vector3d(g(sigma_t), g(sigma_t), g(sigma_t));
    rel.q = (core::yawRotation(g(sigma_yaw)) * rel.q).normalized();
    kfs[k].vio = compose(kfs[k - 1].vio, rel);
  }
}


}  // namespace

Scene makeLapsScene(const LapsOptions& o) {
  Scene scene;
  Gaussian g(o.seed);
  const double perimeter = 2.0 * (o.width + o.height);
  const int per_lap = static_cast<int>(std::round(perimeter / o.step));
  const int n = per_lap * o.laps;
  for (int k = 0; k < n; ++k) {
    const double s = std::fmod(k * o.step, perimeter);
    double x, y, yaw;
    if (s < o.width) { x = s; y = 0; yaw = 0; }
    else if (s < o.width + o.height) { x = o.width; y = s - o.width; yaw = M_PI / 2; }
    else if (s < 2 * o.width + o.height) { x = o.width - (s - o.width - o.height); y = o.height; yaw = M_PI; }
    else { x = 0; y = o.height - (s - 2 * o.width - o.height); yaw = -M_PI / 2; }
    SimKeyframe kf;
    kf.index = k;
    kf.stamp = 100.0 + 0.5 * k;
    kf.truth = Pose(Eigen::Vector3d(x, y, o.lap_z_step * k / per_lap), core::yawRotation(yaw));
    scene.keyframes.push_back(kf);
  }
  integrateVio(scene.keyframes, o.sigma_t, o.sigma_yaw, g);

  // Candidates: ground-truth revisits (true) and look-alike places about false_offset away
  // (false), both with a small relative pose, as PnP returns on a place that looks the same.
  // The search costs O(keyframes x laps): skipped when no candidates are asked for (the cost
  // benchmark's 100k-keyframe trajectories make their own).
  if (o.true_every <= 0 && o.false_every <= 0) return scene;
  int revisit_count = 0, lookalike_count = 0;
  const int w = static_cast<int>(std::ceil((o.false_offset + 1.0) / o.step)) + 2;
  for (int q = o.min_gap; q < n; ++q) {
    const SimKeyframe& kq = scene.keyframes[q];
    const double yaw_q = core::yawOf(kq.truth.q);
    int best = -1, lookalike = -1;
    double best_d = o.revisit_radius, lookalike_err = 0.75;
    // Only keyframes near the same place on earlier laps can be revisits or look-alikes.
    for (int base = q - per_lap; base + w >= 0; base -= per_lap) {
      for (int m = std::max(0, base - w); m <= base + w && m + o.min_gap <= q; ++m) {
        const double d = (scene.keyframes[m].truth.t - kq.truth.t).norm();
        if (std::abs(core::wrapAngleDiff(core::yawOf(scene.keyframes[m].truth.q) - yaw_q)) > 0.5) continue;
        if (d < best_d) { best = m; best_d = d; }
        if (std::abs(d - o.false_offset) < lookalike_err) { lookalike = m; lookalike_err = std::abs(d - o.false_offset); }
      }
    }
    if (best >= 0 && o.true_every > 0 && ++revisit_count % o.true_every == 0) {
      Pose rel = relative(scene.keyframes[best].truth, kq.truth);
      rel.t += Eigen::Vector3d(g(o.candidate_sigma_t), g(o.candidate_sigma_t), g(o.candidate_sigma_t));
      rel.q = (core::yawRotation(g(o.candidate_sigma_yaw)) * rel.q).normalized();
      SimCandidate sc;
      sc.candidate = loopCandidate(kq, scene.keyframes[best], rel, 40);
      sc.is_true = true;
      sc.truth_distance = best_d;
      scene.candidates.push_back(sc);
    }
    if (lookalike >= 0 && o.false_every > 0 && ++lookalike_count % o.false_every == o.false_every / 2) {
      const SimKeyframe& km = scene.keyframes[lookalike];
      Pose rel;
      rel.t = Eigen::Vector3d(g(0.3), g(0.3), g(0.05));
      rel.q = core::yawRotation(core::wrapAngleDiff(yaw_q - core::yawOf(km.truth.q)) + g(o.candidate_sigma_yaw));
      SimCandidate sc;
      sc.candidate = loopCandidate(kq, km, rel, 40);
      sc.is_true = false;
      sc.truth_distance = (km.truth.t - kq.truth.t).norm();
      scene.candidates.push_back(sc);
    }
  }
  return scene;
}

double ate(const std::vector<Pose>& estimate, const std::vector<Pose>& truth, bool with_scale) {
  const size_t n = std::min(estimate.size(), truth.size());
  Eigen::Matrix3Xd E(3, n), T(3, n);
  for (size_t i = 0; i < n; ++i) {
    E.col(i) = estimate[i].t;
    T.col(i) = truth[i].t;
  }
  return core::alignPositions(T, E, with_scale).rmse;
}

core::LoopCandidate loopCandidate(const SimKeyframe& query, const SimKeyframe& match, const Pose& rel,
                                  int inliers) {
  core::LoopCandidate c;
  c.query_index = query.index;
  c.match_index = match.index;
  c.relative_t = rel.t;
  c.relative_q = rel.q;
  c.relative_yaw = core::yawOf(rel.q);  // keyframes of sim scenes turn about z only
  c.inliers = inliers;
  return c;
}

std::string ratioText(int num, int den) {
  if (den == 0) return "-";
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3f", static_cast<double>(num) / den);
  return buf;
}

}  // namespace sim
}  // namespace rover_loop_fusion
