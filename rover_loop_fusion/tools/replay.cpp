// rover_replay: runs the ROVER core over a scenario directory (docs/scenario-format.md) the way
// loop_fusion would see it: keyframes in order, each candidate verified when its query
// keyframe has arrived. Writes the verdict log and the resulting trajectories.
//
//   rover_replay --scenario DIR --out DIR [--protocol sequential|oracle|none]
//                [--relocalisation confirm|reject|accept_unverified]
//                [--config FILE] [--<parameter> VALUE ...] [--snapshots K]
//                [--compare-trials N] [--quiet]
//
// Verifier parameters: every row of the parameter table (core/parameters.h) is a flag
// --<name> VALUE (a boolean flag alone means true); --config FILE reads a verifier YAML with
// the same keys. Both apply in command-line order: flags after --config override it, and a
// second --config overrides the first, so a shipped set is --config config/rover_template.yaml
// --config config/rover_outdoor.yaml (the template, then the override: what the launch files
// load). Without either, the defaults of core::VerifierConfig (config/rover_template.yaml's). `mode: auto` is 4dof here
// (scenarios hold VIO poses). A value of the wrong type or out of range is an error (exit 2).
// `rover_replay --help` lists every parameter with its unit, range and default.
//
// Relocalisation policy (what the hosts set, never a YAML): --relocalisation confirm (the
// default, as the ROS product ships it: ~relocalisation in launch/*.launch), reject or
// accept_unverified, mapped exactly as the hosts map ~relocalisation (plugins.cpp):
// accept_without_prior = (policy == accept_unverified), confirm_without_prior = (policy ==
// confirm). A YAML's accept_without_prior / confirm_without_prior are not used (the hosts
// ignore them too). For A/B the two can still be set as flags, in command-line order with
// --relocalisation; without --relocalisation before them they start from the core's defaults
// (accept_without_prior true, confirm_without_prior false: what rover_replay ran before, i.e.
// `--accept_without_prior` alone is the old behaviour, `--relocalisation accept_unverified` too).
//
// Protocols:
//   sequential  commit what the verifier accepts (what the product does); a verdict says what
//               was committed: an accepted loop whose commit is refused (the same loop again)
//               is invalid_input, as the hosts report it (core::rejectRefusedCommit);
//   oracle      commit only candidates labelled true (scores every candidate against the
//               graph a perfect verifier would have built: for ranking metrics, AP / MR);
//   none        commit nothing (every candidate scored against odometry alone).
//
// Output directory:
//   verdicts.csv                    one row per candidate: the columns of ~verdict_log, then
//                                   verified_at_keyframe (keyframes the verifier held when
//                                   verify() was called), decided_at_keyframe (when the final
//                                   decision came: the release, drop or revocation; for an
//                                   immediate verdict the same as verified_at_keyframe) and
//                                   group_first_at_keyframe (a released candidate: the
//                                   verified_at_keyframe of the first member of the group it was
//                                   released with; otherwise its own verified_at_keyframe)
//   keyframe_ms.csv                 per keyframe: index, the wall-clock time of addKeyframe()
//                                   (where held candidates are judged and released) [ms] and the
//                                   decisions it produced
//   intake.csv                      per keyframe of keyframes.csv, in its order: index, sequence,
//                                   stamp, kept (1, or 0: refused by addKeyframe, not in the graph
//                                   nor in the trajectories) and addKeyframe()'s message (why it
//                                   was refused, or a warning; empty when clean). The keyframes
//                                   the peers of the benchmarks get (roverlib/problem.py)
//   odometry.tum                    the VIO keyframe poses
//   verified.tum                    the verifier's estimate X at the end
//   loop_fusion_verified.tum        loop_fusion's optimisation of the verified graph
//   loop_fusion_accept_all.tum      loop_fusion's optimisation with every candidate
//   groundtruth.tum                 (if the scenario has ground truth)
//   trials.csv                      with --compare-trials N (decision metric, revisit): for every candidate,
//                                   before its verify(), the verdicts of the full-window trial
//                                   and of the trial condensed above N keyframes against the same
//                                   graph and X (Verifier::compareTrials; the agreement benchmark)
//   snapshots/{verified,loop_fusion_verified,loop_fusion_accept_all}_K.tum
//                                   with --snapshots K: the same trajectories as the run had
//                                   them after k/K of the keyframes, k = 1..K (what the system
//                                   showed at that time; for the temporal ATE)
#include "rover_loop_fusion/core/parameters.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/verdict_csv.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scenario_io.h"
#include "rover_loop_fusion/sim/scene.h"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <map>
#include <string>

