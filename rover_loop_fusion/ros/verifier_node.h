// rover_verifier_node: the loop verifier fed from topics, for bag replay, the demo and the
// regression tests, without VINS-Fusion.
//
// Input: keyframe VIO poses (nav_msgs/Odometry, as /vins_estimator/keyframe_pose publishes
// them: raw per-session VIO poses) and loop candidates (rover_loop_fusion/LoopCandidate, as the
// patched loop_fusion publishes them on /loop_fusion/loop_candidates). Keyframes are numbered
// in arrival order (0, 1, ...); candidates name their keyframes by stamp (index -1) or by that
// number. Any other negative index is invalid.
//
// Output (private topics): ~loop_verdicts, ~loop_markers (and the optional CSV log) as the
// patched loop_fusion publishes them; ~pose_graph_path, what loop_fusion's optimisation makes
// of the keyframes and the loops this node accepted (the verified trajectory; with the
// accept-all plugin: upstream loop_fusion's); ~odometry_path (the VIO keyframe poses) and
// ~estimate_path (the verifier's own estimate; empty if it keeps none). The paths are latched
// and refreshed every ~optimize_period seconds (if something changed) and by the ~optimize
// service (rover_loop_fusion/Optimize), which also returns them.
//
// Robustness: a candidate that arrives before its keyframes waits up to ~candidate_timeout
// seconds from its own arrival (indexed by the keyframe it waits for: each message costs
// O(log n) however many wait); then, or when it names keyframes that never came or were
// refused, it gets an invalid_input verdict with a ROS_WARN. Keyframe stamps need not increase
// (stamped late, a clock that steps back), so no stamp counts as passed: a candidate naming a
// stamp no keyframe has yet always waits its timeout. Stamps are written sec.nsec in messages. Keyframes are checked by the verifier's own rules
// (the core's keyframe intake, with the plausibility limits of the verifier's namespace:
// max_keyframe_jump, max_stamp_jump, jump_confirmations), so the node and the verifier keep the
// same keyframes: malformed ones (NaN, non-unit quaternion, a repeated message, out-of-order
// stamps, jumps) are refused with a ROS_WARN (the first 20 one by one, then a summary every
// 10 s); the last 10000 refusals are remembered to explain verdicts. A keyframe stamped late
// is kept, and so are keyframes of a clock that stopped (a stamp several keyframes carry cannot
// name one: candidates must name them by number).
// Nothing a message contains stops the node.
//
// Threading: the subscriptions have their own callback queue and thread, which only append
// each message to an inbox (at most ~queue_size messages, at least 1000: a smaller value is
// raised with a ROS_WARN). The node's main thread takes them from the inbox in arrival order
// and does the work. A verification that takes longer than the input rate (a bag played at
// 200x) therefore never makes roscpp drop keyframe messages. A message that arrives when the
// inbox is full is not processed, but keeps its place (ROS_ERROR, counted): a keyframe keeps
// only its stamp and number and is refused ("dropped: the inbox was full"), so candidates that
// name it say why; a candidate gets an invalid_input verdict saying it was not verified.
// Every candidate gets a verdict. ~loop_verdicts queues at least 100000 verdicts per
// subscriber (kVerdictQueueSize), more if queue_size is larger, whatever queue_size says.
//
// Held candidates: a candidate the verifier holds gets a deferred verdict (final: false) and,
// when the verifier decides (after a later keyframe or candidate), its final one: released
// (accepted; the loop enters the node's pose graph) or dropped (unconfirmed). A revoked loop
// leaves the pose graph with a revoked verdict. See msg/LoopVerdict.msg.
//
// Shutdown (SIGINT, SIGTERM): the node finishes the verification under way, stops taking
// messages, gives every candidate it has not decided a verdict ("not verified: the node was
// shut down"; a held one: unconfirmed, "still held when the node was shut down"), publishes and
// logs them, says what it left undone, then exits.
//
// Master watchdog: the node checks the ROS master every second; if it restarted (new
// /run_id), the node's registrations are gone, so it exits with status 2 and a ROS_FATAL
// saying so, after giving every candidate it has not decided its final verdict as at a
// shutdown (in the CSV log; nobody can receive the topic); verifier.launch respawns it.
#pragma once

#include "rover_loop_fusion/LoopCandidate.h"
#include "rover_loop_fusion/Optimize.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/ros/verifier_host.h"
#include "rover_loop_fusion/ros/waiting_candidates.h"

#include <nav_msgs/Odometry.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include <atomic>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {

