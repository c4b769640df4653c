// The 6-DoF condensed trial (mode 6dof, condense_min_window; the 4-DoF one and what both share:
// condensed_trial.cpp): the window's anchors with full poses (core/condensed6.h), a chain of
// odometry between two anchors as one edge whose covariance is the chain model's below, and
// the keyframes between anchors placed by that model's conditional mean for scoring and
// adoption.
//
// The chain model (loop_fusion's unit weighting, as the 4-DoF unitStepCovariance): one step
// k-1 -> k of a chain with odometry_neighbours edges per keyframe has isotropic noise, sigma_t
// (kSixDofTranslationSigma) in translation and sigma_q (kSixDofRotationSigma) in rotation, each
// variance divided by the stiffness sum k^2. A step's rotation phi_k turns every later keyframe
// about keyframe k, so the world-frame change of a later keyframe p (position, rotation) is
//   (tau_k - [p_p - p_k]x phi_k,  phi_k),
// and the covariance of p's and b's changes sums, over the steps before both, products that
// need only the count, sum p_k and sum [p_k]x[p_k]x of the steps' positions (ChainSums).
#include "rover_loop_fusion/core/pose_graph_impl.h"

#include "rover_loop_fusion/core/geometry.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>

namespace rover_loop_fusion {
namespace core {

namespace {

Eigen::Vector3d positionOf(const KeyframeState& s) { return Eigen::Vector3d(s.t[0], s.t[1], s.t[2]); }
Eigen::Quaterniond rotationQ(const KeyframeState& s) {
  return Eigen::Quaterniond(s.q[0], s.q[1], s.q[2], s.q[3]).normalized();
}

/// Sums over a chain's steps (their keyframes' positions, relative to the chain's start).
struct ChainSums {
  double n = 0;
  Eigen::Vector3d s1 = Eigen::Vector3d::Zero();  // sum p_k
  Eigen::Matrix3d s2 = Eigen::Matrix3d::Zero();  // sum [p_k]x [p_k]x
  void add(const Eigen::Vector3d& pk) {
    const Eigen::Matrix3d S = skew(pk);
    n += 1;
    s1 += pk;
    s2 += S * S;
  }
  /// World-frame covariance (position, rotation) of the changes at keyframes p and b caused by
  /// the steps summed (each at or before p and b); st, sq: a step's variances.
  Matrix6d cross(const Eigen::Vector3d& pp, const Eigen::Vector3d& pb, double st, double sq) const {
    const Eigen::Matrix3d Pp = skew(pp), Pb = skew(pb), S1 = skew(s1);
    const Eigen::Matrix3d X = n * Pp * Pb - Pp * S1 - S1 * Pb + s2;  // sum [p_p - p_k]x [p_b - p_k]x
    Matrix6d C;
    C.topLeftCorner<3, 3>() = st * n * Eigen::Matrix3d::Identity() - sq * X;
    C.topRightCorner<3, 3>() = -sq * (n * Pp - S1);
    C.bottomLeftCorner<3, 3>() = sq * (n * Pb - S1);
    C.bottomRightCorner<3, 3>() = sq * n * Eigen::Matrix3d::Identity();
    return C;
  }
};

}  // namespace

KeyframeState KeyframeGraph::Impl::stateWithPose(KeyframeState s, const Eigen::Vector3d& p,
                                                 const Eigen::Quaterniond& q) const {
  const Eigen::Quaterniond u = q.normalized();
  for (int k = 0; k < 3; ++k) s.t[k] = p[k];
  s.q[0] = u.w();
  s.q[1] = u.x();
  s.q[2] = u.y();
  s.q[3] = u.z();
  s.yaw = yawOf(u);
  return s;
}

Matrix6d KeyframeGraph::Impl::unitLoopCovariance6() const {
  Matrix6d C = Matrix6d::Zero();
  C.diagonal().head<3>().setConstant(kSixDofTranslationSigma * kSixDofTranslationSigma);
  C.diagonal().tail<3>().setConstant(kSixDofRotationSigma * kSixDofRotationSigma);
  return C;
}

void KeyframeGraph::Impl::unitStepVariances6(double* st, double* sq) const {
  const double stiffness = stepStiffness();
  *st = kSixDofTranslationSigma * kSixDofTranslationSigma / stiffness;
  *sq = kSixDofRotationSigma * kSixDofRotationSigma / stiffness;
}

bool KeyframeGraph::Impl::condense6(int component, const std::vector<size_t>& extra, const CondenseOptions& o,
                                    CondensedGraph6* cg, std::vector<size_t>* anchors) const {
  const std::vector<LoopRep> reps = condensedAnchors(component, extra, o, anchors);
  const std::vector<size_t>& a = *anchors;
  for (size_t p : a) {
    AnchorPose pose;
    pose.p = positionOf(x[p]);
    pose.q = rotationQ(x[p]);
    cg->addAnchor(pose, kfs[p].sequence == 0 || p <= o.first);
  }
  double st = 0, sq = 0;
  unitStepVariances6(&st, &sq);
  for (size_t i = 1; i < a.size(); ++i) {
    const size_t pa = a[i - 1], pb = a[i];
    const Keyframe& ka = kfs[pa];
    const Keyframe& kb = kfs[pb];
    if (ka.segment != kb.segment || pa < o.first) continue;
    // The chain's keyframes are the positions (pa, pb] (a segment's keyframes are contiguous).
    ChainSums sums;
    for (size_t k = pa + 1; k <= pb; ++k) sums.add(kfs[k].vio.t - ka.vio.t);
    const Eigen::Vector3d d = kb.vio.t - ka.vio.t;
    Matrix6d T = Matrix6d::Zero();  // world-frame changes of b -> the residual's frames
    T.topLeftCorner<3, 3>() = ka.vio.q.conjugate().toRotationMatrix();
    T.bottomRightCorner<3, 3>() = kb.vio.q.conjugate().toRotationMatrix();
    CondensedEdge6 e;
    e.from = static_cast<int>(i - 1);
    e.to = static_cast<int>(i);
    e.t = ka.vio.q.conjugate() * d;
    e.q = ka.vio.q.conjugate() * kb.vio.q;
    e.covariance = T * sums.cross(d, d, st, sq) * T.transpose();
    if (!cg->addEdge(e)) return false;
  }
  auto id = [&](size_t p) { return static_cast<int>(std::lower_bound(a.begin(), a.end(), p) - a.begin()); };
  for (const LoopRep& r : reps) {
    CondensedEdge6 e;
    e.from = id(r.from);
    e.to = id(r.to);
    e.t = r.loop->relative_t;
    e.q = r.loop->relative_q;
    e.covariance = unitLoopCovariance6() / r.count;
    e.count = r.count;
    e.huber = cfg.trial.loop_huber;
    if (!cg->addEdge(e)) return false;
  }
  return true;
}

/// The 6-DoF chain model's conditional mean, in the frame of X before the solution: per chain
/// the rigid move of its first anchor and the weights of the gap at its end, and the sums over
/// its steps up to the last keyframe placed (placed in increasing order, a chain's steps are
/// summed once for its end and once for its keyframes).
class KeyframeGraph::Impl::SixDofPlacer : public ChainPlacer {
 public:
  SixDofPlacer(const Impl& m, const TrialSolution& s) : m_(m), s_(s) {
    m.unitStepVariances6(&st_, &sq_);
  }