using namespace rover_loop_fusion;

namespace {

// A CSV field in double quotes (a quote doubled, a line break as a space), as verdicts.csv's detail.
std::string csvQuoted(const std::string& text) {
  std::string out = "\"";
  for (char ch : text) {
    if (ch == '"') out += "\"\"";
    else if (ch == '\n' || ch == '\r') out += ' ';
    else out += ch;
  }
  return out + "\"";
}

int usage(int code) {
  std::FILE* out = code ? stderr : stdout;
  std::fprintf(out,
               "usage: rover_replay --scenario DIR --out DIR [--protocol sequential|oracle|none]\n"
               "                    [--relocalisation confirm|reject|accept_unverified]\n"
               "                    [--config FILE] [--<parameter> VALUE ...] [--snapshots K]\n"
               "                    [--compare-trials N] [--quiet]\n"
               "--relocalisation: the hosts' ~relocalisation policy for candidates between sequences nothing\n"
               "connects (default confirm, as the ROS product ships it): sets accept_without_prior and\n"
               "confirm_without_prior as the hosts do; a YAML's values of those two are not used. For A/B\n"
               "they can be given as flags (applied in order with --relocalisation; without it before them,\n"
               "from the core's defaults: --accept_without_prior alone is rover_replay's old behaviour).\n"
               "Output: verdicts.csv (the verdict log's columns, then verified_at_keyframe,\n"
               "decided_at_keyframe, group_first_at_keyframe), keyframe_ms.csv (addKeyframe() time per\n"
               "keyframe), intake.csv (each keyframe kept or refused, and why), TUM trajectories.\n"
               "verifier parameters (applied in order; --config FILE reads a verifier YAML: a shipped set is\n"
               "--config config/rover_template.yaml --config config/rover_outdoor.yaml, the template then\n"
               "the override; the defaults are the template's; a boolean flag alone means true):\n");
  for (const core::Parameter& p : core::verifierParameters())
    std::fprintf(out, "  --%-26s %-22s default %-7s %s\n", p.name.c_str(), p.range().c_str(),
                 p.defaultText().c_str(), p.doc.c_str());
  return code;
}

/// A non-negative integer, the whole text.
bool count(const std::string& s, int* v) {
  const core::ParameterValue n = core::ParameterValue::parse(s);
  if (n.type != core::ParameterValue::Type::kNumber || !n.integral || n.number < 0 || n.number > 1e6) return false;
  *v = static_cast<int>(n.number);
  return true;
}

/// The hosts' ~relocalisation policy as the verifier's two flags (ros/plugins.cpp does the same).
bool applyRelocalisation(const std::string& policy, core::VerifierConfig* c) {
  if (policy != "confirm" && policy != "reject" && policy != "accept_unverified") return false;
  c->host.accept_without_prior = policy == "accept_unverified";
  c->host.confirm_without_prior = policy == "confirm";
  return true;
}

double percentileOf(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q / 100.0 * static_cast<double>(v.size() - 1);
  const size_t lo = static_cast<size_t>(std::floor(pos)), hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

/// The first member named by a group decision's detail ("... (loops Q->M .. ...)"); false if none.
bool groupFront(const std::string& detail, std::pair<int64_t, int64_t>* key) {
  const size_t at = detail.find("(loops ");
  if (at == std::string::npos) return false;
  long long q = 0, m = 0;
  if (std::sscanf(detail.c_str() + at, "(loops %lld->%lld", &q, &m) != 2) return false;
  *key = std::make_pair(static_cast<int64_t>(q), static_cast<int64_t>(m));
  return true;
}

/// mkdir -p
void makeDirs(const std::string& path) {
  for (size_t i = 1; i <= path.size(); ++i)
    if (i == path.size() || path[i] == '/') mkdir(path.substr(0, i).c_str(), 0755);
}

bool writeTum(const std::string& path, const std::vector<double>& stamps,
              const std::vector<core::Pose>& poses) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) return false;
  for (size_t i = 0; i < poses.size() && i < stamps.size(); ++i) {
    const core::Pose& p = poses[i];
    std::fprintf(f, "%.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", stamps[i], p.t.x(), p.t.y(), p.t.z(),
                 p.q.x(), p.q.y(), p.q.z(), p.q.w());
  }
  std::fclose(f);
  return true;
}