/// The node's own parameters (private namespace); the shared ones are in HostParams, the
/// plugin reads ~<verifier_name>/...
struct VerifierNodeParams {
  std::string keyframe_topic = "/vins_estimator/keyframe_pose";
  std::string candidate_topic = "/loop_fusion/loop_candidates";
  int sequence = 1;                ///< loop_fusion sequence of every keyframe received (>= 1)
  bool use_imu = true;             ///< 4-DoF (VIO) or 6-DoF (VO) pose graph, as loop_fusion's flag
  double candidate_timeout = 2.0;  ///< [s, wall clock] a candidate waits for its keyframes
  double stamp_tolerance = 1e-3;   ///< [s] a candidate's stamp names the nearest keyframe within it
  double optimize_period = 2.0;    ///< [s, wall clock] loop_fusion-like optimisation; 0: on ~optimize only
  int optimize_iterations = 5;     ///< loop_fusion's optimize4DoF: 5
  int queue_size = 100000;         ///< messages waiting to be processed (inbox and subscriber queues), >= 1000
};

class VerifierNode {
 public:
  /// nh: where the input topics are resolved; pnh: the private namespace (parameters, outputs).
  VerifierNode(const ros::NodeHandle& nh, const ros::NodeHandle& pnh);
  ~VerifierNode();

  /// Reads the parameters, loads and initialises the plugin, advertises and subscribes.
  /// false with *error naming the parameter when the node cannot run.
  bool start(std::string* error);

  /// Runs the main thread's callbacks until ros::ok() ends, `stop` is set (a signal handler's
  /// flag) or the master restarted, then finish(). Returns the process's exit status: 0, or 2
  /// when the master restarted.
  int spin(const std::atomic<bool>& stop);

  /// Stops taking messages and gives every candidate not decided yet (waiting, or still in
  /// the inbox) an invalid_input verdict "not verified: the node was shut down"; logs what
  /// was left undone. Call while ROS is still up.
  void finish();

  size_t verdictCount() const { return host_.output().published(); }

  /// Processes everything in the inbox now (the main thread does this on its own; for tests).
  void drainInbox();

 private:
  /// The node's own parameters (start()): read, checked, errors in the host's reader.
  void readParams();
  /// The paths, the ~optimize service, the subscriptions (on their own thread) and the timers.
  void connect();
  typedef WaitingCandidates<LoopCandidate>::Wait WaitKey;
  enum class Resolution { kFound, kWait, kInvalid };
  /// A message as received: exactly one of the two is set, or neither for a keyframe that
  /// arrived when the inbox was full (dropped: only its stamp is kept). `dropped`: not to be
  /// processed (the inbox was full): a keyframe is refused, a candidate rejected.
  struct Incoming {
    nav_msgs::Odometry::ConstPtr keyframe;
    LoopCandidate::ConstPtr candidate;
    bool dropped = false;
    int64_t dropped_stamp_ns = 0;
    double received = 0.0;  ///< [s, wall clock] when the receiver thread took it
  };
  class DrainCallback;

  /// Receiver thread: appends to the inbox and schedules a drain on the main thread.
  void receive(Incoming item);
  /// Main thread: processes up to `max_items` messages from the inbox; reschedules itself
  /// if more are waiting (so that timers and the service still get their turn).
  void drainSome(size_t max_items);
  void onKeyframe(const nav_msgs::Odometry::ConstPtr& msg);
  /// A keyframe or candidate message that arrived when the inbox was full, in its turn.
  void onDropped(const Incoming& item);
  /// Why a dropped message was not processed (names queue_size).
  std::string droppedText() const;
  void onCandidate(const LoopCandidate::ConstPtr& msg);
  bool onOptimize(Optimize::Request& req, Optimize::Response& res);
  void onPendingTimer(const ros::WallTimerEvent&);
  void onOptimizeTimer(const ros::WallTimerEvent&);
  void onWatchdog(const ros::WallTimerEvent&);

