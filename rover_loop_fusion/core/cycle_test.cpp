// The cycle test of two loops (core/cycle_test.h).
#include "rover_loop_fusion/core/cycle_test.h"

#include "rover_loop_fusion/core/decision.h"
#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Geometry>

#include <algorithm>

namespace rover_loop_fusion {
namespace core {

namespace {

/// 4-DoF perturbation of a relative pose (translation in its `from` frame, yaw about z).
Eigen::Isometry3d perturbed(const Eigen::Isometry3d& T, const Eigen::Vector4d& d) {
  Eigen::Isometry3d out = T;
  out.translation() += d.head<3>();
  out.linear() = Eigen::AngleAxisd(d[3], Eigen::Vector3d::UnitZ()).toRotationMatrix() * T.linear();
  return out;
}

Eigen::Vector4d cycleResidual(const Eigen::Isometry3d& C) {
  Eigen::Vector4d r;
  r.head<3>() = C.translation();
  r[3] = rotationToYawPitchRoll(C.linear())[0];
  return r;
}

Eigen::Isometry3d poseAt(const KeyframeGraph& graph, size_t pos, bool vio) {
  Pose p;
  if (vio)
    graph.vioAt(pos, &p);
  else
    graph.estimateAt(pos, &p);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = p.q.toRotationMatrix();
  T.translation() = p.t;
  return T;
}

}  // namespace

int cycleTest(const KeyframeGraph& graph, const VerifierConfig& config, double drift_scale, const HeldCandidate& a,
              const HeldCandidate& b, bool from_vio, double* residual_m) {
  // The cycle q_a -> m_a -> m_b -> q_b -> q_a through the two loops and the odometry between
  // the matches and between the queries must close: C = Za^-1 (Tma^-1 Tmb) Zb (Tqb^-1 Tqa) = I.
  // Each factor is a 4-DoF relative pose B with its covariance (from the older keyframe to the
  // newer one, inverted where the cycle runs the other way); the covariance of C's residual
  // comes from numeric Jacobians.
  struct Factor {
    Eigen::Isometry3d base;
    bool inverted;
    Eigen::Matrix4d cov;
  };
  auto loopPose = [](const LoopCandidate& c) {
    Eigen::Isometry3d Z = Eigen::Isometry3d::Identity();
    Z.linear() = c.relative_q.normalized().toRotationMatrix();
    Z.translation() = c.relative_t;
    return Z;
  };
  auto odometry = [&](size_t from, size_t to, Factor* f) {  // the factor T_from^-1 T_to
    const size_t lo = std::min(from, to), hi = std::max(from, to);
    f->base = poseAt(graph, lo, from_vio).inverse() * poseAt(graph, hi, from_vio);
    f->inverted = from > to;
    return graph.chainCovariance(lo, hi, drift_scale, &f->cov);
  };
  const Eigen::Matrix4d L = graph.loopCovariance();
  Factor f[4];
  f[0] = Factor{loopPose(a.candidate), true, L};
  f[2] = Factor{loopPose(b.candidate), false, L};
  if (!odometry(a.match_pos, b.match_pos, &f[1]) || !odometry(b.query_pos, a.query_pos, &f[3])) return -1;
  auto value = [](const Factor& x, const Eigen::Vector4d& d) {
    const Eigen::Isometry3d B = perturbed(x.base, d);
    return x.inverted ? Eigen::Isometry3d(B.inverse()) : B;
  };
  auto residual = [&](int k, const Eigen::Vector4d& d) {
    Eigen::Isometry3d C = Eigen::Isometry3d::Identity();
    for (int i = 0; i < 4; ++i) C = C * value(f[i], i == k ? d : Eigen::Vector4d::Zero());
    return cycleResidual(C);
  };
  const Eigen::Vector4d r = residual(-1, Eigen::Vector4d::Zero());
  if (residual_m) *residual_m = r.head<3>().norm();
  Eigen::Matrix4d S = Eigen::Matrix4d::Zero();
  const double h = 1e-6;
  for (int k = 0; k < 4; ++k) {
    Eigen::Matrix4d J;
    for (int d = 0; d < 4; ++d) J.col(d) = (residual(k, h * Eigen::Vector4d::Unit(d)) - r) / h;
    S += J * f[k].cov * J.transpose();
  }
  return mahalanobis(r, S) <= chiSquareQuantile(config.chi2.gate_probability, 4) ? 1 : 0;
}

}  // namespace core
}  // namespace rover_loop_fusion