/// What the command line asks for.
struct Options {
  std::string scenario_dir, out_dir, protocol = "sequential";
  core::VerifierConfig cfg;
  std::string relocalisation = "confirm";  // "" once the two flags are set one by one
  bool quiet = false;
  int snapshots = 0;
  int compare_trials = -1;
};

int fail(const std::string& what) {
  std::fprintf(stderr, "rover_replay: %s (rover_replay --help lists the parameters)\n", what.c_str());
  return 2;
}

/// The value of a boolean flag at argv[*i]: the next word if it is a boolean (consumed), else "true".
std::string booleanText(int argc, char** argv, int* i) {
  const core::ParameterValue next = *i + 1 < argc ? core::ParameterValue::parse(argv[*i + 1]) : core::ParameterValue();
  return next.type == core::ParameterValue::Type::kBoolean ? argv[++*i] : "true";
}

/// Parses the command line into *o; returns -1 to run, or the exit status (help, an error).
int parseArguments(int argc, char** argv, Options* o) {
  // The relocalisation policy's two flags, applied after every other parameter (a YAML does not
  // set them: the hosts ignore them there too). Default: the product's policy, confirm.
  core::VerifierConfig policy;
  bool policy_given = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has_value = i + 1 < argc;
    const core::Parameter* p = a.compare(0, 2, "--") == 0 ? core::findParameter(a.substr(2)) : nullptr;
    std::string why;
    if (p && (p->name == "accept_without_prior" || p->name == "confirm_without_prior")) {
      // A/B: set one by one; from the core's defaults unless --relocalisation came before.
      if (!policy_given) policy = core::VerifierConfig();
      policy_given = true;
      o->relocalisation.clear();
      if (!core::assignParameter(*p, core::ParameterValue::parse(booleanText(argc, argv, &i)), &policy, &why))
        return fail(a + ": " + why);
    } else if (a == "--relocalisation") {
      if (!has_value) return fail(a + " needs a value");
      o->relocalisation = argv[++i];
      if (!applyRelocalisation(o->relocalisation, &policy))
        return fail("--relocalisation must be confirm, reject or accept_unverified (got '" + o->relocalisation + "')");
      policy_given = true;
    } else if (p) {
      // --flag alone means true; --flag true|false (any other next word is the next flag).
      if (p->type != core::Parameter::Type::kBoolean && !has_value) return fail(a + " needs a value");
      const std::string text = p->type == core::Parameter::Type::kBoolean ? booleanText(argc, argv, &i) : argv[++i];
      if (!core::assignParameter(*p, core::ParameterValue::parse(text), &o->cfg, &why)) return fail(a + ": " + why);
    } else if (a == "--help" || a == "-h") {
      return usage(0);
    } else if (!has_value && a != "--quiet") {
      return fail(a.compare(0, 2, "--") == 0 ? "unknown or incomplete option " + a : "unexpected argument " + a);
    } else if (a == "--scenario") o->scenario_dir = argv[++i];
    else if (a == "--out") o->out_dir = argv[++i];
    else if (a == "--protocol") o->protocol = argv[++i];
    else if (a == "--config") {
      if (!core::readParameterFile(argv[++i], &o->cfg, &why)) return fail(why);
    } else if (a == "--snapshots") {
      if (!count(argv[++i], &o->snapshots)) return fail("--snapshots must be a count (got '" + std::string(argv[i]) + "')");
    } else if (a == "--compare-trials") {
      if (!count(argv[++i], &o->compare_trials) || o->compare_trials < 1)
        return fail("--compare-trials must be a keyframe count >= 1 (got '" + std::string(argv[i]) + "')");
    } else if (a == "--quiet") o->quiet = true;
    else return fail("unknown option " + a);
  }
  if (!policy_given) applyRelocalisation(o->relocalisation, &policy);
  o->cfg.host.accept_without_prior = policy.host.accept_without_prior;
  o->cfg.host.confirm_without_prior = policy.host.confirm_without_prior;
  if (o->scenario_dir.empty() || o->out_dir.empty()) return usage(2);
  if (o->protocol != "sequential" && o->protocol != "oracle" && o->protocol != "none")
    return fail("--protocol must be sequential, oracle or none (got '" + o->protocol + "')");
  const std::string invalid = o->cfg.validate();
  if (!invalid.empty()) return fail("invalid parameters: " + invalid);
  return -1;
}

