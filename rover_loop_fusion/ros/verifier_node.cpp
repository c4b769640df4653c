#include "rover_loop_fusion/ros/verifier_node.h"

#include "rover_loop_fusion/core/parameters.h"
#include "rover_loop_fusion/ros/conversions.h"
#include "rover_loop_fusion/ros/guarded.h"
#include "rover_loop_fusion/ros/params.h"

#include <Eigen/Geometry>
#include <boost/make_shared.hpp>
#include <nav_msgs/Path.h>
#include <ros/master.h>
#include <ros/names.h>

#include <algorithm>
#include <cmath>
#include <iterator>
#include <limits>
#include <sstream>
#include <vector>

namespace rover_loop_fusion {

namespace {

const size_t kRefusedKept = 10000;  // refused keyframe messages remembered to explain verdicts
/// Kept keyframes a new one is compared with to find those stamped late (the intake keeps at
/// most jump_confirmations - 1 in a row, and jump_confirmations is at most 100).
const size_t kRecentKept = 100;
/// The least inbox: what arrives while one verification or optimisation runs (a bag at 400
/// keyframes/s and a 200 ms time budget: 80 messages; loop_fusion's optimisation of a long run
/// on the main thread: seconds). A smaller ~queue_size is raised to it with a ROS_WARN.
const int kMinQueueSize = 1000;
/// The largest keyframe number a candidate can name (loop_fusion's indices are int).
const int64_t kMaxKeyframeNumber = std::numeric_limits<int32_t>::max();

/// What a later decision's verdict is published with: its candidate as handed to verify()
/// (keyframes by number, inliers); the stamps come from the keyframes (publishVerdict).
LoopCandidate candidateMsg(const core::LoopCandidate& c) {
  LoopCandidate msg;
  msg.query_index = c.query_index;
  msg.match_index = c.match_index;
  msg.inliers = c.inliers;
  return msg;
}

/// Nearest entry of `m` (keyed by stamp [ns]) within `tol` of `ns`; end() if none.
template <typename Map>
typename Map::const_iterator nearest(const Map& m, int64_t ns, int64_t tol) {
  auto best = m.end();
  auto it = m.lower_bound(ns);
  if (it != m.end() && it->first - ns <= tol) best = it;
  if (it != m.begin()) {
    auto prev = std::prev(it);
    if (ns - prev->first <= tol && (best == m.end() || ns - prev->first < best->first - ns)) best = prev;
  }
  return best;
}

int64_t toNs(const ros::Time& t) { return static_cast<int64_t>(t.toNSec()); }

}  // namespace

VerifierNode::VerifierNode(const ros::NodeHandle& nh, const ros::NodeHandle& pnh)
    : nh_(nh), pnh_(pnh), host_(pnh, "frame_id") {}

/// Runs one drainSome() on the main thread's callback queue.
class VerifierNode::DrainCallback : public ros::CallbackInterface {
 public:
  explicit DrainCallback(VerifierNode* node) : node_(node) {}
  CallResult call() override {
    node_->drainSome(kBatch);
    return Success;
  }
  static constexpr size_t kBatch = 200;

