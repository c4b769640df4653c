#include "rover_loop_fusion/core/alignment.h"

#include <Eigen/Geometry>

#include <cmath>

namespace rover_loop_fusion {
namespace core {

AlignmentResult alignPositions(const Eigen::Matrix3Xd& reference, const Eigen::Matrix3Xd& moved,
                               bool with_scale) {
  AlignmentResult r;
  const Eigen::Index n = reference.cols();
  if (n == 0 || moved.cols() != n || !reference.allFinite() || !moved.allFinite()) return r;
  if (n == 1) {
    r.translation = reference.col(0) - moved.col(0);
    r.ok = true;
    return r;
  }
  // Sim(3) is undefined when P* has no spread; fall back to SE(3) there.
  const Eigen::Vector3d mean = moved.rowwise().mean();
  const bool spread = (moved.colwise() - mean).squaredNorm() > 1e-18;
  const Eigen::Matrix4d T = Eigen::umeyama(moved, reference, with_scale && spread);
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  r.translation = T.topRightCorner<3, 1>();
  r.scale = (with_scale && spread) ? std::cbrt(sR.determinant()) : 1.0;
  r.rotation = sR / r.scale;
  const Eigen::Matrix3Xd aligned = (sR * moved).colwise() + r.translation;
  r.rmse = std::sqrt((reference - aligned).colwise().squaredNorm().mean());
  r.ok = std::isfinite(r.rmse);
  return r;
}

}  // namespace core
}  // namespace rover_loop_fusion
