#include "rover_loop_fusion/ros/verifier_node.h"

#include "rover_loop_fusion/ros/params.h"

#include <Eigen/Geometry>
#include <boost/make_shared.hpp>
#include <nav_msgs/Path.h>

#include <cmath>
#include <cstdio>
#include <iterator>
#include <sstream>
#include <vector>

namespace rover_loop_fusion {

namespace {

/// Yaw [rad] of a rotation (Z-Y-X, as loop_fusion's R2ypr); NaN for an unusable quaternion.
double yawOf(const Eigen::Quaterniond& q) {
  const double n = q.norm();
  if (!std::isfinite(n) || n < 1e-9) return std::nan("");
  const Eigen::Matrix3d R = q.normalized().toRotationMatrix();
  return std::atan2(R(1, 0), R(0, 0));
}

std::string stampText(const ros::Time& t) {
  char buf[48];
  std::snprintf(buf, sizeof(buf), "%u.%09u", t.sec, t.nsec);
  return buf;
}

std::string stampText(int64_t ns) { return stampText(ros::Time().fromNSec(ns)); }

ros::Time timeFromNs(int64_t ns) { return ns > 0 ? ros::Time().fromNSec(ns) : ros::Time(); }

geometry_msgs::PoseStamped poseStamped(const core::Pose& p, const ros::Time& stamp, const std::string& frame) {
  geometry_msgs::PoseStamped s;
  s.header.stamp = stamp;
  s.header.frame_id = frame;
  s.pose.position.x = p.t.x();
  s.pose.position.y = p.t.y();
  s.pose.position.z = p.t.z();
  s.pose.orientation.w = p.q.w();
  s.pose.orientation.x = p.q.x();
  s.pose.orientation.y = p.q.y();
  s.pose.orientation.z = p.q.z();
  return s;
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

}  // namespace

VerifierNode::VerifierNode(const ros::NodeHandle& nh, const ros::NodeHandle& pnh) : nh_(nh), pnh_(pnh) {}

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

bool VerifierNode::start(std::string* error) {
  std::vector<std::string> errors;
  ParamReader r(pnh_, &errors);
  VerifierNodeParams& p = params_;
  r.text("verifier_type", &p.verifier_type);
  r.text("verifier_name", &p.verifier_name);
  r.text("keyframe_topic", &p.keyframe_topic);
  r.text("candidate_topic", &p.candidate_topic);
  r.integer("sequence", &p.sequence);
  r.boolean("use_imu", &p.use_imu);
  r.number("candidate_timeout", &p.candidate_timeout);
  r.number("stamp_tolerance", &p.stamp_tolerance);
  r.number("optimize_period", &p.optimize_period);
  r.integer("optimize_iterations", &p.optimize_iterations);
  r.text("frame_id", &p.frame_id);
  r.boolean("publish_markers", &p.publish_markers);
  r.text("verdict_log", &p.verdict_log);
  r.integer("queue_size", &p.queue_size);
  if (!validVerifierName(p.verifier_name))
    r.error("verifier_name", "must be a plain name such as rover (got '" + p.verifier_name + "')");
  if (p.keyframe_topic.empty()) r.error("keyframe_topic", "must not be empty");
  if (p.candidate_topic.empty()) r.error("candidate_topic", "must not be empty");
  if (p.sequence < 0) r.error("sequence", "must be >= 0");
  if (!(p.candidate_timeout >= 0.0)) r.error("candidate_timeout", "must be >= 0 [s]");
  if (!(p.stamp_tolerance >= 0.0 && p.stamp_tolerance < 1.0)) r.error("stamp_tolerance", "must be in [0, 1) [s]");
  if (!std::isfinite(p.optimize_period)) r.error("optimize_period", "must be a number [s]");
  if (p.optimize_iterations < 1) r.error("optimize_iterations", "must be >= 1");
  if (p.frame_id.empty()) r.error("frame_id", "must not be empty");
  if (p.queue_size < 1) r.error("queue_size", "must be >= 1");
  if (!errors.empty()) {
    *error = errors[0];
    for (size_t i = 1; i < errors.size(); ++i) *error += "; " + errors[i];
    return false;
  }

  VerdictOutput::Options o;
  o.frame_id = p.frame_id;
  o.markers = p.publish_markers;
  o.csv_path = p.verdict_log;
  std::string output_error;
  if (!output_.initialize(pnh_, o, &output_error)) {
    *error = "parameter " + pnh_.resolveName("verdict_log") + ": " + output_error;
    return false;
  }

  verifier_type_ = resolveVerifierType(p.verifier_type);
  verifier_ = loadVerifierPlugin(p.verifier_type, pnh_.resolveName("verifier_type"), error);
  if (!verifier_) return false;
  HostInfo host;
  host.uses_imu = p.use_imu;
  host.shifts_sequences = false;  // raw VIO poses: the verifier anchors sequences itself
  if (!initializeVerifier(*verifier_, verifier_type_, p.verifier_name, pnh_, host, error)) return false;

  core::VerifierConfig g;  // loop_fusion's graph: its fixed odometry neighbours and Huber loss
  g.mode = p.use_imu ? core::Mode::kFourDof : core::Mode::kSixDof;
  g.anchor_incoming_keyframes = true;
  graph_.reset(new core::PoseGraph(g));

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
  ROS_INFO("[rover] %s: verifying loop candidates from %s (keyframes: %s) with %s (parameters in %s)%s%s",
           ros::this_node::getName().c_str(), candidate_sub_.getTopic().c_str(), keyframe_sub_.getTopic().c_str(),
           verifier_type_.c_str(), pnh_.resolveName(p.verifier_name).c_str(),
           p.verdict_log.empty() ? "" : ", verdict log ", p.verdict_log.c_str());
  return true;
}

void VerifierNode::finish() {
  if (receiver_) receiver_->stop();
  drainInbox();
  if (inbox_dropped_ > 0)
    ROS_ERROR("[rover] %zu messages were dropped because the inbox was full (queue_size=%d)", inbox_dropped_,
              params_.queue_size);
  try {
    while (!pending_.empty()) {
      const Pending c = pending_.front();
      pending_.pop_front();
      reject(c.msg, -1, -1, "the node stopped before the candidate's keyframes arrived");
    }
  } catch (...) {
  }
}

// ---- input -----------------------------------------------------------------------------------

void VerifierNode::receive(Incoming item) {
  bool schedule = false;
  {
    std::lock_guard<std::mutex> lock(inbox_mutex_);
    if (inbox_.size() >= static_cast<size_t>(params_.queue_size)) {
      ++inbox_dropped_;
      ROS_ERROR_THROTTLE(1.0, "[rover] %s message dropped: %zu messages are waiting to be processed "
                         "(queue_size=%d; %zu dropped so far); verification is slower than the input",
                         item.keyframe ? "keyframe" : "loop candidate", inbox_.size(), params_.queue_size,
                         inbox_dropped_);
      return;
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
  for (size_t n = 0;; ++n) {
    Incoming item;
    {
      std::lock_guard<std::mutex> lock(inbox_mutex_);
      if (inbox_.empty()) {
        drain_scheduled_ = false;
        return;
      }
      if (n == max_items) break;  // still scheduled: comes back after the other callbacks
      item = std::move(inbox_.front());
      inbox_.pop_front();
    }
    if (item.keyframe) onKeyframe(item.keyframe);
    if (item.candidate) onCandidate(item.candidate);
  }
  ros::getGlobalCallbackQueue()->addCallback(boost::make_shared<DrainCallback>(this),
                                             reinterpret_cast<uint64_t>(this));
}

void VerifierNode::drainInbox() { drainSome(static_cast<size_t>(-1)); }

void VerifierNode::onKeyframe(const nav_msgs::Odometry::ConstPtr& msg) {
  try {
    addKeyframe(*msg);
    processPending(false);
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] keyframe message: %s", e.what());
  } catch (...) {
    ROS_ERROR("[rover] keyframe message: unknown exception");
  }
}

void VerifierNode::onCandidate(const LoopCandidate::ConstPtr& msg) {
  try {
    pending_.push_back(Pending{*msg, ros::WallTime::now()});
    processPending(false);
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] loop candidate message: %s", e.what());
  } catch (...) {
    ROS_ERROR("[rover] loop candidate message: unknown exception");
  }
}

void VerifierNode::onPendingTimer(const ros::WallTimerEvent&) {
  if (pending_.empty()) return;
  try {
    processPending(true);
  } catch (...) {
    ROS_ERROR("[rover] deciding waiting candidates: unknown exception");
  }
}

void VerifierNode::addKeyframe(const nav_msgs::Odometry& msg) {
  const int64_t index = next_index_++;
  const int64_t ns = static_cast<int64_t>(msg.header.stamp.toNSec());
  const geometry_msgs::Point& pos = msg.pose.pose.position;
  const geometry_msgs::Quaternion& ori = msg.pose.pose.orientation;
  const Eigen::Vector3d t(pos.x, pos.y, pos.z);
  const Eigen::Quaterniond q(ori.w, ori.x, ori.y, ori.z);
  std::string why;
  if (have_keyframe_ && ns <= newest_stamp_ns_) {
    auto same = by_stamp_.find(ns);
    why = same != by_stamp_.end()
              ? "duplicate: keyframe " + std::to_string(same->second) + " has the same stamp"
              : "out of order: stamp " + stampText(ns) + " is not after the newest keyframe's " +
                    stampText(newest_stamp_ns_);
  } else {
    const core::Status s = graph_->addKeyframe(index, msg.header.stamp.toSec(), params_.sequence, t, q);
    if (!s.ok) why = s.message;
  }
  if (!why.empty()) {
    ++keyframes_refused_;
    refused_by_index_[index] = why;
    if (!by_stamp_.count(ns)) refused_by_stamp_[ns] = why;
    ROS_WARN("[rover] keyframe message %ld (stamp %s) refused: %s; loop candidates that name it get "
             "invalid_input", static_cast<long>(index), stampText(ns).c_str(), why.c_str());
    return;
  }
  by_stamp_[ns] = index;
  stamp_of_[index] = ns;
  newest_stamp_ns_ = ns;
  have_keyframe_ = true;
  changed_ = true;
  core::Status s;
  try {
    s = verifier_->addKeyframe(index, msg.header.stamp.toSec(), params_.sequence, t, q);
  } catch (const std::exception& e) {
    s = core::Status::Error(std::string("the verifier threw: ") + e.what());
  } catch (...) {
    s = core::Status::Error("the verifier threw an exception");
  }
  if (!s.ok)
    ROS_WARN("[rover] keyframe %ld not added to the verifier (%s); loops that involve it are rejected",
             static_cast<long>(index), s.message.c_str());
}

VerifierNode::Resolution VerifierNode::resolve(int64_t index, const ros::Time& stamp, const char* role,
                                               int64_t* found, std::string* why) const {
  const std::string who = std::string(role) + " keyframe ";
  if (index >= 0) {
    if (stamp_of_.count(index)) {
      *found = index;
      return Resolution::kFound;
    }
    auto refused = refused_by_index_.find(index);
    if (refused != refused_by_index_.end()) {
      *why = who + std::to_string(index) + " was refused (" + refused->second + ")";
      return Resolution::kInvalid;
    }
    *why = who + std::to_string(index) + " has not arrived";
    return index >= next_index_ ? Resolution::kWait : Resolution::kInvalid;
  }
  const int64_t ns = static_cast<int64_t>(stamp.toNSec());
  const int64_t tol = static_cast<int64_t>(std::llround(params_.stamp_tolerance * 1e9));
  auto hit = nearest(by_stamp_, ns, tol);
  if (hit != by_stamp_.end()) {
    *found = hit->second;
    return Resolution::kFound;
  }
  auto refused = nearest(refused_by_stamp_, ns, tol);
  if (refused != refused_by_stamp_.end()) {
    *why = who + "with stamp " + stampText(stamp) + " was refused (" + refused->second + ")";
    return Resolution::kInvalid;
  }
  if (!have_keyframe_ || ns > newest_stamp_ns_ + tol) {
    *why = who + "with stamp " + stampText(stamp) + " has not arrived";
    return Resolution::kWait;
  }
  *why = "no " + who + "with stamp " + stampText(stamp) + " (keyframes are named by the stamp of a keyframe "
         "pose message, or by their number in arrival order)";
  return Resolution::kInvalid;
}

void VerifierNode::processPending(bool check_timeout) {
  const ros::WallTime now = ros::WallTime::now();
  for (auto it = pending_.begin(); it != pending_.end();) {
    const LoopCandidate& msg = it->msg;
    int64_t q = -1, m = -1;
    std::string why_q, why_m;
    const Resolution rq = resolve(msg.query_index, msg.query_stamp, "query", &q, &why_q);
    const Resolution rm = resolve(msg.match_index, msg.match_stamp, "match", &m, &why_m);
    // Copy: verify() and reject() publish, and the element is erased below.
    const LoopCandidate c = msg;
    if (rq == Resolution::kInvalid || rm == Resolution::kInvalid) {
      it = pending_.erase(it);
      reject(c, q, m, rq == Resolution::kInvalid ? why_q : why_m);
    } else if (rq == Resolution::kFound && rm == Resolution::kFound) {
      it = pending_.erase(it);
      verify(c, q, m);
    } else if (rq == Resolution::kFound) {
      // Keyframes arrive in order: a match that has not arrived is newer than the query.
      it = pending_.erase(it);
      reject(c, q, m, why_m + " although the query keyframe has: the match must be the older keyframe");
    } else if (check_timeout && (now - it->received).toSec() > params_.candidate_timeout) {
      std::ostringstream s;
      s << why_q << " within candidate_timeout=" << params_.candidate_timeout << " s";
      it = pending_.erase(it);
      reject(c, q, m, s.str());
    } else {
      ++it;
    }
  }
}

// ---- verdicts --------------------------------------------------------------------------------

void VerifierNode::verify(const LoopCandidate& msg, int64_t query, int64_t match) {
  core::LoopCandidate c;
  c.query_index = query;
  c.match_index = match;
  const geometry_msgs::Pose& p = msg.relative_pose;
  c.relative_t = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  c.relative_q = Eigen::Quaterniond(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
  c.relative_yaw = std::isnan(msg.relative_yaw) ? yawOf(c.relative_q) : msg.relative_yaw;
  c.inliers = msg.inliers;
  core::Verdict v = verifyAndCommit(*verifier_, verifier_type_, c);
  if (v.accepted) {
    // The core's API reports refusals as a Status; it does not throw.
    const core::Status g = graph_->addLoop(c);
    if (g.ok) {
      changed_ = true;
    } else {
      v.accepted = false;
      v.reason = core::Reason::kInvalidInput;
      v.detail += "; but the node's pose graph refused it: " + g.message;
    }
  }
  v.query_index = query;
  v.match_index = match;
  publishVerdict(v, msg);
}

void VerifierNode::reject(const LoopCandidate& msg, int64_t query, int64_t match, const std::string& why) {
  core::Verdict v;
  v.query_index = query;
  v.match_index = match;
  v.accepted = false;
  v.reason = core::Reason::kInvalidInput;
  v.detail = why;
  publishVerdict(v, msg);
}

void VerifierNode::publishVerdict(const core::Verdict& v, const LoopCandidate& msg) {
  VerdictContext ctx;
  ctx.inliers = msg.inliers;
  ctx.verifier = verifier_type_;
  auto q = stamp_of_.find(v.query_index), m = stamp_of_.find(v.match_index);
  ctx.query_stamp = q != stamp_of_.end() ? timeFromNs(q->second).toSec() : msg.query_stamp.toSec();
  ctx.match_stamp = m != stamp_of_.end() ? timeFromNs(m->second).toSec() : msg.match_stamp.toSec();
  const std::string what = "loop " + std::to_string(v.query_index) + " -> " + std::to_string(v.match_index) +
                           " (stamps " + stampText(ros::Time(ctx.query_stamp)) + " -> " +
                           stampText(ros::Time(ctx.match_stamp)) + ")";
  if (v.accepted) ROS_INFO("[rover] %s accepted: %s", what.c_str(), v.detail.c_str());
  else if (v.reason == core::Reason::kInvalidInput)
    ROS_WARN("[rover] %s REJECTED (invalid_input): %s", what.c_str(), v.detail.c_str());
  else ROS_INFO("[rover] %s REJECTED (%s): %s", what.c_str(), core::toString(v.reason), v.detail.c_str());
  try {
    if (params_.publish_markers && q != stamp_of_.end() && m != stamp_of_.end()) {
      // At the verifier's estimate (an accepted loop's ends meet), else at the VIO positions.
      std::vector<core::TrajectoryPoint> trajectory = verifier_->trajectory();
      if (trajectory.empty()) trajectory = graph_->trajectory();
      ctx.have_positions = findTrajectoryPosition(trajectory, v.query_index, &ctx.query_position) &&
                           findTrajectoryPosition(trajectory, v.match_index, &ctx.match_position);
    }
  } catch (...) {
    ctx.have_positions = false;
  }
  try {
    output_.publish(v, ctx);
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] publishing the verdict on %s failed: %s", what.c_str(), e.what());
  }
}

// ---- loop_fusion's optimisation and the paths ------------------------------------------------

void VerifierNode::onOptimizeTimer(const ros::WallTimerEvent&) {
  if (!changed_) return;
  try {
    Optimize::Response r;
    optimizeAndPublish(&r);
  } catch (const std::exception& e) {
    ROS_ERROR("[rover] optimisation: %s", e.what());
  } catch (...) {
    ROS_ERROR("[rover] optimisation: unknown exception");
  }
}

bool VerifierNode::onOptimize(Optimize::Request&, Optimize::Response& res) {
  try {
    optimizeAndPublish(&res);
  } catch (const std::exception& e) {
    res.success = false;
    res.message = e.what();
  } catch (...) {
    res.success = false;
    res.message = "unknown exception";
  }
  return true;
}

void VerifierNode::optimizeAndPublish(Optimize::Response* out) {
  changed_ = false;
  const std::vector<core::TrajectoryPoint> trajectory = graph_->trajectory();
  const core::BatchSolveResult solved = graph_->solveLikeLoopFusion(params_.optimize_iterations);
  const ros::Time newest = have_keyframe_ ? timeFromNs(newest_stamp_ns_) : ros::Time();
  nav_msgs::Path& odometry = out->odometry;
  nav_msgs::Path& pose_graph = out->pose_graph;
  nav_msgs::Path& estimate = out->estimate;
  odometry.header.stamp = pose_graph.header.stamp = estimate.header.stamp = newest;
  odometry.header.frame_id = pose_graph.header.frame_id = estimate.header.frame_id = params_.frame_id;
  for (size_t i = 0; i < trajectory.size(); ++i) {
    auto ns = stamp_of_.find(trajectory[i].index);
    const ros::Time stamp = ns != stamp_of_.end() ? timeFromNs(ns->second) : ros::Time(trajectory[i].stamp);
    odometry.poses.push_back(poseStamped(trajectory[i].vio, stamp, params_.frame_id));
    // A failed solve (reported) leaves the VIO poses.
    const core::Pose& p = solved.ok && i < solved.poses.size() ? solved.poses[i] : trajectory[i].vio;
    pose_graph.poses.push_back(poseStamped(p, stamp, params_.frame_id));
  }
  const std::vector<core::TrajectoryPoint> own = verifier_->trajectory();
  for (const core::TrajectoryPoint& t : own) {
    auto ns = stamp_of_.find(t.index);
    estimate.poses.push_back(
        poseStamped(t.estimate, ns != stamp_of_.end() ? timeFromNs(ns->second) : ros::Time(t.stamp), params_.frame_id));
  }
  odometry_path_pub_.publish(odometry);
  pose_graph_path_pub_.publish(pose_graph);
  estimate_path_pub_.publish(estimate);
  if (!solved.ok) ROS_WARN("[rover] loop_fusion's optimisation failed: %s", solved.message.c_str());
  out->success = solved.ok;
  out->keyframe_messages = static_cast<uint32_t>(next_index_);
  out->keyframes = static_cast<uint32_t>(trajectory.size());
  out->candidates_waiting = static_cast<uint32_t>(pending_.size());
  out->verdicts = static_cast<uint32_t>(output_.published());
  out->loops = static_cast<uint32_t>(graph_->loopCount());
  std::ostringstream s;
  s.precision(3);
  s << trajectory.size() << " keyframes (" << keyframes_refused_ << " refused), " << graph_->loopCount()
    << " loops accepted, " << output_.published() << " verdicts; loop_fusion optimisation: "
    << (solved.ok ? "" : "FAILED ") << solved.free_keyframes << " keyframes free, " << solved.iterations
    << " iterations, " << std::fixed << solved.solve_ms << " ms";
  out->message = s.str();
}

}  // namespace rover_loop_fusion