 private:
  VerifierNode* node_;
};

VerifierNode::~VerifierNode() {
  if (receiver_) receiver_->stop();
  keyframe_sub_.shutdown();
  candidate_sub_.shutdown();
  // Drain callbacks still on the global queue point at this node.
  ros::getGlobalCallbackQueue()->removeByID(reinterpret_cast<uint64_t>(this));
}

void VerifierNode::readParams() {
  VerifierNodeParams& p = params_;
  HostParamReader& r = host_.reader();
  r.text("keyframe_topic", &p.keyframe_topic, false);
  r.text("candidate_topic", &p.candidate_topic, false);
  r.integer("sequence", &p.sequence, 1, 1000000);
  r.boolean("use_imu", &p.use_imu);
  r.number("candidate_timeout", &p.candidate_timeout, 0.0, 86400.0, "s");
  r.number("stamp_tolerance", &p.stamp_tolerance, 0.0, 0.5, "s");
  r.number("optimize_period", &p.optimize_period, 0.0, 86400.0, "s");
  if (p.optimize_period > 0.0 && p.optimize_period < 0.1) {
    std::ostringstream got;
    got << p.optimize_period;
    r.error("optimize_period", "must be 0 (on ~optimize only) or at least 0.1 s (got " + got.str() + ")");
  }
  r.integer("optimize_iterations", &p.optimize_iterations, 1, 1000);
  r.integer("queue_size", &p.queue_size, 1, 10000000);
  if (p.queue_size >= 1 && p.queue_size < kMinQueueSize) {
    ROS_WARN("[rover] %s=%d cannot hold a burst of messages (what arrives during one verification or "
             "optimisation): raised to %d. Messages beyond the inbox are not processed (a keyframe is refused, a "
             "candidate gets an invalid_input verdict)",
             host_.resolve("queue_size").c_str(), p.queue_size, kMinQueueSize);
    p.queue_size = kMinQueueSize;
  }
  const std::pair<const char*, const std::string*> topics[] = {{"keyframe_topic", &p.keyframe_topic},
                                                               {"candidate_topic", &p.candidate_topic}};
  for (const auto& topic : topics) {
    std::string why;
    if (!topic.second->empty() && !ros::names::validate(*topic.second, why))
      r.error(topic.first, "is not a valid topic name: " + why);
  }
}

void VerifierNode::connect() {
  const VerifierNodeParams& p = params_;
  odometry_path_pub_ = pnh_.advertise<nav_msgs::Path>("odometry_path", 1, true);
  pose_graph_path_pub_ = pnh_.advertise<nav_msgs::Path>("pose_graph_path", 1, true);
  estimate_path_pub_ = pnh_.advertise<nav_msgs::Path>("estimate_path", 1, true);
  optimize_srv_ = pnh_.advertiseService("optimize", &VerifierNode::onOptimize, this);
  ros::SubscribeOptions ko = ros::SubscribeOptions::create<nav_msgs::Odometry>(
      p.keyframe_topic, p.queue_size,
      [this](const nav_msgs::Odometry::ConstPtr& m) { receive(Incoming{m, nullptr}); }, ros::VoidPtr(),
      &receive_queue_);
  ros::SubscribeOptions co = ros::SubscribeOptions::create<LoopCandidate>(
      p.candidate_topic, p.queue_size, [this](const LoopCandidate::ConstPtr& m) { receive(Incoming{nullptr, m}); },
      ros::VoidPtr(), &receive_queue_);
  keyframe_sub_ = nh_.subscribe(ko);
  candidate_sub_ = nh_.subscribe(co);
  receiver_.reset(new ros::AsyncSpinner(1, &receive_queue_));
  receiver_->start();
  pending_timer_ = nh_.createWallTimer(ros::WallDuration(0.1), &VerifierNode::onPendingTimer, this);
  if (p.optimize_period > 0)
    optimize_timer_ = nh_.createWallTimer(ros::WallDuration(p.optimize_period), &VerifierNode::onOptimizeTimer, this);
  if (!ros::param::get("/run_id", run_id_)) run_id_.clear();
  watchdog_timer_ = nh_.createWallTimer(ros::WallDuration(1.0), &VerifierNode::onWatchdog, this);
}

bool VerifierNode::start(std::string* error) {
  readParams();
  VerifierNodeParams& p = params_;
  HostInfo info;
  info.uses_imu = p.use_imu;
  info.shifts_sequences = false;  // raw VIO poses: the verifier anchors sequences itself
  VerifierHost::Start s = host_.start(info, p.queue_size);
  if (!s.errors.empty() || !s.verifier_error.empty()) {
    std::vector<std::string> all = s.errors;
    if (!s.verifier_error.empty()) all.push_back(s.verifier_error);
    *error = all[0];
    for (size_t i = 1; i < all.size(); ++i) *error += "; " + all[i];
    return false;
  }

  core::VerifierConfig g;  // loop_fusion's graph: its fixed odometry neighbours and Huber loss
  g.mode = p.use_imu ? core::Mode::kFourDof : core::Mode::kSixDof;
  g.host.anchor_incoming_keyframes = true;
  // One keyframe policy: the graph takes the keyframes the verifier takes. Both run the core's
  // intake with the plausibility limits of the verifier's namespace (the table's defaults where
  // it sets none), so a stamp or pose fault refuses the same keyframes in both (the node's graph
  // numbers keyframes for candidates; a keyframe only one of them had made loops into it
  // invalid). A plugin with other rules (accept_all keeps every keyframe) leaves the node's.
  {
    const ConfigLoad limits = loadVerifierConfig(ros::NodeHandle(pnh_, host_.params().verifier_name), p.use_imu);
    g.input.max_keyframe_jump = limits.config.input.max_keyframe_jump;
    g.input.max_stamp_jump = limits.config.input.max_stamp_jump;
    g.input.jump_confirmations = limits.config.input.jump_confirmations;
  }
  graph_.reset(new core::KeyframeGraph(g));

  connect();
  ROS_INFO("[rover] %s: candidates from %s, keyframes from %s (sequence %d, %s); candidate_timeout %.3g s, "
           "stamp_tolerance %.3g s, optimize_period %.3g s, queue_size %d",
           ros::this_node::getName().c_str(), candidate_sub_.getTopic().c_str(), keyframe_sub_.getTopic().c_str(),
           p.sequence, p.use_imu ? "4-DoF" : "6-DoF", p.candidate_timeout, p.stamp_tolerance, p.optimize_period,
           p.queue_size);
  return true;
}

int VerifierNode::spin(const std::atomic<bool>& stop) {
  stop_ = &stop;
  ros::CallbackQueue* queue = ros::getGlobalCallbackQueue();
  while (ros::ok() && !stop && exit_code_ == 0) queue->callAvailable(ros::WallDuration(0.1));
  // Also when the master restarted (exit status 2): the verdicts cannot reach a subscriber
  // then, but the CSV log gets every candidate's final verdict.
  finish();
  return exit_code_;
}

void VerifierNode::finish() {
  guarded("shutting down", [&] {
    if (receiver_) receiver_->stop();
    keyframe_sub_.shutdown();
    candidate_sub_.shutdown();
    std::deque<Incoming> inbox;
    {
      std::lock_guard<std::mutex> lock(inbox_mutex_);
      receiving_ = false;
      inbox.swap(inbox_);
      inbox_overflow_ = 0;
    }
    const size_t waiting = waiting_.size();
    size_t unprocessed_keyframes = 0, unprocessed_candidates = 0;
    for (uint64_t id : waiting_.ids())
      reject(waiting_.take(id), -1, -1, "not verified: the node was shut down while the candidate waited for its "
             "keyframes", false);
    // Held candidates get their final verdict too: what the last message decided, then a drop
    // for what nothing confirmed before the end.
    applyDecisions();
    const std::vector<core::LoopDecision> dropped = host_.dropHeld("still held when the node was shut down");
    const size_t held = dropped.size();
    for (const core::LoopDecision& d : dropped) publishVerdict(d.verdict, candidateMsg(d.candidate), false, "drop");
    for (const Incoming& item : inbox) {
      if (!item.candidate) {
        ++unprocessed_keyframes;
        continue;
      }
      ++unprocessed_candidates;
      reject(*item.candidate, -1, -1,
             item.dropped ? "not verified: " + droppedText()
                          : "not verified: the node was shut down before it got to the candidate",
             false);
    }
    refused_warning_.flush();
    if (inbox_dropped_ > 0)
      ROS_ERROR("[rover] %zu messages arrived when the inbox was full (queue_size=%d) and were not processed: "
                "keyframes refused, candidates rejected (invalid_input)",
                inbox_dropped_, params_.queue_size);
    ROS_INFO("[rover] %s shutting down: %zu verdicts published; %zu candidates not verified (%zu waiting for "
             "keyframes, %zu not processed) got an invalid_input verdict saying so; %zu held candidates not "
             "confirmed got an unconfirmed verdict; %zu keyframe messages not processed",
             ros::this_node::getName().c_str(), host_.output().published(), waiting + unprocessed_candidates,
             waiting, unprocessed_candidates, held, unprocessed_keyframes);
    // roscpp sends on its own threads and has no flush: give the last verdicts time to leave.
    if (waiting + unprocessed_candidates + held > 0) ros::WallDuration(0.5).sleep();
  });
}

// ---- input -----------------------------------------------------------------------------------

void VerifierNode::receive(Incoming item) {
  bool schedule = false;
  item.received = ros::WallTime::now().toSec();
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    if (!receiving_) return;
    if (inbox_.size() - inbox_overflow_ >= static_cast<size_t>(params_.queue_size)) {
      // Not processed, but not lost either: it keeps its place, so that a keyframe keeps its
      // number and is refused with a reason, and a candidate gets its verdict. A keyframe keeps
      // only its stamp (the inbox bounds what full messages wait).
      ++inbox_dropped_;
      ++inbox_overflow_;
      ROS_ERROR_THROTTLE(1.0, "[rover] %s message not processed: %zu messages are waiting (queue_size=%d; %zu not "
                         "processed so far); verification is slower than the input. %s",
                         item.keyframe ? "keyframe" : "loop candidate", inbox_.size(), params_.queue_size,
                         inbox_dropped_,
                         item.keyframe ? "The keyframe is refused" : "The candidate gets an invalid_input verdict");
      item.dropped = true;
      if (item.keyframe) {
        item.dropped_stamp_ns = toNs(item.keyframe->header.stamp);
        item.keyframe.reset();
      }
    }
    inbox_.push_back(std::move(item));
    if (inbox_.size() > inbox_peak_) {
      inbox_peak_ = inbox_.size();
      if (inbox_peak_ % 1000 == 0)
        ROS_WARN("[rover] %zu messages waiting to be processed: verification is slower than the input",
                 inbox_peak_);
    }
    if (!drain_scheduled_) drain_scheduled_ = schedule = true;
  }
  if (schedule)
    ros::getGlobalCallbackQueue()->addCallback(boost::make_shared<DrainCallback>(this),
                                               reinterpret_cast<uint64_t>(this));
}