/// A file of the output directory, opened for writing with its header line; nullptr (said) if not.
std::FILE* openOutput(const std::string& out_dir, const char* name, const std::string& header) {
  std::FILE* f = std::fopen((out_dir + "/" + name).c_str(), "w");
  if (!f) {
    std::fprintf(stderr, "rover_replay: cannot write %s/%s\n", out_dir.c_str(), name);
    return nullptr;
  }
  std::fprintf(f, "%s\n", header.c_str());
  return f;
}

std::string trialsHeader() {
  std::string h = "query_index,match_index,label";
  for (const std::string k : {"full", "condensed"})
    for (const char* col : {"accepted", "reason", "score", "threshold", "window", "iterations", "ms"})
      h += "," + k + "_" + col;
  return h;
}

/// One row per candidate, written at the end: a held candidate's row becomes its final
/// decision (released, dropped), an accepted loop's row "revoked" if a revocation comes.
struct Row {
  core::Verdict verdict;
  int label = -1;
  double query_stamp = 0.0, match_stamp = 0.0;
  int inliers = -1;
  const char* decision = "verify";  // or the later decision: release, drop, revoke
  // Keyframes the verifier held when the candidate was verified, when its final decision
  // came, and (released) when the first member of its released group was verified.
  size_t verified_at = 0, decided_at = 0, group_first_at = 0;
};

using Key = std::pair<int64_t, int64_t>;
Key key(const core::LoopCandidate& c) { return std::make_pair(c.query_index, c.match_index); }

/// The run: the scenario's keyframes in order, each candidate verified once its query keyframe
/// is in the graph (file order kept), beside loop_fusion's graph with every candidate.
class Replay {
 public:
  Replay(const Options& o, const sim::Scenario& s)
      : o_(o), s_(s), verifier_(o.cfg), accept_all_(verifier_.config()) {
    for (size_t i = 0; i < s.candidates.size(); ++i) by_query_.emplace(s.candidates[i].candidate.query_index, i);
    for (const sim::ScenarioKeyframe& k : s.keyframes) ++upcoming_[k.index];
    // odometry.csv: the step covariances the data carries (the uncertainty uses them instead of
    // the drift model's).
    for (const auto& sc : s.step_covariance) step_covariance_[sc.first] = &sc.second;
  }

