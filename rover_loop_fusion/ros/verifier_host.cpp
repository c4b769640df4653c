#include "rover_loop_fusion/ros/verifier_host.h"

#include "rover_loop_fusion/core/parameters.h"
#include "rover_loop_fusion/ros/guarded.h"

#include <pluginlib/class_loader.hpp>
#include <ros/console.h>
#include <ros/names.h>
#include <ros/param.h>
#include <ros/this_node.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace rover_loop_fusion {

const char kTrajectoryPriorVerifierType[] = "rover_loop_fusion/TrajectoryPriorVerifier";
const char kAcceptAllVerifierType[] = "rover_loop_fusion/AcceptAllVerifier";

const char* toString(Relocalisation policy) {
  switch (policy) {
    case Relocalisation::kConfirm: return "confirm";
    case Relocalisation::kAcceptUnverified: return "accept_unverified";
    case Relocalisation::kReject: return "reject";
  }
  return "reject";
}

bool parseRelocalisation(const std::string& text, Relocalisation* policy) {
  if (text == "confirm") *policy = Relocalisation::kConfirm;
  else if (text == "reject") *policy = Relocalisation::kReject;
  else if (text == "accept_unverified") *policy = Relocalisation::kAcceptUnverified;
  else return false;
  return true;
}

std::string resolveVerifierType(const std::string& type_or_alias) {
  if (type_or_alias == "rover") return kTrajectoryPriorVerifierType;
  if (type_or_alias == "accept_all") return kAcceptAllVerifierType;
  return type_or_alias;
}

const std::vector<std::string>& hostDerivedVerifierParameters() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const core::Parameter& p : core::verifierParameters())
      if (p.host_set) n.push_back(p.name);
    return n;
  }();
  return names;
}

core::Verdict rejection(const core::LoopCandidate& c, const std::string& detail) {
  return core::Verdict::Reject(core::Reason::kInvalidInput, c, detail);
}

namespace {

/// Creates an instance of the plugin `type` with pluginlib. On failure returns null and sets
/// *error, naming the parameter `type_param` and listing the available types.
VerifierPtr loadVerifierPlugin(const std::string& type_or_alias, const std::string& type_param, std::string* error) {
  typedef pluginlib::ClassLoader<LoopVerifier> Loader;
  const std::string type = resolveVerifierType(type_or_alias);
  VerifierPtr out;
  std::string why;
  const bool ok = guarded("loading verifier plugin " + type, [&] {
    std::shared_ptr<Loader> loader = std::make_shared<Loader>("rover_loop_fusion", "rover_loop_fusion::LoopVerifier");
    if (!loader->isClassAvailable(type)) {
      std::vector<std::string> known = loader->getDeclaredClasses();
      std::sort(known.begin(), known.end());
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      *error = "parameter " + type_param + ": unknown verifier type '" + type_or_alias + "' (available: " + list +
               "; or rover, accept_all)";
      return;
    }
    auto instance = loader->createUniqueInstance(type);
    if (!instance) {
      *error = "parameter " + type_param + ": pluginlib returned no instance of '" + type + "'";
      return;
    }
    auto deleter = instance.get_deleter();
    LoopVerifier* raw = instance.release();
    // The deleter holds the loader: it is destroyed after the instance it created.
    out = VerifierPtr(raw, [loader, deleter](LoopVerifier* p) { deleter(p); });
  }, &why);
  if (!ok) *error = "parameter " + type_param + ": cannot load verifier plugin '" + type + "': " + why;
  return out;
}

bool validVerifierName(const std::string& name) {
  std::string why;
  return !name.empty() && ros::names::validate(name, why) && name.find('/') == std::string::npos && name[0] != '~';
}

const char* relocalisationText(Relocalisation policy) {
  switch (policy) {
    case Relocalisation::kConfirm:
      return "loops between unconnected sequences, e.g. into a loaded map, are held until confirm_count of them agree";
    case Relocalisation::kAcceptUnverified:
      return "a first loop between unconnected sequences, e.g. into a loaded map, is USED UNVERIFIED";
    case Relocalisation::kReject: break;
  }
  return "a first loop between unconnected sequences, e.g. into a loaded map, is rejected";
}

std::string str(int value) { return std::to_string(value); }
std::string str(double value) { return core::formatNumber(value); }

}  // namespace

// ---- RepeatedWarning -------------------------------------------------------------------------

