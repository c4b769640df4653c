// The entry point of the patched VINS-Fusion loop_fusion (patches/): the patch calls these
// few methods with plain values; everything else (parameters, the pluginlib verifier,
// verdict topic, markers, CSV log) lives behind them in our package.
//
// This header is included by loop_fusion's pose_graph.h and must compile with loop_fusion's
// own flags (-std=c++11) and include paths: it includes only the standard library and Eigen,
// never ROS, pluginlib or Ceres headers (checked at build time, see CMakeLists.txt).
//
// Loops decided later: the verifier may hold a candidate (a deferred verdict; the loop is
// dropped from the keyframe like a rejected one, so nothing uses or saves it) and decide about
// it a few keyframes later, or revoke a loop it accepted. The patch applies such decisions at
// the end of addKeyFrame (takeLaterLoops(), LaterLoop::apply()), where loop_fusion holds
// m_keyframelist: a released loop is set on its keyframe and used like a loop accepted at once
// (earliest_loop_index, the first-loop sequence shift, optimize_buf); a revoked one is removed.
//
// Host safety: no method throws. Errors are logged with ROS_ERROR and fail closed (the loop
// is rejected). A verifier that cannot be set up from the parameters either falls back to
// accepting every loop (only if ~fallback_to_accept_all is true) or stops the process with a
// ROS_FATAL message that names the parameter to fix.
#ifndef ROVER_LOOP_FUSION_ROS_LOOP_FUSION_ADAPTER_H
#define ROVER_LOOP_FUSION_ROS_LOOP_FUSION_ADAPTER_H

#include <Eigen/Core>

#include <memory>
#include <string>
#include <vector>

namespace rover_loop_fusion {

class LoopVerifier;

class LoopFusionAdapter {
 public:
  /// loop_info layout of loop_fusion's keyframes:
  /// [t_x, t_y, t_z, q_w, q_x, q_y, q_z, relative_yaw_degrees], the query keyframe in the
  /// match keyframe's frame.
  typedef Eigen::Matrix<double, 8, 1> LoopInfo;

  /// A loop decided after its keyframe's own verdict, for loop_fusion to apply to keyframe
  /// `index` (takeLaterLoops()).
  struct LaterLoop {
    /// true: a held loop released: use it from now on; false: an accepted loop revoked:
    /// remove it (the keyframe keeps no loop).
    bool use;
    int index;        ///< the query keyframe (loop_fusion's global index)
    int match_index;  ///< the match keyframe
    double loop_info[8];  ///< released: the keyframe's loop_info as findConnection set it
    int inliers;      ///< released: the PnP inlier count, -1 if unknown
    /// Sets the keyframe's loop fields: released: has_loop = true, loop_index = match_index,
    /// loop_info, loop_inliers; revoked: as a keyframe without a loop (has_loop = false,
    /// loop_index = -1, loop_info = 0, loop_inliers = -1), so that savePoseGraph does not save it.
    void apply(bool& has_loop, int& loop_index, LoopInfo& info, int& loop_inliers) const {
      has_loop = use;
      loop_index = use ? match_index : -1;
      for (int i = 0; i < 8; ++i) info(i) = use ? loop_info[i] : 0.0;
      loop_inliers = use ? inliers : -1;
    }
  };

  /// Does not touch ROS (loop_fusion's PoseGraph is a global object built before ros::init).
  LoopFusionAdapter();
  /// finish(), then stops the verdict output (waits up to 2 s for the CSV log's last rows).
  ~LoopFusionAdapter();
  LoopFusionAdapter(const LoopFusionAdapter&) = delete;
  LoopFusionAdapter& operator=(const LoopFusionAdapter&) = delete;

  /// Reads the parameters from the node's private namespace (~verifier_type, ~verifier_name,
  /// ~fallback_to_accept_all, ~relocalisation, ~verdict_log, ~marker_frame, ~publish_markers and
  /// the plugin's ~<verifier_name>/...), loads the verifier plugin and advertises
  /// ~loop_verdicts, ~loop_markers and ~loop_candidates. Call once, after ros::init
  /// (loop_fusion: in setIMUFlag). use_imu: loop_fusion's 4-DoF (true) or 6-DoF (false) pose
  /// graph. Returns true when the configured verifier runs, false in fallback mode (every loop
  /// accepted). If the verifier cannot start and the fallback is off, the process stops
  /// (ROS_FATAL naming the parameter, exit status 1). A second call does nothing and returns
  /// the first result. Never blocks on the verdict log (a FIFO is opened when a reader comes).
  bool initialize(bool use_imu);