void VerifierNode::drainSome(size_t max_items) {
  expire();
  for (size_t n = 0;; ++n) {
    Incoming item;
    {
      std::lock_guard<std::mutex> lock(inbox_mutex_);
      if (inbox_.empty() || !receiving_) {
        drain_scheduled_ = false;
        return;
      }
      // Stopping: leave the rest to finish(), which says what was not processed.
      if ((stop_ && *stop_) || exit_code_ != 0) return;
      if (n == max_items) break;  // still scheduled: comes back after the other callbacks
      item = std::move(inbox_.front());
      inbox_.pop_front();
      if (item.dropped) --inbox_overflow_;
    }
    if (item.dropped) onDropped(item);
    else if (item.keyframe) onKeyframe(item.keyframe);
    else if (item.candidate) onCandidate(item.candidate);
  }
  ros::getGlobalCallbackQueue()->addCallback(boost::make_shared<DrainCallback>(this),
                                             reinterpret_cast<uint64_t>(this));
}

void VerifierNode::drainInbox() { drainSome(static_cast<size_t>(-1)); }

void VerifierNode::onKeyframe(const nav_msgs::Odometry::ConstPtr& msg) {
  guarded("keyframe message", [&] {
    const int64_t index = next_index_++;
    addKeyframe(*msg, index);
    wake(toNs(msg->header.stamp), index);
  });
}