std::string keyframeWarning(int64_t index, const std::string& message) {
  const std::string named = "keyframe " + std::to_string(static_cast<long long>(index)) + ":";
  return "verifier, " + (message.compare(0, named.size(), named) == 0 ? message : named + " " + message);
}

void RepeatedWarning::warn(const std::string& text) {
  ++count_;
  if (count_ <= individually_) {
    ROS_WARN("[rover] %s%s", text.c_str(),
             count_ == individually_ ? " (further ones are summarised)" : "");
    last_summary_ = ros::WallTime::now();
    return;
  }
  ++held_back_;
  latest_ = text;
  if ((ros::WallTime::now() - last_summary_).toSec() >= period_s_) flush();
}

void RepeatedWarning::flush() {
  const std::string summary = takeSummary();
  if (!summary.empty()) ROS_WARN("%s", summary.c_str());
}

std::string RepeatedWarning::takeSummary() {
  if (held_back_ == 0) return std::string();
  const std::string out = "[rover] " + std::to_string(held_back_) + " more like this (" + std::to_string(count_) +
                          " in all); the latest: " + latest_;
  held_back_ = 0;
  last_summary_ = ros::WallTime::now();
  return out;
}

// ---- HostParamReader -------------------------------------------------------------------------

HostParamReader::HostParamReader(const ros::NodeHandle& nh) : nh_(nh), reader_(nh, &errors_) {}

void HostParamReader::text(const std::string& key, std::string* value, bool allow_empty) {
  keys_.push_back(key);
  reader_.text(key, value);
  if (!allow_empty && value->empty()) error(key, "must not be empty");
}

void HostParamReader::boolean(const std::string& key, bool* value) {
  keys_.push_back(key);
  reader_.boolean(key, value);
}

void HostParamReader::integer(const std::string& key, int* value, int lo, int hi) {
  keys_.push_back(key);
  const size_t before = errors_.size();
  reader_.integer(key, value);
  if (errors_.size() == before && (*value < lo || *value > hi))
    error(key, "must be in [" + str(lo) + ", " + str(hi) + "] (got " + str(*value) + ")");
}

void HostParamReader::number(const std::string& key, double* value, double lo, double hi, const char* unit) {
  keys_.push_back(key);
  const size_t before = errors_.size();
  reader_.number(key, value);
  if (errors_.size() == before && !(*value >= lo && *value <= hi))
    error(key, "must be in [" + str(lo) + ", " + str(hi) + "] " + unit + " (got " + str(*value) + ")");
}

void HostParamReader::error(const std::string& key, const std::string& what) { reader_.error(key, what); }

