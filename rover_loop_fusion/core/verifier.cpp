#include "rover_loop_fusion/core/verifier.h"

#include "rover_loop_fusion/core/decision.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>

namespace rover_loop_fusion {
namespace core {

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

}  // namespace

Verifier::Verifier(const VerifierConfig& config)
    : config_error_(config.validate()),
      config_(config_error_.empty() ? config : VerifierConfig()),
      graph_(config_),
      rule_(makeDecisionRule(config_, graph_)),
      loops_(config_, graph_, *rule_),
      held_(config_) {
  // What this configuration's decisions will need, kept up to date keyframe by keyframe and
  // loop by loop (a first use after 100k keyframes would otherwise build it all at once:
  // ~30-60 ms for the moments, ~10 ms for the places of 20 000 loops).
  graph_.keepMoments(config_.decision != Decision::kMetric,
                     config_.mode == Mode::kFourDof && config_.trial.condense_min_window > 0);
  if (config_.decision != Decision::kChi2) graph_.keepPathLengths();  // the gate's and threshold's path
}

Verifier::~Verifier() = default;

Status Verifier::addKeyframe(int64_t index, double stamp, int sequence, const Eigen::Vector3d& t,
                             const Eigen::Quaterniond& q, const Eigen::Matrix4d* step_covariance) {
  std::lock_guard<std::mutex> lock(mutex_);
  const Status s = graph_.addKeyframe(index, stamp, sequence, t, q, step_covariance);
  // The revisit hypotheses are judged, and dropped members re-tested, here only: on keyframe
  // arrival, the re-tests within revisit_retest_budget_ms counted from it (retestNow()).
  if (!held_.settled()) {
    retest_.started = Clock::now();
    retest_.count = 0;
    settle(true);
    // Members waiting to be tested alone: those a commit or the end of revisit_window made due.
    held_.beginWaiting();
    HeldCandidate h;
    std::string why;
    while (held_.nextWaiting(graph_.keyframeCount(), graph_.revision(), &h, &why)) dropMember(h, why, false);
  }
  if (!held_.pool().empty() &&
      graph_.keyframeCount() >= last_global_pass_ + static_cast<size_t>(config_.global.global_period)) {
    const Status pass = globalPass();
    if (s.ok && pass.warning()) return Status::Warning(s.warning() ? s.message + "; " + pass.message : pass.message);
  }
  return s;
}

Verdict Verifier::verify(const LoopCandidate& c) {
  const auto t0 = Clock::now();
  std::lock_guard<std::mutex> lock(mutex_);
  // The stages, once each, in order; the first that says more than "next" decides.
  Passage p(c, t0, config_.metric.threshold);
  StageOutcome out = input_.run(&p);     // bad input: invalid_input
  if (out.next()) out = copies_.run(&p);  // a copy of a held, rejected or committed candidate
  if (out.next()) out = prior_.run(p);    // no trajectory prior: the host's policy
  if (out.next()) out = decide_.run(&p);  // the gate, the trial and its score (or chi2)
  const StageOutcome failed = out;
  out = act(&p, hold_stage_.run(p, failed), failed);  // a rejection held as a rival or for the global pass
  const Verdict v = emit_.verdict(p, out);
  if (!out.copy) copies_.verified(c, v);
  return v;
}

StageOutcome Verifier::act(Passage* p, StageOutcome out, const StageOutcome& failed) {
  if (out.held && out.hold == HoldKind::kGlobal) {
    HeldCandidate h = loops_.heldFor(p->c);
    h.query_pos = p->qpos;
    h.match_pos = p->mpos;
    h.kind = HoldKind::kGlobal;
    if (!addToGlobalPool(h)) return failed;
    copies_.held(p->c);
  } else if (out.held) {
    hold(p->c, p->qpos, p->mpos, out.hold, out.d2);
  } else if (out.keep_decided) {
    pending_.valid = true;
    pending_.candidate = p->c;
    pending_.revision = graph_.revision();
    pending_.decided = std::move(p->decided);
  }
  return out;
}

std::pair<Verdict, Verdict> Verifier::compareTrials(const LoopCandidate& c, int condense_min_window) {
  std::lock_guard<std::mutex> lock(mutex_);
  size_t qpos = 0, mpos = 0;
  std::string why = graph_.checkLoop(c, &qpos, &mpos);
  if (why.empty() && !graph_.connected(qpos, mpos)) why = "no trajectory prior: no trial";
  if (why.empty() && graph_.sequenceAt(qpos) == 0 && graph_.sequenceAt(mpos) == 0) why = "both in sequence 0";
  if (why.empty() && config_.decision == Decision::kChi2) why = "decision chi2: no trial";  // revisit: the metric trial first
  if (!why.empty()) {
    const Verdict v = emit_.reject(Reason::kInvalidInput, c, why, Verdict(), Clock::now());
    return {v, v};
  }
  auto trialVerdict = [&](int condense) {
    const auto t0 = Clock::now();
    Verdict measured;
    TrialSolution trial;
    const Check d = metricDecision(config_, graph_, c, qpos, mpos, condense, t0, &measured, &trial);
    return emit_.outcome(d, c, measured, t0);
  };
  const Verdict full = trialVerdict(0);
  return {full, trialVerdict(condense_min_window)};
}

Status Verifier::commit(const LoopCandidate& c) {
  std::lock_guard<std::mutex> lock(mutex_);
  return commitLocked(c, true);
}

Status Verifier::commitLocked(const LoopCandidate& c, bool update_estimate) {
  const Pending& p = pending_;
  const bool reuse = p.valid && p.revision == graph_.revision() &&
                     p.candidate.query_index == c.query_index &&
                     p.candidate.match_index == c.match_index &&
                     p.candidate.relative_t == c.relative_t &&
                     p.candidate.relative_q.coeffs() == c.relative_q.coeffs() &&
                     p.candidate.relative_yaw == c.relative_yaw;
  size_t qpos = 0, mpos = 0;
  const bool prior = graph_.find(c.query_index, &qpos) && graph_.find(c.match_index, &mpos) &&
                     graph_.connected(qpos, mpos);
  const Status added = graph_.addLoop(c);
  if (!added) return Status::Error("commit refused: " + added.message);
  pending_.valid = false;
  Status updated;
  if (reuse) {
    if (p.decided.calibrates) rule_->learn(p.decided);
    updated = rule_->adoptDecided(p.decided, qpos, update_estimate);
  } else {
    if (!update_estimate) return Status::Ok();  // the caller updates X once for a group (release())
    // A loop accepted without a prior is committed in the host's loop-closure path, right after
    // its verdict: bounded like a verification. Other loops committed without their accepting
    // verify() (rover_replay's oracle protocol, overrides) are solved to convergence, so that
    // what they build does not depend on the machine's load.
    updated = rule_->updateEstimate(mpos, qpos, prior ? 0.0 : config_.trial.time_budget_ms);
  }
  // The loop is in the graph (the host uses it) whatever happened to X.
  if (!updated.ok) return Status::Warning("loop committed but the update of the estimate failed (" + updated.message + ")");
  if (updated.warning())
    return Status::Warning("loop committed; the update of the estimate stopped at time_budget_ms (" +
                           updated.message + "): the next accepted loop's solve continues from there");
  return Status::Ok();
}


// ---- held candidates ------------------------------------------------------------------------

std::vector<LoopDecision> Verifier::takeDecisions() {
  std::lock_guard<std::mutex> lock(mutex_);
  return emit_.take();
}

size_t Verifier::heldCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return held_.size() + copies_.waiting();
}