  /// Writes every output file; the exit status.
  int run() {
    csv_ = openOutput(o_.out_dir, "verdicts.csv",
                      core::verdictCsvHeader() + ",verified_at_keyframe,decided_at_keyframe,group_first_at_keyframe");
    keyframe_csv_ = openOutput(o_.out_dir, "keyframe_ms.csv", "index,add_keyframe_ms,decisions");
    intake_csv_ = openOutput(o_.out_dir, "intake.csv", "index,sequence,stamp,kept,message");
    if (o_.compare_trials > 0) trials_csv_ = openOutput(o_.out_dir, "trials.csv", trialsHeader());
    if (!csv_ || !keyframe_csv_ || !intake_csv_ || (o_.compare_trials > 0 && !trials_csv_)) return 1;
    if (o_.snapshots > 0) makeDirs(o_.out_dir + "/snapshots");
    for (const sim::ScenarioKeyframe& k : s_.keyframes) addKeyframe(k);
    // Candidates whose query keyframe never arrived: still a verdict each (invalid input).
    for (const auto& left : by_query_) handle(s_.candidates[left.second]);
    writeRows();
    // Snapshots still due (the last keyframes were refused).
    for (; o_.snapshots > 0 && next_snapshot_ <= static_cast<size_t>(o_.snapshots); ++next_snapshot_)
      takeSnapshot(next_snapshot_);
    for (std::FILE* f : {csv_, keyframe_csv_, intake_csv_, trials_csv_})
      if (f) std::fclose(f);
    if (!writeTrajectories() || !snapshots_ok_) {
      std::fprintf(stderr, "rover_replay: cannot write trajectories to %s\n", o_.out_dir.c_str());
      return 1;
    }
    printSummary();
    return 0;
  }

 private:
  void addKeyframe(const sim::ScenarioKeyframe& k) {
    ++handled_keyframes_;
    if (--upcoming_[k.index] == 0) upcoming_.erase(k.index);
    const auto given = step_covariance_.find(k.index);
    const auto t0 = std::chrono::steady_clock::now();
    const core::Status st = verifier_.addKeyframe(k.index, k.stamp, k.sequence, k.vio.t, k.vio.q,
                                                  given == step_covariance_.end() ? nullptr : given->second);
    const double add_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    add_keyframe_ms_.push_back(add_ms);
    accept_all_.addKeyframe(k.index, k.stamp, k.sequence, k.vio.t, k.vio.q);
    std::fprintf(intake_csv_, "%lld,%d,%.9f,%d,%s\n", static_cast<long long>(k.index), k.sequence, k.stamp,
                 st ? 1 : 0, csvQuoted(st.message).c_str());
    if (!st) {
      ++refused_keyframes_;
      std::fprintf(keyframe_csv_, "%lld,%.4f,0\n", static_cast<long long>(k.index), add_ms);
      if (!o_.quiet) std::printf("keyframe refused: %s\n", st.message.c_str());
      return;
    }
    ++keyframes_held_;
    if (st.warning() && !o_.quiet) std::printf("keyframe warning: %s\n", st.message.c_str());
    std::fprintf(keyframe_csv_, "%lld,%.4f,%zu\n", static_cast<long long>(k.index), add_ms, takeDecisions());
    stamp_of_[k.index] = k.stamp;
    stamps_.push_back(k.stamp);
    odometry_.push_back(k.vio);
    auto range = by_query_.equal_range(k.index);
    for (auto it = range.first; it != range.second; ++it) handle(s_.candidates[it->second]);
    by_query_.erase(range.first, range.second);
    // Snapshot k (1..K) is taken once the first ceil(k * N / K) keyframes have been handled.
    for (; o_.snapshots > 0 && next_snapshot_ <= static_cast<size_t>(o_.snapshots) &&
           handled_keyframes_ * o_.snapshots >= next_snapshot_ * s_.keyframes.size();
         ++next_snapshot_)
      takeSnapshot(next_snapshot_);
  }