  void addKeyframe(const nav_msgs::Odometry& msg, int64_t index);
  void refuseKeyframe(int64_t index, int64_t ns, const std::string& why);
  /// Decides what can be decided about a candidate: verifies or rejects it (true), or it has to
  /// wait for its query keyframe (and maybe its match): false, with what it waits for.
  /// settled: the candidate waited candidate_timeout; a stamp of a keyframe stamped late names it.
  bool tryDecide(const LoopCandidate& msg, std::vector<WaitKey>* waits, bool settled = false);
  /// Keyframe `index`, kept with stamp `ns`, is named by it: a stamp the keyframe kept before
  /// carries too (the clock stopped) names none of them (shared_stamps_); one an earlier keyframe
  /// carries (stamped wrong) names the newer one from now on.
  void nameByStamp(int64_t ns, int64_t index);
  WaitKey waitKey(int64_t index, const ros::Time& stamp) const;
  /// Re-examines the waiting candidates that a keyframe with stamp `ns` / number `index` may
  /// have resolved, in arrival order.
  void wake(int64_t ns, int64_t index);
  /// Rejects the candidates that waited longer than candidate_timeout.
  void expire();
  Resolution resolve(int64_t index, const ros::Time& stamp, const char* role, int64_t* found,
                     std::string* why, bool settled = false) const;
  void verify(const LoopCandidate& msg, int64_t query, int64_t match);
  /// Adds an accepted or released loop to the node's pose graph; a refusal turns *v into an
  /// invalid_input rejection.
  void useLoop(const core::LoopCandidate& c, core::Verdict* v);
  /// The verifier's later decisions (after every keyframe and verification): a release adds
  /// the loop to the node's pose graph, a revocation removes it; each gets its verdict.
  void applyDecisions();
  void reject(const LoopCandidate& msg, int64_t query, int64_t match, const std::string& why, bool log = true);
  void publishVerdict(const core::Verdict& v, const LoopCandidate& msg, bool log = true,
                      const char* decision = "verify");
  /// Runs loop_fusion's optimisation on the graph and publishes the paths (into *out too).
  void optimizeAndPublish(Optimize::Response* out);

  ros::NodeHandle nh_, pnh_;
  VerifierHost host_;
  VerifierNodeParams params_;
  /// loop_fusion's pose graph: every keyframe and the loops this node accepted, whatever the
  /// plugin; solved like loop_fusion (solveLikeLoopFusion) for ~pose_graph_path.
  std::unique_ptr<core::KeyframeGraph> graph_;
  ros::Subscriber keyframe_sub_, candidate_sub_;
  ros::Publisher odometry_path_pub_, pose_graph_path_pub_, estimate_path_pub_;
  ros::ServiceServer optimize_srv_;
  ros::WallTimer pending_timer_, optimize_timer_, watchdog_timer_;

  // Receiving (see "Threading" above). The spinner is declared last among these so that it is
  // destroyed (stopped) first.
  ros::CallbackQueue receive_queue_;
  std::mutex inbox_mutex_;
  std::deque<Incoming> inbox_;
  bool drain_scheduled_ = false;
  bool receiving_ = true;
  size_t inbox_peak_ = 0;
  size_t inbox_dropped_ = 0;   // messages that arrived when the inbox was full
  size_t inbox_overflow_ = 0;  // of those, still in the inbox
  std::unique_ptr<ros::AsyncSpinner> receiver_;

  const std::atomic<bool>* stop_ = nullptr;  // set by spin(): checked between messages
  int exit_code_ = 0;
  std::string run_id_;        // the master's /run_id at start
  bool master_lost_ = false;

  int64_t next_index_ = 0;               // number of the next keyframe message
  std::map<int64_t, int64_t> by_stamp_;  // stamp [ns] -> index, keyframes in the graph
  std::map<int64_t, int64_t> stamp_of_;  // index -> stamp [ns], keyframes in the graph
  std::map<int64_t, std::string> refused_by_index_;  // the last kRefusedKept refused keyframe messages
  std::map<int64_t, int64_t> refused_by_stamp_;  // stamp -> index of those (stamps no graph keyframe has)
  std::deque<std::pair<int64_t, int64_t>> refused_order_;  // (index, stamp) oldest first
  RepeatedWarning refused_warning_;
  std::set<int64_t> shared_stamps_;  // stamps consecutive graph keyframes carry (the clock stopped)
  bool have_keyframe_ = false;
  int64_t newest_stamp_ns_ = 0;  // newest stamp of a keyframe in the graph
  int64_t last_kept_ns_ = 0;      // stamp of the newest keyframe in the graph
  std::deque<std::pair<int64_t, int64_t>> recent_kept_;  // (index, stamp) of the newest keyframes in the graph
  std::set<int64_t> stamped_late_;  // keyframes in the graph stamped after a keyframe kept after them

  // Candidates waiting for their keyframes (received: when the node took them from the inbox).
  WaitingCandidates<LoopCandidate> waiting_;

  bool changed_ = false;  // keyframes or loops since the last optimisation
  size_t keyframes_refused_ = 0;
};

}  // namespace rover_loop_fusion