std::string VerifierNode::droppedText() const {
  return "it arrived when the node's inbox was full (queue_size=" + std::to_string(params_.queue_size) +
         " messages waiting: verification is slower than the input)";
}

void VerifierNode::onDropped(const Incoming& item) {
  guarded("message not processed", [&] {
    if (item.candidate) {
      const LoopCandidate& msg = *item.candidate;
      int64_t q = -1, m = -1;
      std::string ignored;
      resolve(msg.query_index, msg.query_stamp, "query", &q, &ignored);
      resolve(msg.match_index, msg.match_stamp, "match", &m, &ignored);
      reject(msg, q, m, "not verified: " + droppedText());
      return;
    }
    const int64_t index = next_index_++;
    refuseKeyframe(index, item.dropped_stamp_ns, "not processed: " + droppedText());
    wake(item.dropped_stamp_ns, index);  // candidates waiting for it: rejected, saying why
  });
}

void VerifierNode::onCandidate(const LoopCandidate::ConstPtr& msg) {
  guarded("loop candidate message", [&] {
    std::vector<WaitKey> waits;
    if (!tryDecide(*msg, &waits)) waiting_.add(*msg, ros::WallTime::now().toSec(), waits);
  });
}

void VerifierNode::onPendingTimer(const ros::WallTimerEvent&) {
  guarded("deciding waiting candidates", [&] { expire(); });
}

void VerifierNode::addKeyframe(const nav_msgs::Odometry& msg, int64_t index) {
  const int64_t ns = toNs(msg.header.stamp);
  const geometry_msgs::Point& pos = msg.pose.pose.position;
  const geometry_msgs::Quaternion& ori = msg.pose.pose.orientation;
  const Eigen::Vector3d t(pos.x, pos.y, pos.z);
  const Eigen::Quaterniond q(ori.w, ori.x, ori.y, ori.z);
  // The core's intake decides (a repeat, out-of-order stamps, a late stamp, a stopped clock,
  // jumps): the ordering rules live in one place, the same as the verifier's. The verifier sees
  // every keyframe message the node's graph sees, refused ones too, so that a run of refused
  // keyframes (a relocation, a new clock) is confirmed in both at the same keyframe.
  const double stamp = msg.header.stamp.toSec();
  const core::Status s = graph_->addKeyframe(index, stamp, params_.sequence, t, q);
  core::Status added;
  std::string threw;
  if (!guarded("verifier " + host_.verifierType() + ": addKeyframe " + std::to_string(index),
               [&] { added = host_.verifier()->addKeyframe(index, stamp, params_.sequence, t, q); }, &threw))
    added = core::Status::Error("the verifier threw: " + threw);
  if (!s.ok) {
    refuseKeyframe(index, ns, s.message);
  } else {
    if (s.warning()) ROS_WARN("[rover] keyframe message %ld: %s", static_cast<long>(index), s.message.c_str());
    nameByStamp(ns, index);
    stamp_of_[index] = ns;
    newest_stamp_ns_ = have_keyframe_ ? std::max(newest_stamp_ns_, ns) : ns;
    have_keyframe_ = true;
    changed_ = true;
    if (added.warning() && added.message != s.message)
      ROS_WARN("[rover] %s", keyframeWarning(index, added.message).c_str());
    if (!added.ok)
      refused_warning_.warn("keyframe " + std::to_string(index) + " not added to the verifier (" + added.message +
                            "); loops that involve it are rejected");
  }
  applyDecisions();
}