  /// As initialize(), with a verifier built by the caller instead of the one named by
  /// ~verifier_type (embedding without pluginlib, tests). `verifier_type` is reported in
  /// verdicts. The verifier's own initialize() is called here.
  bool initializeWithVerifier(bool use_imu, std::unique_ptr<LoopVerifier> verifier,
                              const std::string& verifier_type);

  /// Registers a keyframe: loop_fusion's global index, stamp [s], sequence and VIO pose
  /// (after loop_fusion's own sequence shift w_r_vio / w_t_vio). Call before verifyLoop()
  /// for that keyframe.
  void addKeyframe(int index, double stamp, int sequence, const Eigen::Vector3d& P,
                   const Eigen::Matrix3d& R);

  /// The hook after a successful KeyFrame::findConnection: verifies the loop findConnection
  /// has just stored in the keyframe (its has_loop, loop_index, loop_info, passed by reference)
  /// with verifyLoop(). A loop that loop_fusion must not use now (rejected, or held) is dropped
  /// from the keyframe: has_loop = false, loop_index = -1, loop_info = 0, as a keyframe without
  /// a loop, so that savePoseGraph does not save it (loadPoseGraph reads loop_index != -1 as a
  /// loop); a held loop comes back through takeLaterLoops() if it is released. Returns true iff
  /// loop_fusion may use the loop now. inliers: the PnP inlier count, -1 if unknown.
  bool verifyKeyframeLoop(int index, int inliers, bool& has_loop, int& loop_index, LoopInfo& loop_info);

  /// The hook in loadKeyFrame, after addKeyframe(): adds the stored loop of a loaded keyframe
  /// (if has_loop) with commitStoredLoop(); a stored loop the verifier refuses is dropped from
  /// the keyframe as in verifyKeyframeLoop(), so that both graphs hold the same loops.
  void keepStoredLoop(int index, bool& has_loop, int& loop_index, LoopInfo& loop_info);

  /// Verifies a loop candidate; commits it when accepted and publishes the verdict. The
  /// candidate itself is published on ~loop_candidates first (rover_loop_fusion/LoopCandidate,
  /// keyframes named by stamp) so that a recorded run can be replayed through
  /// rover_verifier_node. Returns true iff loop_fusion may use the loop now. A held candidate
  /// gets a deferred verdict (false now); its final verdict follows when the verifier decides.
  bool verifyLoop(int query_index, int match_index, const LoopInfo& loop_info, int inliers = -1);

  /// The loops decided since the last call (held loops released, accepted loops revoked),
  /// oldest first, each for a keyframe loop_fusion has (addKeyframe() was called for both ends).
  /// Their verdicts are already published. Call once per addKeyFrame, after the keyframe is in
  /// keyframelist, holding m_keyframelist: for each, apply() to the keyframe; if `use`, do what
  /// addKeyFrame does with an accepted loop; then queue one optimisation.
  std::vector<LaterLoop> takeLaterLoops();

  /// Adds a loop stored in a loaded pose graph (loadPoseGraph) without verifying it: both
  /// keyframes belong to the loaded map, which loop_fusion holds fixed. Not published.
  /// Returns false if the verifier refused it (logged).
  bool commitStoredLoop(int query_index, int match_index, const LoopInfo& loop_info);

  /// loop_fusion ends: every candidate still held gets its final verdict (unconfirmed, decision
  /// drop, "still held when loop_fusion ended"), published and in the CSV log (flushed, up to
  /// 2 s), so that the log has one final verdict per candidate; verification stops (later loops
  /// are rejected). A second call does nothing. Called by the destructor, and on std::terminate:
  /// upstream loop_fusion ends that way (its main returns with joinable threads, after the 's'
  /// save and after Ctrl-C: exit status -6), without running any destructor; a verifying
  /// adapter installs a terminate handler that calls finish() and then the previous handler.
  void finish();

  /// true after initialize() set up the configured verifier (not the fallback).
  bool verifying() const;
  /// Verdicts published so far (deferred and later ones included).
  size_t verdictCount() const;
  /// Candidates held now (deferred, not yet released or dropped).
  size_t heldCount() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace rover_loop_fusion

#endif  // ROVER_LOOP_FUSION_ROS_LOOP_FUSION_ADAPTER_H