  KeyframeState place(size_t i, size_t p, bool position_only) override {
    const std::vector<size_t>& a = s_.positions;
    const auto& x = m_.x;
    const size_t pa = a[i], pb = a[i + 1];
    const Eigen::Vector3d xa = positionOf(x[pa]), xb = positionOf(x[pb]);
    auto found = fits_.find(i);
    if (found == fits_.end()) {
      ChainFit f;
      f.Rc = rotationQ(s_.states[i]).toRotationMatrix() * rotationQ(x[pa]).toRotationMatrix().transpose();
      f.tc = positionOf(s_.states[i]) - f.Rc * xa;
      // What is left at b after the rigid move, as a change of b in X's frame.
      Vector6d gap;
      gap.head<3>() = f.Rc.transpose() * (positionOf(s_.states[i + 1]) - f.tc) - xb;
      const Eigen::AngleAxisd turn(f.Rc.transpose() * rotationQ(s_.states[i + 1]).toRotationMatrix() *
                                   rotationQ(x[pb]).toRotationMatrix().transpose());
      gap.tail<3>() = turn.angle() * turn.axis();
      ChainSums all;
      for (size_t k = pa + 1; k <= pb; ++k) all.add(positionOf(x[k]) - xa);
      f.w = all.cross(xb - xa, xb - xa, st_, sq_).ldlt().solve(gap);
      f.next = pa + 1;
      found = fits_.emplace(i, f).first;
    }
    ChainFit& f = found->second;
    for (; f.next <= p; ++f.next) f.sums.add(positionOf(x[f.next]) - xa);
    const Vector6d corr = f.sums.cross(positionOf(x[p]) - xa, xb - xa, st_, sq_) * f.w;
    const Eigen::Vector3d t = f.Rc * (positionOf(x[p]) + corr.head<3>()) + f.tc;
    if (position_only) {
      KeyframeState st = x[p];
      for (int k = 0; k < 3; ++k) st.t[k] = t[k];
      return st;
    }
    const Eigen::Quaterniond q(f.Rc * rotationExp(corr.tail<3>()).toRotationMatrix() *
                               rotationQ(x[p]).toRotationMatrix());
    return m_.stateWithPose(x[p], t, q);
  }

 private:
  struct ChainFit {
    Eigen::Matrix3d Rc;  // the rigid move of the chain's first anchor: R_c, t_c
    Eigen::Vector3d tc;
    Vector6d w;          // C_bb^-1 gap
    ChainSums sums;      // over the steps (a, next)
    size_t next;
  };
  const Impl& m_;
  const TrialSolution& s_;
  double st_ = 0, sq_ = 0;
  std::map<size_t, ChainFit> fits_;
};

std::unique_ptr<KeyframeGraph::Impl::ChainPlacer> KeyframeGraph::Impl::chainPlacer6(const TrialSolution& s) const {
  return std::unique_ptr<ChainPlacer>(new SixDofPlacer(*this, s));
}

}  // namespace core
}  // namespace rover_loop_fusion