void VerifierNode::nameByStamp(int64_t ns, int64_t index) {
  const bool stopped = have_keyframe_ && last_kept_ns_ == ns;  // the same stamp as the keyframe kept before
  last_kept_ns_ = ns;
  // Recent keyframes stamped after this one were stamped late (the intake kept this one as
  // plausibly after the keyframe before them).
  for (const std::pair<int64_t, int64_t>& r : recent_kept_)
    if (r.second > ns) stamped_late_.insert(r.first);
  recent_kept_.emplace_back(index, ns);
  if (recent_kept_.size() > kRecentKept) recent_kept_.pop_front();
  if (stamped_late_.size() > kRefusedKept) stamped_late_.erase(stamped_late_.begin());
  auto named = by_stamp_.emplace(ns, index);
  if (named.second || shared_stamps_.count(ns)) return;
  if (stopped) {
    // Consecutive keyframes with one stamp: the clock stopped, and the stamp names none of them.
    shared_stamps_.insert(ns);
    return;
  }
  // An earlier keyframe, not the one before, carries this stamp: its stamp was the wrong one (one
  // stamped late onto a stamp still to come, or the clock went back past it). The stamp names the
  // keyframe that carries it in order; the earlier one keeps its number as its name.
  const int64_t earlier = named.first->second;
  named.first->second = index;
  ROS_WARN("[rover] keyframe message %ld: stamp %s is keyframe %ld's too, which came earlier out of order (its stamp "
           "was wrong): the stamp names keyframe %ld from now on; name keyframe %ld by its number",
           static_cast<long>(index), stampText(rosTimeFromNs(ns)).c_str(), static_cast<long>(earlier),
           static_cast<long>(index), static_cast<long>(earlier));
}

void VerifierNode::refuseKeyframe(int64_t index, int64_t ns, const std::string& why) {
  ++keyframes_refused_;
  refused_by_index_[index] = why;
  if (!by_stamp_.count(ns)) refused_by_stamp_[ns] = index;
  refused_order_.emplace_back(index, ns);
  if (refused_order_.size() > kRefusedKept) {
    const std::pair<int64_t, int64_t> old = refused_order_.front();
    refused_order_.pop_front();
    refused_by_index_.erase(old.first);
    auto same = refused_by_stamp_.find(old.second);
    if (same != refused_by_stamp_.end() && same->second == old.first) refused_by_stamp_.erase(same);
  }
  refused_warning_.warn("keyframe message " + std::to_string(index) + " (stamp " + stampText(rosTimeFromNs(ns)) +
                        ") refused: " + why + "; loop candidates that name it get invalid_input");
}

VerifierNode::Resolution VerifierNode::resolve(int64_t index, const ros::Time& stamp, const char* role,
                                               int64_t* found, std::string* why, bool settled) const {
  const std::string who = std::string(role) + " keyframe ";
  if (index < -1) {
    *why = who + "index " + std::to_string(index) + " is negative (-1 names a keyframe by its stamp)";
    return Resolution::kInvalid;
  }
  if (index > kMaxKeyframeNumber) {
    // No keyframe can ever have it: invalid now, not after candidate_timeout.
    *why = who + "index " + std::to_string(index) + " cannot name a keyframe (keyframes are numbered in arrival "
           "order, at most " + std::to_string(kMaxKeyframeNumber) + " as loop_fusion's int indices)";
    return Resolution::kInvalid;
  }
  if (index >= 0) {
    if (stamp_of_.count(index)) {
      *found = index;
      return Resolution::kFound;
    }
    auto refused = refused_by_index_.find(index);
    if (refused != refused_by_index_.end()) {
      *found = index;  // (named in the verdict: the keyframe message had that number)
      *why = who + std::to_string(index) + " was refused (" + refused->second + ")";
      return Resolution::kInvalid;
    }
    if (index < next_index_) {
      *why = who + std::to_string(index) + " was refused";
      return Resolution::kInvalid;
    }
    *why = who + std::to_string(index) + " has not arrived";
    return Resolution::kWait;
  }
  const int64_t ns = toNs(stamp);
  const int64_t tol = static_cast<int64_t>(std::llround(params_.stamp_tolerance * 1e9));
  auto hit = nearest(by_stamp_, ns, tol);
  if (hit != by_stamp_.end()) {
    if (shared_stamps_.count(hit->first)) {
      *why = who + "with stamp " + stampText(stamp) + ": several keyframes carry that stamp (the clock stopped), "
             "so it names none of them; name keyframes by their number";
      return Resolution::kInvalid;
    }
    if (!settled && std::string(role) == "query" && stamped_late_.count(hit->second)) {
      // The stamp of a keyframe stamped late, onto a stamp still to come: a candidate that
      // names it after the keyframes that followed may be about the keyframe that carries it in
      // order, which has not arrived. It waits for that one up to candidate_timeout, then names
      // the late keyframe.
      *why = who + "with stamp " + stampText(stamp) + " (keyframe " + std::to_string(hit->second) +
             "'s, stamped late) has not arrived in order";
      return Resolution::kWait;
    }
    *found = hit->second;
    return Resolution::kFound;
  }
  auto refused = nearest(refused_by_stamp_, ns, tol);
  if (refused != refused_by_stamp_.end()) {
    *found = refused->second;  // (named in the verdict: the keyframe message had that number)
    auto reason = refused_by_index_.find(refused->second);
    *why = who + std::to_string(refused->second) + " (stamp " + stampText(stamp) + ") was refused" +
           (reason != refused_by_index_.end() ? " (" + reason->second + ")" : std::string());
    return Resolution::kInvalid;
  }
  // Not arrived: keyframe stamps need not increase (stamped late, a clock that went back), so
  // no stamp is ever "passed": a candidate waits candidate_timeout from its arrival for its query
  // keyframe. The match is older than the query: once the query has arrived, a match that has not
  // is invalid (tryDecide).
  *why = who + "with stamp " + stampText(stamp) + " has not arrived";
  return Resolution::kWait;
}