void Verifier::hold(const LoopCandidate& c, size_t qpos, size_t mpos, HoldKind kind, double d2) {
  copies_.held(c);
  HeldCandidate h = loops_.heldFor(c);
  h.query_pos = qpos;
  h.match_pos = mpos;
  h.kind = kind;
  h.d2 = d2;
  held_.add(h, loops_);
  // A revisit hypothesis is judged on keyframe arrival (addKeyframe), not here: its joint trial
  // (all its loops) would otherwise land on this verify()'s time (the cost of verify(), docs/results.md).
  if (kind != HoldKind::kRevisit) settle(false);
}

void Verifier::drop(const HeldGroup& group, const std::string& why, bool contradicted) {
  const size_t now = graph_.keyframeCount(), window = static_cast<size_t>(config_.revisit.revisit_window);
  for (const HeldCandidate& h : group) {
    // A revisit member whose hypothesis failed before any loop was committed since it was held
    // waits for one (within revisit_window of its arrival) to be tested alone then: a loop of
    // its revisit accepted alone on the fast path may close the drift that made it fail.
    if (!contradicted && h.kind == HoldKind::kRevisit && h.revision == graph_.revision() && now <= h.arrived + window &&
        graph_.connected(h.query_pos, h.match_pos))
      held_.wait(h, why);
    else
      dropMember(h, why, contradicted);
  }
}

void Verifier::dropMember(const HeldCandidate& h, const std::string& why, bool contradicted) {
  // A revisit member is tested alone once more before it goes if loops were committed since
  // it was held (one of its revisit, accepted alone on the fast path, may have closed the
  // drift that made it fail), unless a released group contradicts it.
  std::string again;
  const bool retest = !contradicted && h.kind == HoldKind::kRevisit && h.revision != graph_.revision() &&
                      graph_.connected(h.query_pos, h.match_pos);
  if (retest && !retestNow()) {
    held_.wait(h, why);  // tested alone on the next keyframe's arrival (nextWaiting())
    return;
  }
  if (retest) ++retest_.count;
  if (retest && rule_->retestAlone(h.candidate, h.query_pos, h.match_pos, &again)) {
    pending_.valid = false;
    const Status s = commitLocked(h.candidate, true);
    if (s.ok) {
      emit_.release(h.candidate, "its revisit hypothesis was not released (" + why + "); tested alone again: " + again);
      return;
    }
  }
  if (!addToGlobalPool(h))
    emit_.drop(h.candidate, retest ? why + "; tested alone again: " + again : why);
}

