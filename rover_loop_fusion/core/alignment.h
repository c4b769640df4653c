// Trajectory alignment and the ROVER score (the paper's Eqs. for S* and s_ij).
#pragma once

#include <Eigen/Core>

namespace rover_loop_fusion {
namespace core {

struct AlignmentResult {
  bool ok = false;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;
  double rmse = 0.0;  ///< sqrt(mean ||p_i - (a R p*_i + t)||^2)
};

/// Finds S* = {R, t, a} minimising sum ||p_i - (a R p*_i + t)||^2 (Umeyama, Eigen::umeyama)
/// and returns it with the RMSE of the aligned positions. `reference` = P (3 x N),
/// `moved` = P* (3 x N). with_scale=false: SE(3) (a = 1). Not ok when N == 0, the sizes
/// differ or an input is not finite. N == 1 aligns exactly (rmse 0).
AlignmentResult alignPositions(const Eigen::Matrix3Xd& reference, const Eigen::Matrix3Xd& moved,
                               bool with_scale);

}  // namespace core
}  // namespace rover_loop_fusion