// ---- waiting candidates ----------------------------------------------------------------------

VerifierNode::WaitKey VerifierNode::waitKey(int64_t index, const ros::Time& stamp) const {
  if (index >= 0) return WaitKey{false, index};
  return WaitKey{true, toNs(stamp) - static_cast<int64_t>(std::llround(params_.stamp_tolerance * 1e9))};
}

bool VerifierNode::tryDecide(const LoopCandidate& msg, std::vector<WaitKey>* waits, bool settled) {
  int64_t q = -1, m = -1;
  std::string why_q, why_m;
  const Resolution rq = resolve(msg.query_index, msg.query_stamp, "query", &q, &why_q, settled);
  const Resolution rm = resolve(msg.match_index, msg.match_stamp, "match", &m, &why_m);
  if (rq == Resolution::kInvalid) {
    reject(msg, q, m, why_q);
  } else if (rq == Resolution::kWait) {
    // Decided when the query keyframe arrives (a bad match too: the verdict then names the
    // query as rover_replay's does, whichever topic's message came first).
    waits->push_back(waitKey(msg.query_index, msg.query_stamp));
    if (rm == Resolution::kWait) waits->push_back(waitKey(msg.match_index, msg.match_stamp));
    return false;
  } else if (rm == Resolution::kInvalid) {
    reject(msg, q, m, why_m);
  } else if (rm == Resolution::kFound) {
    verify(msg, q, m);
  } else if (msg.match_index >= 0 || msg.match_stamp > msg.query_stamp) {
    // Keyframes arrive in order: a match that has not arrived is newer than the query.
    reject(msg, q, m, why_m + " although the query keyframe has: the match must be the older keyframe");
  } else {
    reject(msg, q, m, "no match keyframe with stamp " + stampText(msg.match_stamp) + " (keyframes are named by the "
           "stamp of a keyframe pose message, or by their number in arrival order)");
  }
  return true;
}

void VerifierNode::wake(int64_t ns, int64_t index) {
  if (waiting_.empty()) return;
  // Only the candidates whose stamp this keyframe's is within stamp_tolerance of (waitKey: stamp -
  // tolerance), and those waiting for its number.
  const int64_t tol = static_cast<int64_t>(std::llround(params_.stamp_tolerance * 1e9));
  for (uint64_t id : waiting_.wake(ns, index, ns - 2 * tol)) {  // in arrival order
    std::vector<WaitKey> waits;
    if (tryDecide(waiting_.get(id), &waits)) waiting_.take(id);
    else waiting_.rewait(id, waits);
  }
}

void VerifierNode::expire() {
  // A candidate waits candidate_timeout for what arrives after it: time in which the node has
  // processed what arrived. While messages wait in the inbox (a burst, a loaded machine), the
  // wait is counted up to the oldest of them, so that a keyframe received in time is never
  // behind its candidate's timeout.
  double horizon = ros::WallTime::now().toSec();
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    if (!inbox_.empty()) horizon = std::min(horizon, inbox_.front().received);
  }
  const double deadline = horizon - params_.candidate_timeout;
  uint64_t id;
  while (waiting_.oldestBefore(deadline, &id)) {  // arrival order is waiting order
    const LoopCandidate msg = waiting_.take(id);
    // A stamp that names a keyframe stamped late names it now (resolve: settled).
    std::vector<WaitKey> ignored_waits;
    if (tryDecide(msg, &ignored_waits, true)) continue;
    int64_t q = -1, m = -1;
    std::string why;
    resolve(msg.query_index, msg.query_stamp, "query", &q, &why, true);
    std::string ignored;
    resolve(msg.match_index, msg.match_stamp, "match", &m, &ignored, true);
    std::ostringstream s;
    s << why << " within candidate_timeout=" << params_.candidate_timeout << " s";
    reject(msg, q, m, s.str());
  }
}

// ---- verdicts --------------------------------------------------------------------------------