std::vector<std::string> HostParamReader::unknownKeys(const std::vector<std::string>& known_namespaces) const {
  std::vector<std::string> out, all, reported;
  if (!ros::param::getParamNames(all)) return out;
  const std::string prefix = nh_.getNamespace() + "/";
  for (const std::string& p : all) {
    if (p.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string key = p.substr(prefix.size());
    const size_t slash = key.find('/');
    if (slash == std::string::npos) {
      if (std::find(keys_.begin(), keys_.end(), key) == keys_.end())
        out.push_back("unknown parameter " + p + " (ignored; a typo?)");
      continue;
    }
    const std::string ns = key.substr(0, slash);
    if (std::find(known_namespaces.begin(), known_namespaces.end(), ns) != known_namespaces.end() ||
        std::find(reported.begin(), reported.end(), ns) != reported.end())
      continue;
    reported.push_back(ns);
    out.push_back("unknown parameter namespace " + prefix + ns + "/ (nothing reads it; verifier parameters belong in " +
                  prefix + (known_namespaces.empty() ? std::string("?") : known_namespaces.front()) + "/)");
  }
  return out;
}

// ---- VerifierHost ------------------------------------------------------------------------------

VerifierHost::VerifierHost(const ros::NodeHandle& nh, const std::string& frame_key)
    : nh_(nh), frame_key_(frame_key), reader_(nh) {}

VerifierHost::Start VerifierHost::start(const HostInfo& info, int verdict_queue, VerifierPtr injected,
                                        const std::string& injected_type) {
  Start out;
  HostParams& p = params_;
  HostParamReader& r = reader_;
  r.text("verifier_type", &p.verifier_type, false);
  r.text("verifier_name", &p.verifier_name);
  r.text("verdict_log", &p.verdict_log);
  r.boolean("publish_markers", &p.publish_markers);
  r.text(frame_key_, &p.frame_id, false);
  std::string policy = toString(p.relocalisation);
  r.text("relocalisation", &policy);
  if (!parseRelocalisation(policy, &p.relocalisation))
    r.error("relocalisation", "must be confirm, reject or accept_unverified (got '" + policy + "')");
  if (!validVerifierName(p.verifier_name))
    r.error("verifier_name", "must be a plain name such as rover (got '" + p.verifier_name + "')");
  for (const std::string& w : r.unknownKeys({p.verifier_name})) ROS_WARN("[rover] %s", w.c_str());
  if (!r.errors().empty()) {
    out.errors = r.errors();
    return out;
  }

  if (!p.verdict_log.empty() && p.verdict_log[0] != '/') {
    // A relative path is relative to the host's working directory (roslaunch: ~/.ros), which
    // nobody looks at: resolved here and said.
    std::vector<char> cwd(4096);
    if (::getcwd(cwd.data(), cwd.size())) {
      const std::string absolute = std::string(cwd.data()) + "/" + p.verdict_log;
      ROS_INFO("[rover] %s '%s' is a relative path: the verdict log is %s (in the working directory of %s; give an "
               "absolute path to put it elsewhere)",
               resolve("verdict_log").c_str(), p.verdict_log.c_str(), absolute.c_str(),
               ros::this_node::getName().c_str());
      p.verdict_log = absolute;
    }
  }
  VerdictOutput::Options o;
  o.frame_id = p.frame_id;
  o.markers = p.publish_markers;
  o.csv_path = p.verdict_log;
  o.queue_size = verdict_queue;
  std::string why;
  if (!output_.initialize(nh_, o, &why)) {
    out.errors.push_back("parameter " + resolve("verdict_log") + ": " + why);
    return out;
  }
  output_ready_ = true;

  HostInfo host = info;
  host.relocalisation = p.relocalisation;
  if (injected) {
    verifier_ = std::move(injected);
    type_ = injected_type;
  } else {
    type_ = resolveVerifierType(p.verifier_type);
    verifier_ = loadVerifierPlugin(p.verifier_type, resolve("verifier_type"), &out.verifier_error);
  }
  if (!verifier_) return out;
  bool started = false;
  std::string threw;
  if (!guarded(type_ + ": initialize", [&] { started = verifier_->initialize(p.verifier_name, nh_, host); }, &threw))
    out.verifier_error = type_ + ": initialize threw: " + threw;
  else if (!started)
    out.verifier_error = type_ + ": " + verifier_->error();
  if (!out.verifier_error.empty()) {
    verifier_.reset();
    return out;
  }
  ROS_INFO("[rover] %s verifies loop candidates with %s (parameters in %s/); relocalisation: %s (%s); "
           "verdicts on %s%s%s",
           ros::this_node::getName().c_str(), type_.c_str(), resolve(p.verifier_name).c_str(),
           toString(p.relocalisation), relocalisationText(p.relocalisation),
           resolve("loop_verdicts").c_str(), p.verdict_log.empty() ? "" : ", verdict log ", p.verdict_log.c_str());
  return out;
}

core::Verdict VerifierHost::decide(const core::LoopCandidate& c) noexcept {
  core::Verdict v;
  std::string why;
  const bool ok = guarded("verifier " + type_ + " on loop " + std::to_string(c.query_index) + " -> " +
                              std::to_string(c.match_index),
                          [&] {
                            v = verifier_->verify(c);
                            if (!v.accepted) return;
                            core::rejectRefusedCommit(&v, verifier_->commit(c));
                          },
                          &why);
  if (!ok) v = rejection(c, "the verifier threw an exception: " + why);
  if (v.deferred || v.accepted) {
    std::lock_guard<std::mutex> lock(open_mutex_);
    guarded("remembering a verdict", [&] {
      const auto key = std::make_pair(c.query_index, c.match_index);
      if (v.deferred) held_[key].push_back(Open{c, v});
      else loops_[key] = v;
    });
  }
  return v;
}

std::vector<core::LoopDecision> VerifierHost::takeDecisions() noexcept {
  std::vector<core::LoopDecision> out;
  if (verifier_) guarded("verifier " + type_ + ": takeDecisions (decisions lost)", [&] { out = verifier_->takeDecisions(); });
  std::lock_guard<std::mutex> lock(open_mutex_);
  guarded("the final verdicts of later decisions", [&] {
    for (core::LoopDecision& d : out) {
      // The final verdict of a held or committed loop, about the decision's own candidate: the
      // numbers of its verdict at verify, the decision's outcome.
      const auto key = std::make_pair(d.candidate.query_index, d.candidate.match_index);
      core::Verdict at_verify;
      bool found = false;
      if (d.kind == core::LoopDecision::Kind::kRevoke) {
        auto loop = loops_.find(key);
        if (loop != loops_.end()) {
          at_verify = loop->second;
          found = true;
          loops_.erase(loop);
        }
      } else {
        auto held = held_.find(key);
        if (held != held_.end()) {
          at_verify = held->second.front().verdict;
          found = true;
          held->second.pop_front();
          if (held->second.empty()) held_.erase(held);
        }
      }
      if (found) {
        d.verdict = finalVerdict(std::move(at_verify), d.kind, d.verdict);
        if (d.verdict.accepted) loops_[key] = d.verdict;
      }
      d.verdict.query_index = d.candidate.query_index;
      d.verdict.match_index = d.candidate.match_index;
      d.verdict.deferred = false;
    }
  });
  return out;
}

core::Verdict VerifierHost::finalVerdict(core::Verdict at_verify, core::LoopDecision::Kind kind,
                                         const core::Verdict& decided) {
  at_verify.accepted = decided.accepted;
  at_verify.reason = decided.reason;
  at_verify.deferred = false;
  at_verify.detail = std::string(core::toString(kind)) + ": " + decided.detail + " (at verify: " + at_verify.detail + ")";
  return at_verify;
}

std::vector<core::LoopDecision> VerifierHost::dropHeld(const std::string& why) noexcept {
  std::vector<core::LoopDecision> out;
  std::lock_guard<std::mutex> lock(open_mutex_);
  guarded("the final verdicts of the candidates still held", [&] {
    for (const auto& key_held : held_)
      for (const Open& h : key_held.second) {
        core::LoopDecision d;
        d.kind = core::LoopDecision::Kind::kDrop;
        d.candidate = h.candidate;
        d.verdict = finalVerdict(h.verdict, d.kind, core::Verdict::Reject(core::Reason::kUnconfirmed, h.candidate, why));
        out.push_back(d);
      }
  });
  held_.clear();
  return out;
}

size_t VerifierHost::heldCount() noexcept {
  std::lock_guard<std::mutex> lock(open_mutex_);
  size_t n = 0;
  for (const auto& key_held : held_) n += key_held.second.size();
  return n;
}

bool VerifierHost::publish(const core::Verdict& v, VerdictContext ctx, const std::string& what,
                           const PositionLookup& fallback) noexcept {
  if (!what.empty()) guarded("logging a verdict", [&] {
    const bool later = ctx.decision != "verify";
    const std::string how = later ? " (" + ctx.decision + " of a held candidate)" : std::string();
    if (v.accepted) ROS_INFO("[rover] %s accepted%s: %s", what.c_str(), how.c_str(), v.detail.c_str());
    else if (v.deferred) ROS_INFO("[rover] %s HELD (deferred): %s", what.c_str(), v.detail.c_str());
    else if (v.reason == core::Reason::kInvalidInput)
      ROS_WARN("[rover] %s REJECTED (invalid_input): %s", what.c_str(), v.detail.c_str());
    else if (v.reason == core::Reason::kRevoked)
      ROS_WARN("[rover] %s REVOKED: %s", what.c_str(), v.detail.c_str());
    else ROS_INFO("[rover] %s REJECTED (%s)%s: %s", what.c_str(), core::toString(v.reason), how.c_str(),
                  v.detail.c_str());
  });
  if (!output_ready_) return false;
  if (params_.publish_markers)
    guarded("marker positions for " + what, [&] {
      // At the verifier's estimate of the two keyframes (an accepted loop's ends meet), else
      // where the host has them. Two look-ups, never a copy of the trajectory.
      auto find = [&](int64_t index, Eigen::Vector3d* position) {
        core::Pose pose;
        if (verifier_ && verifier_->estimate(index, &pose)) {
          *position = pose.t;
          return true;
        }
        return fallback && fallback(index, position);
      };
      ctx.have_positions = find(v.query_index, &ctx.query_position) && find(v.match_index, &ctx.match_position);
    });
  return guarded("publishing the verdict on " + what, [&] { output_.publish(v, ctx); });
}

}  // namespace rover_loop_fusion
