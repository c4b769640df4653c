#include "rover_loop_fusion/core/drift.h"

#include "rover_loop_fusion/core/geometry.h"

#include <algorithm>

namespace rover_loop_fusion {
namespace core {

Eigen::Matrix4d DriftModel::stepCovariance(double length) const {
  const double l = std::max(length, min_step);
  Eigen::Matrix4d C = Eigen::Matrix4d::Zero();
  C(0, 0) = C(1, 1) = sigma_xy * sigma_xy * l;
  C(2, 2) = sigma_z * sigma_z * l;
  C(3, 3) = sigma_yaw * sigma_yaw * l;
  return C;
}

void ChainMoments::Sums::add(const Sums& o, double sign) {
  A += sign * o.A;
  b += sign * o.b;
  Bp += sign * o.Bp;
  c += sign * o.c;
  cp += sign * o.cp;
  Cpp += sign * o.Cpp;
}

void ChainMoments::clear() {
  n_ = 0;
  checkpoints_.clear();
}

void ChainMoments::extend(const ChainSteps& steps, size_t n) {
  for (size_t k = n_; k < n; ++k) {
    if (k % kStride == 0) {
      if (k == 0) {
        checkpoints_.push_back(Sums());
      } else {
        Sums s = checkpoints_.back();
        for (size_t j = k - kStride + 1; j <= k; ++j) addStep(steps, j, &s);
        checkpoints_.push_back(s);
      }
    }
  }
  n_ = std::max(n_, n);
}

void ChainMoments::addStep(const ChainSteps& steps, size_t j, Sums* s) {
  // The same sums, term by term, as adding a Sums of the one step (each term rounded as it
  // would be there: the step's own moments first, then their addition), without building that
  // Sums: the temporaries were most of what a prefix sum cost in a whole-run trial's scoring.
  if (j == 0) return;
  const Eigen::Matrix4d S = steps.stepCovariance(j);
  const Eigen::Vector3d pj = steps.position(j);
  const Eigen::Matrix3d Stt = S.topLeftCorner<3, 3>();
  if (S.topRightCorner<3, 1>().isZero(0.0) && (Stt - Stt(0, 0) * Eigen::Matrix3d::Identity()).isZero(0.0)) {
    // Isotropic in translation, no cross term (loop_fusion's unit weighting): R S R^T = S and
    // the rotation is not needed; b and Bp get nothing.
    s->A += Stt;
  } else {
    const Eigen::Matrix3d Rj = steps.rotation(j);
    s->A += (Rj * Stt * Rj.transpose()).eval();
    const Eigen::Vector3d b = Rj * S.topRightCorner<3, 1>();
    s->b += b;
    s->Bp += (b * pj.transpose()).eval();
  }
  const double c = S(3, 3);
  s->c += c;
  const Eigen::Vector3d cp = c * pj;
  s->cp += cp;
  s->Cpp += (c * pj * pj.transpose()).eval();
}

ChainMoments::Sums ChainMoments::prefix(const ChainSteps& steps, size_t k) const {
  const size_t i = k / kStride;
  Sums s = checkpoints_[i];
  for (size_t j = i * kStride + 1; j <= k; ++j) addStep(steps, j, &s);
  return s;
}

Eigen::Matrix4d ChainMoments::cross(const ChainSteps& steps, size_t a, size_t k, size_t b) const {
  if (k <= a) return Eigen::Matrix4d::Zero();
  return cross(steps, prefix(steps, a), a, k, b);
}

Eigen::Matrix4d ChainMoments::cross(const ChainSteps& steps, const Sums& prefix_a, size_t a, size_t k,
                                    size_t b) const {
  Eigen::Matrix4d C = Eigen::Matrix4d::Zero();
  if (k <= a) return C;
  Sums s = prefix(steps, k);
  s.add(prefix_a, -1.0);
  const Eigen::Vector3d pk = steps.position(k);
  const Eigen::Vector3d pb = steps.position(b);
  // sum W_yy (pk - pj)(pb - pj)^T
  const Eigen::Matrix3d Sdd = s.c * pk * pb.transpose() - pk * s.cp.transpose() - s.cp * pb.transpose() + s.Cpp;
  if (s.b.isZero(0.0) && s.Bp.isZero(0.0)) {
    // No translation-yaw cross terms (loop_fusion's unit weighting, the drift model's steps):
    // the same values as the general form below, whose terms in b and Bp are exact zeros there,
    // and E M E^T written out (E's entries are 0 and +-1: the products are exact).
    C.topLeftCorner<3, 3>() = s.A;
    C(0, 0) += Sdd(1, 1);
    C(0, 1) += -Sdd(1, 0);
    C(1, 0) += -Sdd(0, 1);
    C(1, 1) += Sdd(0, 0);
    const Eigen::Vector3d vk = s.c * pk - s.cp, vb = s.c * pb - s.cp;
    C(0, 3) = -vk[1];
    C(1, 3) = vk[0];
    C(3, 0) = -vb[1];
    C(3, 1) = vb[0];
    C(3, 3) = s.c;
    return C;
  }
  const Eigen::Matrix3d E = yawGenerator();
  C.topLeftCorner<3, 3>() = s.A + E * (pk * s.b.transpose() - s.Bp.transpose()) +
                            (s.b * pb.transpose() - s.Bp) * E.transpose() + E * Sdd * E.transpose();
  C.topRightCorner<3, 1>() = s.b + E * (s.c * pk - s.cp);
  C.bottomLeftCorner<1, 3>() = (s.b + E * (s.c * pb - s.cp)).transpose();
  C(3, 3) = s.c;
  return C;
}

Eigen::Matrix4d ChainMoments::relative(const ChainSteps& steps, size_t a, size_t b, const Eigen::Matrix3d& Ra) const {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = Ra.transpose();
  const Eigen::Matrix4d C = cross(steps, a, b, b);
  return T * C * T.transpose();
}

void StoredChainMoments::append(const Eigen::Vector3d& p, const Eigen::Matrix3d& R, const Eigen::Matrix4d& step_cov) {
  p_.push_back(p);
  R_.push_back(R);
  cov_.push_back(p_.size() == 1 ? Eigen::Matrix4d::Zero() : step_cov);
  moments_.extend(*this, p_.size());
}

}  // namespace core
}  // namespace rover_loop_fusion