void VerifierNode::verify(const LoopCandidate& msg, int64_t query, int64_t match) {
  // The match keyframe's VIO rotation, for a relative_yaw the message leaves NaN (loop_fusion's
  // convention: the difference of world yaws; the graph's keyframes are anchored by a yaw at
  // most, which leaves that difference as it is).
  core::Pose match_vio;
  size_t match_pos = 0;
  if (!graph_->find(match, &match_pos) || !graph_->vioAt(match_pos, &match_vio))
    match_vio.q = Eigen::Quaterniond(std::nan(""), 0.0, 0.0, 0.0);  // unknown: the yaw stays NaN (invalid)
  const core::LoopCandidate c = fromCandidateMsg(msg, query, match, match_vio.q);
  core::Verdict v = host_.decide(c);
  if (v.accepted) useLoop(c, &v);
  v.query_index = query;
  v.match_index = match;
  publishVerdict(v, msg);
  applyDecisions();
}

void VerifierNode::useLoop(const core::LoopCandidate& c, core::Verdict* v) {
  // The core's API reports refusals as a Status; it does not throw.
  const core::Status g = graph_->addLoop(c);
  if (g.ok) {
    changed_ = true;
    return;
  }
  v->accepted = false;
  v->reason = core::Reason::kInvalidInput;
  v->detail += "; but the node's pose graph refused it: " + g.message;
}

void VerifierNode::applyDecisions() {
  // A copy of a candidate (the same query -> match again) gets its candidate's decision right
  // after it (core/verifier.h): the loop is in use, or removed, already.
  std::pair<int64_t, int64_t> last_pair(-1, -1);
  core::LoopDecision::Kind last_kind = core::LoopDecision::Kind::kDrop;
  for (const core::LoopDecision& d : host_.takeDecisions()) {
    const core::LoopCandidate& c = d.candidate;  // as handed to verify(): inliers included
    core::Verdict v = d.verdict;
    const std::pair<int64_t, int64_t> pair(c.query_index, c.match_index);
    const bool copy = pair == last_pair && d.kind == last_kind;
    last_pair = pair;
    last_kind = d.kind;
    switch (d.kind) {
      case core::LoopDecision::Kind::kRelease:
        if (!copy || !graph_->hasLoop(c.query_index, c.match_index)) useLoop(c, &v);
        break;
      case core::LoopDecision::Kind::kRevoke: {
        if (copy && !graph_->hasLoop(c.query_index, c.match_index)) break;
        // The node's stand-in of loop_fusion's graph drops it too (loop_fusion: has_loop = false).
        const core::Status g = graph_->removeLoop(c.query_index, c.match_index);
        if (g.ok) changed_ = true;
        else
          ROS_WARN("[rover] revoked loop %ld -> %ld: not in the node's pose graph (%s)",
                   static_cast<long>(c.query_index), static_cast<long>(c.match_index), g.message.c_str());
        break;
      }
      case core::LoopDecision::Kind::kDrop:
        break;
    }
    publishVerdict(v, candidateMsg(c), true, core::toString(d.kind));
  }
}

void VerifierNode::reject(const LoopCandidate& msg, int64_t query, int64_t match, const std::string& why, bool log) {
  // A keyframe named by number that did not resolve: the verdict names the number given.
  if (query < 0 && msg.query_index >= 0) query = msg.query_index;
  if (match < 0 && msg.match_index >= 0) match = msg.match_index;
  core::LoopCandidate c;
  c.query_index = query;
  c.match_index = match;
  publishVerdict(rejection(c, why), msg, log);
}

void VerifierNode::publishVerdict(const core::Verdict& v, const LoopCandidate& msg, bool log,
                                  const char* decision) {
  VerdictContext ctx;
  ctx.decision = decision;
  ctx.inliers = msg.inliers;
  ctx.verifier = host_.verifierType();
  auto q = stamp_of_.find(v.query_index), m = stamp_of_.find(v.match_index);
  ctx.query_stamp = q != stamp_of_.end() ? rosTimeFromNs(q->second).toSec() : msg.query_stamp.toSec();
  ctx.match_stamp = m != stamp_of_.end() ? rosTimeFromNs(m->second).toSec() : msg.match_stamp.toSec();
  const std::string what = log ? "loop " + std::to_string(v.query_index) + " -> " + std::to_string(v.match_index) +
                                     " (stamps " + stampText(ctx.query_stamp) + " -> " + stampText(ctx.match_stamp) + ")"
                               : std::string();
  host_.publish(v, ctx, what, [&](int64_t index, Eigen::Vector3d* position) {
    // The keyframes' positions in the node's own graph (the accept-all plugin keeps none).
    core::Pose pose;
    if (!graph_->estimate(index, &pose)) return false;
    *position = pose.t;
    return true;
  });
}

// ---- loop_fusion's optimisation and the paths ------------------------------------------------

