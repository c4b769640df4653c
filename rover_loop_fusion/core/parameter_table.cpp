// The verifier parameter table (core/parameters.h): one row per parameter, in the order of
// config/rover_template.yaml. The values, their checks and the parameter files: parameters.cpp.
#include "rover_loop_fusion/core/parameters.h"

#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

namespace {

/// A field of VerifierConfig (nested by concern): FIELD(metric.threshold).
template <class T>
using Field = T& (*)(VerifierConfig&);
#define FIELD(path) [](VerifierConfig& c) -> decltype(c.path)& { return c.path; }

template <class T>
const T& read(Field<T> field, const VerifierConfig& c) {
  return field(const_cast<VerifierConfig&>(c));  // (field only names a member)
}

Parameter number(const char* name, const char* unit, Field<double> field, double min, double max, bool min_open,
                 const char* doc) {
  Parameter p;
  p.name = name;
  p.type = Parameter::Type::kNumber;
  p.unit = unit;
  p.min = min;
  p.max = max;
  p.min_open = min_open;
  p.doc = doc;
  p.get = [field](const VerifierConfig& c) { return ParameterValue::Number(read(field, c), false); };
  p.set = [field](VerifierConfig* c, const ParameterValue& v, bool) { field(*c) = v.number; };
  return p;
}

/// A field in radians, read and written in degrees.
Parameter degrees(const char* name, Field<double> field, double min, double max, bool min_open, const char* doc) {
  Parameter p = number(name, "deg", field, min, max, min_open, doc);
  p.get = [field](const VerifierConfig& c) { return ParameterValue::Number(read(field, c) * 180.0 / M_PI, false); };
  p.set = [field](VerifierConfig* c, const ParameterValue& v, bool) { field(*c) = v.number * M_PI / 180.0; };
  return p;
}

Parameter integer(const char* name, const char* unit, Field<int> field, int min, int max, const char* doc) {
  Parameter p;
  p.name = name;
  p.type = Parameter::Type::kInteger;
  p.unit = unit;
  p.min = min;
  p.max = max;
  p.doc = doc;
  p.get = [field](const VerifierConfig& c) { return ParameterValue::Number(read(field, c), true); };
  p.set = [field](VerifierConfig* c, const ParameterValue& v, bool) { field(*c) = static_cast<int>(v.number); };
  return p;
}

Parameter boolean(const char* name, Field<bool> field, const char* doc) {
  Parameter p;
  p.name = name;
  p.type = Parameter::Type::kBoolean;
  p.doc = doc;
  p.get = [field](const VerifierConfig& c) { return ParameterValue::Boolean(read(field, c)); };
  p.set = [field](VerifierConfig* c, const ParameterValue& v, bool) { field(*c) = v.boolean; };
  return p;
}

Parameter choice(const char* name, std::vector<std::string> choices, const char* doc) {
  Parameter p;
  p.name = name;
  p.type = Parameter::Type::kChoice;
  p.choices = std::move(choices);
  p.doc = doc;
  return p;
}

/// How candidates are decided, decision metric and the alignment.
void decisionRows(std::vector<Parameter>& t) {
  using C = VerifierConfig;
  // How candidates are decided (core/decision.h).
  Parameter decision = choice("decision", {"metric", "chi2", "revisit"},
                              "metric: threshold and innovation gate in metres (the paper's method); chi2: in "
                              "units of drift (drift_* model, gate_probability, lookalike_*; 6-DoF: on x, y, z, yaw); "
                              "revisit: both per candidate, and the rest judged by revisit (revisit_*)");
  decision.get = [](const C& c) { return ParameterValue::Text(toString(c.decision)); };
  decision.set = [](C* c, const ParameterValue& v, bool) { parseDecision(v.text, &c->decision); };
  t.push_back(decision);
  // decision: metric (the innovation gate, then the score).
  t.push_back(number("threshold", "m", FIELD(metric.threshold), 0.0, 10.0, true,
                     "accept iff the deformation score <= threshold + threshold_per_metre x path length"));
  t.push_back(number("threshold_per_metre", "m/m", FIELD(metric.threshold_per_metre), 0.0, 1.0, false,
                     "threshold growth per metre of odometry path between match and query; 0: fixed"));
  t.push_back(number("max_threshold", "m", FIELD(metric.max_threshold), 0.0, 10.0, false,
                     "cap of the effective threshold; 0: none"));
  t.push_back(number("max_innovation", "m", FIELD(metric.max_innovation), 0.0, 100.0, false,
                     "innovation gate: reject without a solve when the candidate disagrees with the "
                     "estimate by more than max_innovation + max_innovation_per_metre x path length; 0: no gate"));
  t.push_back(number("max_innovation_per_metre", "m/m", FIELD(metric.max_innovation_per_metre), 0.0, 1.0, false,
                     "drift allowed per metre of odometry path between match and query"));
  Parameter mode = choice("mode", {"auto", "4dof", "6dof"},
                          "pose graph: 4dof (VIO), 6dof (VO) or auto (4dof with IMU, 6dof without)");
  mode.get = [](const C& c) { return ParameterValue::Text(toString(c.mode)); };
  mode.set = [](C* c, const ParameterValue& v, bool host_uses_imu) {
    if (v.text == "auto") c->mode = host_uses_imu ? Mode::kFourDof : Mode::kSixDof;
    else parseMode(v.text, &c->mode);
  };
  t.push_back(mode);
  Parameter alignment = choice("alignment", {"se3", "sim3"},
                               "alignment before scoring: se3, or sim3 for monocular VO (scale drift is not deformation)");
  alignment.get = [](const C& c) { return ParameterValue::Text(toString(c.alignment)); };
  alignment.set = [](C* c, const ParameterValue& v, bool) { parseAlignment(v.text, &c->alignment); };
  t.push_back(alignment);
  Parameter no_prior = boolean("accept_without_prior", FIELD(host.accept_without_prior),
                               "verdict for candidates between sequences nothing connects yet (no trajectory "
                               "prior); set by the host from ~relocalisation");
  no_prior.host_set = true;
  t.push_back(no_prior);
}

/// The trial optimisation.
void trialRows(std::vector<Parameter>& t) {
  t.push_back(integer("max_iterations", "", FIELD(trial.max_iterations), 1, 1000,
                      "trial solve iteration limit; hitting it rejects (not_converged)"));
  t.push_back(number("time_budget_ms", "ms", FIELD(trial.time_budget_ms), 0.0, 60000.0, false,
                     "time limit of a verification: a trial solve that would not finish in time is not "
                     "started or is stopped, and rejects (time_budget_exceeded); 0: none"));
  // Measured on the shipped scenarios (docs/design-notes.md): 1e-2 let 4-23 of 80 trial solves
  // per scenario stop at iteration 0 and moved scores by up to 0.39 m; >= 0.5 let false loops in.
  t.push_back(number("function_tolerance", "", FIELD(trial.function_tolerance), 0.0, 1e-3, true,
                     "relative cost change at which the trial solve has converged"));
  t.push_back(integer("odometry_neighbours", "", FIELD(trial.odometry_neighbours), 1, 10,
                      "odometry edges to the previous N keyframes of a sequence (loop_fusion: 4)"));
  t.push_back(number("loop_huber", "m", FIELD(trial.loop_huber), 0.0, 10.0, true,
                     "Huber scale of accepted loop edges (loop_fusion: 0.1)"));
  t.push_back(boolean("robust_candidate", FIELD(trial.robust_candidate),
                      "give the candidate the Huber loss too (experiments only)"));
  t.push_back(integer("window_margin", "keyframes", FIELD(trial.window_margin), 0, 10000,
                      "keyframes before the match also optimised and scored"));
  t.push_back(integer("condense_min_window", "keyframes", FIELD(trial.condense_min_window), 0, 100000000,
                      "trials over more keyframes than this are solved on the condensed graph (4-DoF and 6-DoF) "
                      "(bounded cost); 0: always the full window"));
  t.push_back(integer("trial_loop_anchors", "", FIELD(trial.trial_loop_anchors), 2, 100000,
                      "accepted loops (revisits merged, then older ones thinned) at most in a condensed trial: "
                      "bounds its cost"));
}

/// Plausibility of the input.
void inputRows(std::vector<Parameter>& t) {
  t.push_back(number("max_relative_translation", "m", FIELD(input.max_relative_translation), 0.0, 100.0, true,
                     "candidates with a longer relative translation are invalid input"));
  t.push_back(degrees("max_relative_yaw_deg", FIELD(input.max_relative_yaw), 0.0, 180.0, true,
                      "candidates with a larger relative yaw are invalid input"));
  t.push_back(number("quaternion_tolerance", "", FIELD(input.quaternion_tolerance), 0.0, 0.1, true,
                     "allowed | |q| - 1 | of the quaternions handed in"));
  Parameter anchor = boolean("anchor_incoming_keyframes", FIELD(host.anchor_incoming_keyframes),
                             "poses arrive in raw per-session VIO frames and the verifier applies the sequence "
                             "shift itself; set by the host (rover_verifier_node: true; loop_fusion: false)");
  anchor.host_set = true;
  t.push_back(anchor);
  t.push_back(number("max_keyframe_jump", "m", FIELD(input.max_keyframe_jump), 0.0, 1000.0, true,
                     "a keyframe farther from the previous one of its sequence is refused (a glitch), "
                     "unless jump_confirmations keyframes confirm it (a relocation: a new segment)"));
  t.push_back(number("max_stamp_jump", "s", FIELD(input.max_stamp_jump), 0.0, 1e6, true,
                     "a keyframe stamped not after the previous one of its sequence, or more than this "
                     "after it, is refused unless jump_confirmations keyframes confirm the new clock"));
  t.push_back(integer("jump_confirmations", "keyframes", FIELD(input.jump_confirmations), 2, 100,
                      "consecutive consistent keyframes that make the verifier accept a position or "
                      "stamp jump instead of refusing it"));
}

/// The drift model, the gate, the look-alike test (decision chi2; the cycle test).
void driftRows(std::vector<Parameter>& t) {
  // decision: chi2 (the drift model, the gate, the look-alike test; core/drift.h, core/decision.h).
  t.push_back(number("drift_xy", "m/sqrt(m)", FIELD(drift.drift_xy), 0.0, 10.0, true,
                     "odometry drift, horizontal: standard deviation per square root of a metre travelled"));
  t.push_back(number("drift_z", "m/sqrt(m)", FIELD(drift.drift_z), 0.0, 10.0, true,
                     "odometry drift, vertical: standard deviation per square root of a metre travelled"));
  t.push_back(degrees("drift_yaw_deg", FIELD(drift.drift_yaw), 0.0, 90.0, true,
                      "odometry yaw drift: standard deviation [deg] per square root of a metre travelled"));
  t.push_back(number("drift_min_step", "m", FIELD(drift.drift_min_step), 0.0, 100.0, true,
                     "every keyframe step drifts at least as much as one this long (rotations in place)"));
  t.push_back(number("loop_sigma", "m", FIELD(drift.loop_sigma), 0.0, 10.0, true,
                     "standard deviation of a loop's relative translation (per axis)"));
  t.push_back(degrees("loop_sigma_yaw_deg", FIELD(drift.loop_sigma_yaw), 0.0, 90.0, true,
                      "standard deviation of a loop's relative yaw"));
  t.push_back(number("gate_probability", "", FIELD(chi2.gate_probability), 0.5, 1.0 - 1e-12, false,
                     "reject iff the innovation's Mahalanobis distance exceeds this chi-square quantile (4 dof)"));
  t.push_back(number("lookalike_distance", "m", FIELD(chi2.lookalike_distance), 0.0, 1000.0, false,
                     "the environment repeats this far away horizontally (aisles, doors); 0: no such look-alikes"));
  t.push_back(number("lookalike_distance_vertical", "m", FIELD(chi2.lookalike_distance_vertical), 0.0, 1000.0, false,
                     "the environment repeats this far away vertically (floors); 0: no such look-alikes"));
  t.push_back(number("lookalike_margin", "", FIELD(chi2.lookalike_margin), 0.0, 100.0, false,
                     "reject unless the place explains the innovation better than any look-alike by this "
                     "much (difference of Mahalanobis distances, 2 ln of the likelihood ratio)"));
  t.push_back(integer("max_loop_anchors", "", FIELD(chi2.max_loop_anchors), 2, 100000,
                      "accepted loops (revisits merged) at most in the condensed graph: bounds the cost"));
}

/// Holding, confirming and revocation.
void holdRows(std::vector<Parameter>& t) {
  // Holding and confirming (core/verifier.h: takeDecisions).
  t.push_back(integer("confirm_count", "", FIELD(hold.confirm_count), 2, 100,
                      "held candidates of one stretch that must agree with each other to be released"));
  t.push_back(integer("confirm_window", "keyframes", FIELD(hold.confirm_window), 1, 100000,
                      "a held candidate not confirmed within this many keyframes is dropped"));
  t.push_back(integer("confirm_stretch", "keyframes", FIELD(hold.confirm_stretch), 1, 100000,
                      "queries at most this many keyframes apart are one stretch: held candidates that confirm "
                      "each other, the accepted loops a rival contradicts"));
  t.push_back(number("revoke_margin", "", FIELD(hold.revoke_margin), 0.0, 100.0, false,
                     "revocation: the rivals' misfit must be lower than the contradicted loops' by this much "
                     "(median squared Mahalanobis distances)"));
  t.push_back(integer("revoke_group", "", FIELD(hold.revoke_group), 0, 100,
                      "rivals of one stretch that must agree (and outnumber the accepted loops they "
                      "contradict) to revoke those loops; 0: no revocation"));
  t.push_back(number("hold_sigma", "m", FIELD(chi2.hold_sigma), 0.0, 1000.0, false,
                     "chi2: hold candidates while the relative position's largest standard deviation exceeds "
                     "this (the prior alone too weak); 0: never hold"));
  Parameter confirm = boolean("confirm_without_prior", FIELD(host.confirm_without_prior),
                              "hold candidates between unconnected sequences and release them when confirmed; "
                              "set by the host (relocalisation policy)");
  confirm.host_set = true;
  t.push_back(confirm);
  t.push_back(boolean("calibrate_drift", FIELD(drift.calibrate_drift),
                      "scale the drift model to the innovations of the accepted loops (robust fit)"));
}

/// decision: revisit.
void revisitRows(std::vector<Parameter>& t) {
  // decision: revisit (core/decision_rule.h, core/held_candidates.h).
  t.push_back(integer("revisit_support", "", FIELD(revisit.revisit_support), 2, 100,
                      "members a revisit hypothesis needs before it can be released"));
  t.push_back(integer("revisit_window", "keyframes", FIELD(revisit.revisit_window), 1, 100000,
                      "a revisit hypothesis not released within this many keyframes after its first member is "
                      "dropped"));
  t.push_back(integer("revisit_stretch", "keyframes", FIELD(revisit.revisit_stretch), 1, 100000,
                      "queries at most this many keyframes apart belong to one revisit (members, rivals)"));
  t.push_back(number("revisit_reject_probability", "", FIELD(revisit.revisit_reject_probability), 0.5, 1.0 - 1e-12, false,
                     "candidates beyond this chi-square quantile are rejected at once; the rest that the fast "
                     "path does not accept are held"));
  t.push_back(number("revisit_gate_probability", "", FIELD(revisit.revisit_gate_probability), 0.5, 1.0 - 1e-12, false,
                     "a hypothesis' median member must lie within this chi-square quantile of the prior"));
  t.push_back(number("revisit_max_sigma", "m", FIELD(revisit.revisit_max_sigma), 0.0, 1000.0, false,
                     "a hypothesis whose relative position std exceeds this is not released; 0: no bound"));
  t.push_back(number("revisit_score_sigmas", "", FIELD(revisit.revisit_score_sigmas), 0.0, 100.0, false,
                     "a hypothesis' trial score must be at most max(threshold, this x the relative "
                     "position's largest standard deviation)"));
  t.push_back(boolean("revisit_observed_drift", FIELD(revisit.revisit_observed_drift),
                      "that standard deviation scaled to the drift the accepted loops have shown (never "
                      "below the model's), unless a look-alike explains the hypothesis as well as the place"));
  t.push_back(number("revisit_member_weight", "", FIELD(revisit.revisit_member_weight), 0.0, 100.0, false,
                     "what each member beyond the first takes off a hypothesis' misfit (its median "
                     "Mahalanobis distance) when rivals compete"));
  t.push_back(number("revisit_margin", "", FIELD(revisit.revisit_margin), 0.0, 100.0, false,
                     "a hypothesis is released only if its misfit is lower than every rival's by this"));
  t.push_back(integer("revisit_extend", "loops", FIELD(revisit.revisit_extend), 0, 1000,
                      "a candidate the per-candidate test rejects is accepted if this many accepted loops of "
                      "its stretch close a cycle with it along the VIO odometry (within gate_probability and "
                      "revisit_extend_residual), none contradicts it and its trial converges; 0: off"));
  t.push_back(number("revisit_extend_residual", "m", FIELD(revisit.revisit_extend_residual), 0.0, 100.0, false,
                     "the largest translation residual of such a cycle"));
  t.push_back(number("revisit_retest_budget_ms", "ms", FIELD(revisit.revisit_retest_budget_ms), 0.0, 60000.0, false,
                     "what the re-tests of dropped revisit members may spend together on one keyframe's "
                     "arrival; the rest wait for the next keyframe (one runs per keyframe at least); "
                     "0 (or time_budget_ms 0): no bound"));
}

/// decision revisit's global pass.
void globalRows(std::vector<Parameter>& t) {
  // decision revisit's global pass (core/global_pass.cpp, Verifier::globalPass).
  t.push_back(boolean("global_check", FIELD(global.global_check),
                      "hold what the per-candidate test rejects for contradicting the graph and release "
                      "the inliers of a robust solve over every loop (decision revisit)"));
  t.push_back(integer("global_period", "keyframes", FIELD(global.global_period), 1, 100000,
                      "keyframes between two global passes while candidates are held"));
  t.push_back(integer("global_window", "keyframes", FIELD(global.global_window), 1, 10000000,
                      "a candidate held for the global pass and not released within this many keyframes is dropped"));
  t.push_back(integer("global_max_held", "", FIELD(global.global_max_held), 1, 100000,
                      "candidates held for the global pass at most (the oldest is dropped): bounds its cost"));
  t.push_back(number("global_inlier_probability", "", FIELD(global.global_inlier_probability), 0.5, 1.0 - 1e-12, false,
                     "chi-square quantile (4 dof) of a loop's residual that counts as an inlier, and of its "
                     "innovation against the other loops"));
  t.push_back(number("global_prior_probability", "", FIELD(global.global_prior_probability), 0.5, 1.0 - 1e-12, false,
                     "an inlier is released only if its innovation against the prior alone (the accepted "
                     "loops) lies within this chi-square quantile (4 dof)"));
  t.push_back(number("global_tear_probability", "", FIELD(global.global_tear_probability), 0.5, 1.0 - 1e-12, false,
                     "chi-square quantile (4 dof) beyond which the robust solution tears a chain of odometry; "
                     "an inlier whose cycle holds a torn chain is not released"));
  t.push_back(number("global_max_sigma", "m", FIELD(global.global_max_sigma), 0.0, 1000.0, false,
                     "an inlier is released only if the other loops pin its relative position down to this std; "
                     "0: no bound"));
  t.push_back(number("global_budget_ms", "ms", FIELD(global.global_budget_ms), 0.0, 1e6, false,
                     "a global pass that runs longer stops and releases nothing (the pool waits for the next); "
                     "0, or time_budget_ms 0: no bound"));
  t.push_back(boolean("global_compete", FIELD(global.global_compete),
                      "before a release, solve again without it: if a rival candidate of the same revisit "
                      "then passes every test, the revisit is ambiguous and neither is released"));
}

std::vector<Parameter> makeTable() {
  std::vector<Parameter> t;
  decisionRows(t);
  trialRows(t);
  inputRows(t);
  driftRows(t);
  holdRows(t);
  revisitRows(t);
  globalRows(t);
  return t;
}

}  // namespace

const std::vector<Parameter>& verifierParameters() {
  static const std::vector<Parameter> table = makeTable();
  return table;
}

}  // namespace core
}  // namespace rover_loop_fusion
