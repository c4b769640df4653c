// Build-time check (CMakeLists.txt, target rover_loop_fusion_adapter_h_cxx11): the header the
// VINS-Fusion patch includes compiles as loop_fusion compiles it (-std=c++11) and pulls in
// nothing but the standard library and Eigen (check_header_deps.cmake lists what it includes).
#include "rover_loop_fusion/ros/loop_fusion_adapter.h"

// The calls the patch makes, with the argument types loop_fusion has at hand.
void patchCalls(rover_loop_fusion::LoopFusionAdapter& rover, bool use_imu) {
  Eigen::Vector3d P = Eigen::Vector3d::Zero();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Matrix<double, 8, 1> loop_info = Eigen::Matrix<double, 8, 1>::Zero();
  int index = 1, loop_index = 0, sequence = 1;
  double time_stamp = 0.0;
  bool has_loop = true;
  rover.initialize(use_imu);
  rover.addKeyframe(index, time_stamp, sequence, P, R);
  if (has_loop && !rover.verifyLoop(index, loop_index, loop_info)) has_loop = false;
  rover.commitStoredLoop(index, loop_index, loop_info);
  int loop_inliers = -1;
  for (const rover_loop_fusion::LoopFusionAdapter::LaterLoop& later : rover.takeLaterLoops())
    later.apply(has_loop, loop_index, loop_info, loop_inliers);
  (void)has_loop;
}