  void writeTrial(const sim::ScenarioCandidate& sc) {
    const core::LoopCandidate& c = sc.candidate;
    const std::pair<core::Verdict, core::Verdict> t = verifier_.compareTrials(c, o_.compare_trials);
    std::fprintf(trials_csv_, "%lld,%lld,%d", static_cast<long long>(c.query_index),
                 static_cast<long long>(c.match_index), sc.label);
    for (const core::Verdict* x : {&t.first, &t.second})
      std::fprintf(trials_csv_, ",%d,%s,%.6f,%.6f,%d,%d,%.4f", x->accepted ? 1 : 0, core::toString(x->reason),
                   x->score, x->threshold, x->window_size, x->iterations, x->elapsed_ms);
    std::fprintf(trials_csv_, "\n");
  }

  void handle(const sim::ScenarioCandidate& sc) {
    const core::LoopCandidate& c = sc.candidate;
    if (trials_csv_) writeTrial(sc);
    // A match that has not arrived but comes later: the query is older than its match (the
    // verifier would only know "unknown match keyframe"; the node says the same as this).
    core::Verdict v = !stamp_of_.count(c.match_index) && upcoming_.count(c.match_index)
                          ? core::Verdict::Reject(core::Reason::kInvalidInput, c,
                                                  "match keyframe " + std::to_string(c.match_index) +
                                                      " comes after query keyframe " + std::to_string(c.query_index) +
                                                      " in keyframes.csv: the match must be the older keyframe")
                          : verifier_.verify(c);
    ++verified_;
    verify_ms_ += v.elapsed_ms;
    if (o_.protocol == "sequential" && v.accepted) {
      // What the product does (VerifierHost::decide): a loop whose commit is refused (the same
      // loop again) is not in the graph, and its verdict says so.
      core::rejectRefusedCommit(&v, verifier_.commit(c));
    } else if (o_.protocol == "oracle" && sc.label == 1) {
      // The oracle's graph: every true loop once (a repeated one is refused; the verdict is
      // verify()'s, the ranking protocol's score).
      if (!verifier_.commit(c)) ++oracle_refused_;
    }
    accept_all_.addLoop(c);
    Row row;
    row.verdict = v;
    row.label = sc.label;
    row.query_stamp = stamp_of_.count(c.query_index) ? stamp_of_[c.query_index] : 0.0;
    row.match_stamp = stamp_of_.count(c.match_index) ? stamp_of_[c.match_index] : 0.0;
    row.inliers = c.inliers;
    row.verified_at = row.decided_at = row.group_first_at = keyframes_held_;
    rows_.push_back(row);
    last_row_[key(c)] = rows_.size() - 1;
    if (v.deferred) held_rows_[key(c)].push_back(rows_.size() - 1);
    if (v.accepted) accepted_rows_[key(c)].push_back(rows_.size() - 1);
    if (!o_.quiet)
      std::printf("%7lld -> %7lld  label %2d  %-8s %-22s score %8.3f  %6.2f ms\n",
                  static_cast<long long>(c.query_index), static_cast<long long>(c.match_index), sc.label,
                  v.accepted ? "ACCEPT" : v.deferred ? "HOLD" : "REJECT", core::toString(v.reason), v.score,
                  v.elapsed_ms);
    takeDecisions();
  }

  /// The verifier's later decisions (release, drop, revoke) onto the rows they decide; their count.
  size_t takeDecisions() {
    const std::vector<core::LoopDecision> decisions = verifier_.takeDecisions();
    // A group is released in one call: its decisions come in a row, with the same detail.
    std::string group_detail;
    std::vector<size_t> group_rows;
    size_t group_first = 0;
    auto closeGroup = [&]() {
      for (size_t r : group_rows) rows_[r].group_first_at = group_first;
      group_rows.clear();
      group_detail.clear();
    };
    for (const core::LoopDecision& d : decisions) {
      auto& open = (d.kind == core::LoopDecision::Kind::kRevoke ? accepted_rows_ : held_rows_)[key(d.candidate)];
      if (d.kind != core::LoopDecision::Kind::kRelease || d.verdict.detail != group_detail) closeGroup();
      if (open.empty()) continue;
      const size_t at = open.front();
      open.pop_front();
      Row& row = rows_[at];
      row.decided_at = keyframes_held_;
      if (d.kind == core::LoopDecision::Kind::kRelease) {
        if (group_rows.empty()) {
          group_detail = d.verdict.detail;
          group_first = row.verified_at;
          Key front;
          if (groupFront(d.verdict.detail, &front) && last_row_.count(front))
            group_first = std::min(group_first, rows_[last_row_[front]].verified_at);
        }
        group_first = std::min(group_first, row.verified_at);
        group_rows.push_back(at);
      }
      apply(d, &row);
      if (row.verdict.accepted) accepted_rows_[key(d.candidate)].push_back(at);
    }
    closeGroup();
    return decisions.size();
  }