bool Verifier::retestNow() const {
  // Called on keyframe arrival only (settle(true), nextWaiting()). While the keyframe's work is
  // within revisit_retest_budget_ms; the first re-test of a keyframe always runs (each is bounded
  // by time_budget_ms itself), so every waiting member is tested in turn however busy the
  // keyframes are.
  const double budget = arrivalBudgetMs(config_.revisit.revisit_retest_budget_ms);
  return retest_.count == 0 || budget <= 0 || msSince(retest_.started) < budget;
}

void Verifier::settle(bool revisit) {
  // The store says what is due, one group at a time; each is acted on before the next is asked
  // for (a release or a revocation changes the graph the store's tests read).
  held_.beginSettle(graph_.keyframeCount(), revisit);
  HeldCandidates::Due due;
  while (held_.nextDue(loops_, &due)) {
    switch (due.action) {
      case HeldCandidates::Due::Action::kRelease: {
        // The judge's text opens with the hypothesis' size and loops, which the release names itself.
        const size_t body = due.why.find("): ");
        release(due.group, body != std::string::npos ? due.why.substr(body + 3) : std::string());
        for (const HeldGroup& g : due.dropped) drop(g, due.dropped_why, true);
        break;
      }
      case HeldCandidates::Due::Action::kSettleRivals: settleRivals(due.group, due.targets); break;
      case HeldCandidates::Due::Action::kDrop: drop(due.group, due.why, false); break;
    }
  }
}

void Verifier::release(const HeldGroup& group, const std::string& judged) {
  std::ostringstream why;
  const bool revisit = group.front().kind == HoldKind::kRevisit;
  const bool global = group.front().kind == HoldKind::kGlobal;
  if (revisit)
    why << "released with its revisit hypothesis: " << group.size() << " mutually consistent candidates (loops ";
  else if (global)
    why << "released by the global pass: " << group.size()
        << " inliers of the robust solve over every loop, each pinned down by the others (loops ";
  else
    why << "confirmed: " << group.size() << " held candidates agree with each other (loops ";
  why << group.front().candidate.query_index << "->" << group.front().candidate.match_index << " .. "
      << group.back().candidate.query_index << "->" << group.back().candidate.match_index << ")";
  if (!judged.empty()) why << ": " << judged;
  std::vector<const HeldCandidate*> committed;
  size_t first_match = group.front().match_pos;
  for (const HeldCandidate& h : group) {
    // A candidate held on a weak prior must still pass the test against the graph as it is now
    // (a revisit hypothesis was judged as a whole just now).
    Decided decided;
    if (h.kind == HoldKind::kWeakPrior && graph_.connected(h.query_pos, h.match_pos) &&
        !rule_->recheck(h.candidate, h.query_pos, h.match_pos, &decided)) {
      emit_.drop(h.candidate, "confirmed with its revisit but no longer consistent with the graph");
      continue;
    }
    const bool learn = revisit && rule_->recheck(h.candidate, h.query_pos, h.match_pos, &decided);
    pending_.valid = false;
    const Status s = commitLocked(h.candidate, false);
    if (!s.ok) {
      emit_.drop(h.candidate, "confirmed but not committed: " + s.message);
    } else {
      if (learn) rule_->learn(decided);  // what a confirmed revisit says about the drift
      emit_.release(h.candidate, why.str());
      committed.push_back(&h);
      if (revisit || global) first_match = std::min(first_match, h.match_pos);
    }
  }
  if (committed.empty()) return;
  // One update of the estimate for the whole group; in the host's loop-closure path like a
  // commit: bounded when the group had no prior.
  size_t newest = committed.back()->query_pos;
  for (const HeldCandidate* h : committed) newest = std::max(newest, h->query_pos);
  rule_->updateEstimate(revisit || global ? first_match : committed.front()->match_pos, newest,
                        committed.front()->kind == HoldKind::kNoPrior ? config_.trial.time_budget_ms : 0.0);
}

size_t Verifier::keyframeCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.keyframeCount();
}

size_t Verifier::solveCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.solveCount();
}

size_t Verifier::loopCount() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.loopCount();
}

bool Verifier::hasKeyframe(int64_t index) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.hasKeyframe(index);
}

bool Verifier::estimate(int64_t index, Pose* pose) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.estimate(index, pose);
}

std::vector<TrajectoryPoint> Verifier::trajectory() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.trajectory();
}

double Verifier::driftScale() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return rule_->driftScale();
}

BatchSolveResult Verifier::solveLikeLoopFusion(int max_iterations) const {
  std::lock_guard<std::mutex> lock(mutex_);
  return graph_.solveLikeLoopFusion(max_iterations);
}

}  // namespace core
}  // namespace rover_loop_fusion
