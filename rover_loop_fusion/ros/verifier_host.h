// One start-up for both hosts of a verifier plugin, the patched loop_fusion (through
// LoopFusionAdapter) and rover_verifier_node: they read the keys they share the same way
// (HostParamReader: typed, range-checked, and every key remembered so that anything else in
// the namespace is reported as a possible typo), load the plugin with pluginlib, start it
// with what the host knows about itself (HostInfo), set up the verdict output, and decide and
// publish with the same rules: only a committed loop is usable, every decision gets exactly
// one verdict, nothing thrown reaches the host.
//
// Shared keys (the host's private namespace): verifier_type, verifier_name, verdict_log,
// publish_markers, relocalisation, and the frame (the adapter: marker_frame; the node:
// frame_id). The plugin reads its own under <namespace>/<verifier_name>/.
#pragma once

#include "rover_loop_fusion/ros/conversions.h"
#include "rover_loop_fusion/ros/loop_verifier.h"
#include "rover_loop_fusion/ros/params.h"
#include "rover_loop_fusion/ros/verdict_output.h"

#include <ros/node_handle.h>
#include <ros/time.h>

#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {

/// A verifier instance. For plugins the deleter keeps pluginlib's class loader alive until
/// the instance is gone (the loader must outlive what it created).
typedef std::unique_ptr<LoopVerifier, std::function<void(LoopVerifier*)>> VerifierPtr;

extern const char kTrajectoryPriorVerifierType[];  ///< "rover_loop_fusion/TrajectoryPriorVerifier"
extern const char kAcceptAllVerifierType[];        ///< "rover_loop_fusion/AcceptAllVerifier"

/// The plugin type for a configured name: the short names `rover` and `accept_all` (as in the
/// launch files' verifier:= argument) or a full pluginlib type, returned unchanged.
std::string resolveVerifierType(const std::string& type_or_alias);

/// Verifier parameters the host sets (HostInfo), never a YAML: anchor_incoming_keyframes
/// (from shifts_sequences: a wrong value shifts sessions twice or not at all),
/// accept_without_prior and confirm_without_prior (from ~relocalisation).
const std::vector<std::string>& hostDerivedVerifierParameters();

/// What a host logs of a warning the verifier's addKeyframe returned for keyframe `index`:
/// "verifier, keyframe N: <message>", the keyframe named once (the graph's own warnings name it).
std::string keyframeWarning(int64_t index, const std::string& message);

/// An invalid_input rejection of c that says why.
core::Verdict rejection(const core::LoopCandidate& c, const std::string& detail);

/// Reads the parameters of one private namespace: a present key of the wrong type or out of
/// range is an error naming the full parameter; an absent key keeps the default. Every key
/// read is remembered for unknownKeys().
class HostParamReader {
 public:
  explicit HostParamReader(const ros::NodeHandle& nh);
  void text(const std::string& key, std::string* value, bool allow_empty = true);
  void boolean(const std::string& key, bool* value);
  void integer(const std::string& key, int* value, int lo, int hi);
  /// [lo, hi], in `unit`; NaN is out of range.
  void number(const std::string& key, double* value, double lo, double hi, const char* unit);
  void error(const std::string& key, const std::string& what);
  const std::vector<std::string>& errors() const { return errors_; }
  /// Keys directly in the namespace that nobody read, and sub-namespaces other than
  /// `known_namespaces`, as warnings ("unknown parameter /n/x (ignored; a typo?)").
  std::vector<std::string> unknownKeys(const std::vector<std::string>& known_namespaces) const;

 private:
  ros::NodeHandle nh_;
  std::vector<std::string> errors_;
  ParamReader reader_;
  std::vector<std::string> keys_;
};

/// A warning that can repeat for every message of a stream (refused keyframes): the first
/// `individually` are logged one by one, then at most one summary every `period_s` seconds with
/// the count and the latest text, and one more from flush(). Bounded log volume, nothing
/// hidden without a count.
class RepeatedWarning {
 public:
  explicit RepeatedWarning(size_t individually = 20, double period_s = 10.0)
      : individually_(individually), period_s_(period_s) {}
  void warn(const std::string& text);
  /// Logs the summary of what was held back since the last one.
  void flush();
  /// That summary, for a host that must print it elsewhere (after ros::shutdown() rosconsole
  /// prints nothing); "" if nothing was held back.
  std::string takeSummary();
  size_t count() const { return count_; }

 private:
  size_t individually_;
  double period_s_;
  size_t count_ = 0;
  size_t held_back_ = 0;
  std::string latest_;
  ros::WallTime last_summary_;
};

/// The shared keys.
struct HostParams {
  std::string verifier_type = kTrajectoryPriorVerifierType;  ///< or rover / accept_all
  std::string verifier_name = "rover";
  std::string verdict_log;  ///< CSV file every verdict is appended to; empty: off
  bool publish_markers = true;
  std::string frame_id = "world";
  Relocalisation relocalisation = Relocalisation::kConfirm;
};