  void apply(const core::LoopDecision& d, Row* row) const {
    core::Verdict& v = row->verdict;
    v.accepted = d.verdict.accepted;
    v.deferred = false;
    v.reason = d.verdict.reason;
    v.detail = std::string(core::toString(d.kind)) + ": " + d.verdict.detail + " (at verify: " + v.detail + ")";
    row->decision = core::toString(d.kind);
    if (!o_.quiet)
      std::printf("%7lld -> %7lld  label %2d  %-8s %s\n", static_cast<long long>(d.candidate.query_index),
                  static_cast<long long>(d.candidate.match_index), row->label, core::toString(d.kind),
                  d.verdict.detail.c_str());
  }

  void takeSnapshot(size_t k) {
    std::vector<core::Pose> est;
    for (const core::TrajectoryPoint& p : verifier_.trajectory()) est.push_back(p.estimate);
    const std::string base = o_.out_dir + "/snapshots/";
    const std::string suffix = "_" + std::to_string(k) + ".tum";
    snapshots_ok_ = snapshots_ok_ && writeTum(base + "verified" + suffix, stamps_, est) &&
                    writeTum(base + "loop_fusion_verified" + suffix, stamps_, verifier_.solveLikeLoopFusion(5).poses) &&
                    writeTum(base + "loop_fusion_accept_all" + suffix, stamps_, accept_all_.solveLikeLoopFusion(5).poses);
  }

  /// verdicts.csv; a candidate still held when the run ends is not confirmed.
  void writeRows() {
    for (Row& r : rows_) {
      if (!r.verdict.deferred) continue;
      r.verdict.deferred = false;
      r.verdict.reason = core::Reason::kUnconfirmed;
      r.verdict.detail = "still held when the run ended (" + r.verdict.detail + ")";
      r.decision = "drop";
      r.decided_at = keyframes_held_;
    }
    for (const Row& r : rows_) {
      if (r.label == 1) (r.verdict.accepted ? tp_ : fn_)++;
      if (r.label == 0) (r.verdict.accepted ? fp_ : tn_)++;
      std::fprintf(csv_, "%s,%zu,%zu,%zu\n",
                   core::verdictCsvRow(r.verdict, r.query_stamp, r.match_stamp, r.inliers, "rover_replay", r.decision)
                       .c_str(),
                   r.verified_at, r.decided_at, r.group_first_at);
    }
  }

  bool writeTrajectories() {
    std::vector<core::Pose> estimate;
    for (const core::TrajectoryPoint& p : verifier_.trajectory()) estimate.push_back(p.estimate);
    const std::string& out = o_.out_dir;
    bool ok = writeTum(out + "/odometry.tum", stamps_, odometry_) && writeTum(out + "/verified.tum", stamps_, estimate) &&
              writeTum(out + "/loop_fusion_verified.tum", stamps_, verifier_.solveLikeLoopFusion(5).poses) &&
              writeTum(out + "/loop_fusion_accept_all.tum", stamps_, accept_all_.solveLikeLoopFusion(5).poses);
    if (s_.truth.empty()) return ok;
    std::vector<double> gt_stamps;
    std::vector<core::Pose> gt;
    for (size_t i = 0; i < s_.truth.size(); ++i) {
      if (!stamp_of_.count(s_.truth_index[i])) continue;
      gt_stamps.push_back(stamp_of_[s_.truth_index[i]]);
      gt.push_back(s_.truth[i]);
    }
    return ok && writeTum(out + "/groundtruth.tum", gt_stamps, gt);
  }