void VerifierNode::onOptimizeTimer(const ros::WallTimerEvent&) {
  if (!changed_) return;
  guarded("optimisation", [&] {
    Optimize::Response r;
    optimizeAndPublish(&r);
  });
}

bool VerifierNode::onOptimize(Optimize::Request&, Optimize::Response& res) {
  std::string why;
  if (!guarded("~optimize", [&] { optimizeAndPublish(&res); }, &why)) {
    res.success = false;
    res.message = why;
  }
  return true;
}

void VerifierNode::onWatchdog(const ros::WallTimerEvent&) {
  guarded("master watchdog", [&] {
    if (!ros::master::check()) {
      if (!master_lost_)
        ROS_WARN("[rover] the ROS master at %s is unreachable; if it restarts, this node exits (status 2) to be "
                 "respawned",
                 ros::master::getURI().c_str());
      master_lost_ = true;
      return;
    }
    std::string run_id;
    XmlRpc::XmlRpcValue args, result, payload;
    args[0] = ros::this_node::getName();
    args[1] = "/run_id";
    if (ros::master::execute("getParam", args, result, payload, false) &&
        payload.getType() == XmlRpc::XmlRpcValue::TypeString)
      run_id = static_cast<std::string>(payload);
    // A new /run_id is a new master; without one to compare, coming back after being
    // unreachable counts as a restart.
    const bool restarted =
        !run_id_.empty() && !run_id.empty() ? run_id != run_id_ : run_id_.empty() && master_lost_;
    if (!restarted) {
      if (master_lost_) ROS_INFO("[rover] the ROS master is reachable again");
      master_lost_ = false;
      return;
    }
    ROS_FATAL("[rover] the ROS master restarted (run_id %s -> %s): this node's topics and services were registered "
              "with the old one and nobody can reach them. Exiting with status 2 (verifier.launch respawns the node).",
              run_id_.c_str(), run_id.c_str());
    exit_code_ = 2;
  });
}

void VerifierNode::optimizeAndPublish(Optimize::Response* out) {
  changed_ = false;
  const std::vector<core::TrajectoryPoint> trajectory = graph_->trajectory();
  const core::BatchSolveResult solved = graph_->solveLikeLoopFusion(params_.optimize_iterations);
  const ros::Time newest = have_keyframe_ ? rosTimeFromNs(newest_stamp_ns_) : ros::Time();
  const std::string& frame = host_.params().frame_id;
  nav_msgs::Path& odometry = out->odometry;
  nav_msgs::Path& pose_graph = out->pose_graph;
  nav_msgs::Path& estimate = out->estimate;
  odometry.header.stamp = pose_graph.header.stamp = estimate.header.stamp = newest;
  odometry.header.frame_id = pose_graph.header.frame_id = estimate.header.frame_id = frame;
  auto stampOf = [&](const core::TrajectoryPoint& t) {
    auto ns = stamp_of_.find(t.index);
    return ns != stamp_of_.end() ? rosTimeFromNs(ns->second) : toRosTime(t.stamp);
  };
  for (size_t i = 0; i < trajectory.size(); ++i) {
    const ros::Time stamp = stampOf(trajectory[i]);
    odometry.poses.push_back(toPoseStamped(trajectory[i].vio, stamp, frame));
    // A failed solve (reported) leaves the VIO poses.
    const core::Pose& p = solved.ok && i < solved.poses.size() ? solved.poses[i] : trajectory[i].vio;
    pose_graph.poses.push_back(toPoseStamped(p, stamp, frame));
  }
  for (const core::TrajectoryPoint& t : host_.verifier()->trajectory())
    estimate.poses.push_back(toPoseStamped(t.estimate, stampOf(t), frame));
  odometry_path_pub_.publish(odometry);
  pose_graph_path_pub_.publish(pose_graph);
  estimate_path_pub_.publish(estimate);
  if (!solved.ok) ROS_WARN("[rover] loop_fusion's optimisation failed: %s", solved.message.c_str());
  out->success = solved.ok;
  out->keyframe_messages = static_cast<uint32_t>(next_index_);
  out->keyframes = static_cast<uint32_t>(trajectory.size());
  out->candidates_waiting = static_cast<uint32_t>(waiting_.size());
  out->verdicts = static_cast<uint32_t>(host_.output().published());
  out->loops = static_cast<uint32_t>(graph_->loopCount());
  std::ostringstream s;
  s.precision(3);
  s << trajectory.size() << " keyframes (" << keyframes_refused_ << " refused), " << graph_->loopCount()
    << " loops accepted, " << host_.output().published() << " verdicts; loop_fusion optimisation: "
    << (solved.ok ? "" : "FAILED ") << solved.free_keyframes << " keyframes free, " << solved.iterations
    << " iterations, " << std::fixed << solved.solve_ms << " ms";
  out->message = s.str();
}

}  // namespace rover_loop_fusion