class VerifierHost {
 public:
  /// Looks up a keyframe position for a marker when the verifier keeps no trajectory.
  typedef std::function<bool(int64_t index, Eigen::Vector3d* position)> PositionLookup;
  struct Start {
    std::vector<std::string> errors;  ///< the host's parameters or output: fix them
    std::string verifier_error;       ///< the plugin could not be loaded or started
  };

  /// nh: the host's private namespace; frame_key: the key of its frame parameter.
  VerifierHost(const ros::NodeHandle& nh, const std::string& frame_key);

  /// The reader the host reads its own keys with, before start().
  HostParamReader& reader() { return reader_; }

  /// Reads the shared keys, warns about unknown ones, opens the output (verdict_queue: see
  /// VerdictOutput::Options), then loads and starts the plugin named by verifier_type (or
  /// `injected`, reported as `injected_type`). Stops at the first stage that fails. Logs the
  /// host's settings at INFO; the plugin logs its decision parameters.
  Start start(const HostInfo& info, int verdict_queue, VerifierPtr injected = VerifierPtr(),
              const std::string& injected_type = "");

  const HostParams& params() const { return params_; }
  /// The plugin type (resolved; the injected one's name).
  const std::string& verifierType() const { return type_; }
  /// null if start() failed or after stopVerifier().
  LoopVerifier* verifier() { return verifier_.get(); }
  void stopVerifier() { verifier_.reset(); }
  bool outputReady() const { return output_ready_; }
  const VerdictOutput& output() const { return output_; }
  /// VerdictOutput::flushLog (a host that ends: its last verdicts into the CSV log).
  size_t flushLog(double timeout_s) { return output_.flushLog(timeout_s); }
  std::string resolve(const std::string& key) const { return nh_.resolveName(key); }

  /// One decision: verify(c) and, if accepted, commit(c). A refused commit or anything the
  /// plugin throws gives an invalid_input rejection (logged). A deferred verdict (held) is
  /// passed on: takeDecisions() later says what became of the candidate. Needs a running
  /// verifier.
  core::Verdict decide(const core::LoopCandidate& c) noexcept;

  /// The plugin's decisions since the last call (LoopVerifier::takeDecisions), each verdict
  /// final (not deferred) and naming the decision's candidate; empty if it threw (logged) or
  /// no verifier runs. Call after every addKeyframe() and decide(). A decision about a
  /// candidate decide() held or accepted keeps the numbers of that verdict (score, threshold,
  /// innovation, window, times: what verify() measured) and takes accepted and reason from the
  /// decision, its detail "<decision>: <why> (at verify: <detail>)": the same final verdict as
  /// rover_replay's row of the candidate.
  std::vector<core::LoopDecision> takeDecisions() noexcept;

  /// A host that ends: every candidate decide() held and no decision has ended yet gets its
  /// final verdict, a drop (unconfirmed, `why`) with its numbers at verify, as takeDecisions()
  /// gives them; nothing is held afterwards. Call takeDecisions() first (what the verifier
  /// decided last).
  std::vector<core::LoopDecision> dropHeld(const std::string& why) noexcept;
  /// Candidates decide() held that no decision has ended yet.
  size_t heldCount() noexcept;

  /// Logs v (INFO; WARN for invalid_input and revoked) as "<what> accepted/HELD/REJECTED/
  /// REVOKED ..." (not if `what` is empty: the caller sums such verdicts up) and publishes it
  /// (ctx.decision: verify, or the later release/drop/revoke) with a marker at the verifier's
  /// estimate of the two keyframes (else at `fallback`). A failure to draw the marker leaves
  /// it out; false if the verdict could not be published (logged). Never throws.
  bool publish(const core::Verdict& v, VerdictContext ctx, const std::string& what,
               const PositionLookup& fallback = PositionLookup()) noexcept;

 private:
  ros::NodeHandle nh_;
  std::string frame_key_;
  HostParamReader reader_;
  HostParams params_;
  std::string type_;
  VerifierPtr verifier_;
  VerdictOutput output_;
  bool output_ready_ = false;
  /// decide()'s verdicts by (query, match): of the candidates held (in order: the same loop may
  /// be proposed again while held) until their release or drop, and of the loops in use until
  /// their revocation (a released loop's merged verdict replaces its deferred one).
  struct Open {
    core::LoopCandidate candidate;
    core::Verdict verdict;
  };
  std::map<std::pair<int64_t, int64_t>, std::deque<Open>> held_;
  std::map<std::pair<int64_t, int64_t>, core::Verdict> loops_;
  /// `at_verify` (the verdict decide() gave) with the outcome of decision `kind` (`decided`).
  static core::Verdict finalVerdict(core::Verdict at_verify, core::LoopDecision::Kind kind,
                                    const core::Verdict& decided);
  std::mutex open_mutex_;
};

}  // namespace rover_loop_fusion