  void printSummary() const {
    std::printf("rover_replay: %zu keyframes (%d refused), %zu candidates, protocol %s, threshold %.2f m\n",
                stamps_.size(), refused_keyframes_, verified_, o_.protocol.c_str(), o_.cfg.metric.threshold);
    if (oracle_refused_ > 0)
      std::printf("rover_replay: %d true candidates not committed by the oracle (the same loop again)\n",
                  oracle_refused_);
    if (tp_ + fp_ + tn_ + fn_ > 0)
      std::printf("rover_replay: TP %d FP %d TN %d FN %d  precision %s recall %s\n", tp_, fp_, tn_, fn_,
                  sim::ratioText(tp_, tp_ + fp_).c_str(), sim::ratioText(tp_, tp_ + fn_).c_str());
    const double max_ms =
        add_keyframe_ms_.empty() ? 0.0 : *std::max_element(add_keyframe_ms_.begin(), add_keyframe_ms_.end());
    std::printf("rover_replay: mean verification %.3f ms; addKeyframe p50 %.3f ms, p99 %.3f ms, max %.3f ms; "
                "output in %s\n",
                verified_ ? verify_ms_ / verified_ : 0.0, percentileOf(add_keyframe_ms_, 50),
                percentileOf(add_keyframe_ms_, 99), max_ms, o_.out_dir.c_str());
  }

  const Options& o_;
  const sim::Scenario& s_;
  core::Verifier verifier_;
  core::KeyframeGraph accept_all_;  // loop_fusion's graph with every candidate
  std::FILE *csv_ = nullptr, *keyframe_csv_ = nullptr, *intake_csv_ = nullptr, *trials_csv_ = nullptr;
  std::multimap<int64_t, size_t> by_query_;  // query keyframe -> candidates still to verify
  std::map<int64_t, int> upcoming_;          // keyframe indices still to come (how often)
  std::map<int64_t, const Eigen::Matrix4d*> step_covariance_;
  std::map<int64_t, double> stamp_of_;
  std::vector<Row> rows_;
  // The rows open for a later decision, by (query, match), oldest first (the same loop may be
  // proposed again while held: the verifier decides each copy, in the order they came): held
  // ones for their release or drop, accepted ones for a revocation.
  std::map<Key, std::deque<size_t>> held_rows_, accepted_rows_;
  std::map<Key, size_t> last_row_;  // every candidate's latest row
  int tp_ = 0, fp_ = 0, tn_ = 0, fn_ = 0, refused_keyframes_ = 0, oracle_refused_ = 0;
  size_t verified_ = 0, keyframes_held_ = 0, handled_keyframes_ = 0, next_snapshot_ = 1;
  double verify_ms_ = 0.0;
  bool snapshots_ok_ = true;
  std::vector<double> stamps_, add_keyframe_ms_;
  std::vector<core::Pose> odometry_;
};

}  // namespace

int main(int argc, char** argv) {
  Options o;
  const int status = parseArguments(argc, argv, &o);
  if (status >= 0) return status;
  if (!o.quiet)
    std::printf("rover_replay: %s; relocalisation: %s (accept_without_prior %s, confirm_without_prior %s)\n",
                core::describe(o.cfg).c_str(), o.relocalisation.empty() ? "set by flags" : o.relocalisation.c_str(),
                o.cfg.host.accept_without_prior ? "true" : "false", o.cfg.host.confirm_without_prior ? "true" : "false");
  sim::Scenario s;
  std::string error;
  if (!sim::loadScenario(o.scenario_dir, &s, &error)) {
    std::fprintf(stderr, "rover_replay: %s\n", error.c_str());
    return 1;
  }
  makeDirs(o.out_dir);
  return Replay(o, s).run();
}
