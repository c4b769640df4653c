// Command-line demo of the ROVER core: a simulated drifting trajectory with true and false
// loop candidates, each verified in the order loop_fusion would see it; prints every verdict
// and a summary (precision/recall against the labels, ATE of odometry / accept-all / verified).
//
//   rover_cli_demo [--scene corridor|deck] [--laps N] [--sigma_t M] [--sigma_yaw RAD]
//                  [--threshold M] [--margin N] [--robust_candidate] [--seed N] [--quiet]
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

using namespace rover_loop_fusion;

namespace {

void usage() {
  std::printf(
      "usage: rover_cli_demo [--scene corridor|deck] [--laps N] [--sigma_t M] [--sigma_yaw RAD]\n"
      "                      [--threshold M] [--margin N] [--robust_candidate] [--seed N] [--quiet]\n");
}

std::vector<core::Pose> estimates(const core::Verifier& v) {
  std::vector<core::Pose> out;
  for (const core::TrajectoryPoint& p : v.trajectory()) out.push_back(p.estimate);
  return out;
}

}  // namespace

namespace {

/// Parses the command line; returns -1 to run, or the exit status.
int parseArguments(int argc, char** argv, sim::LapsOptions* opt_out, core::VerifierConfig* cfg_out, std::string* scene_out,
                   bool* quiet_out) {
  sim::LapsOptions& opt = *opt_out;
  core::VerifierConfig& cfg = *cfg_out;
  std::string& scene = *scene_out;
  bool& quiet = *quiet_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        usage();
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--scene") scene = next();
    else if (a == "--laps") opt.laps = std::atoi(next());
    else if (a == "--sigma_t") opt.sigma_t = std::atof(next());
    else if (a == "--sigma_yaw") opt.sigma_yaw = std::atof(next());
    else if (a == "--threshold") cfg.metric.threshold = std::atof(next());
    else if (a == "--margin") cfg.trial.window_margin = std::atoi(next());
    else if (a == "--robust_candidate") cfg.trial.robust_candidate = true;
    else if (a == "--seed") opt.seed = static_cast<uint32_t>(std::atoi(next()));
    else if (a == "--quiet") quiet = true;
    else {
      usage();
      return a == "--help" || a == "-h" ? 0 : 2;
    }
  }
  if (scene == "deck") {
    // Parking deck: a spiral, each lap one floor (3 m) up; every "revisit" is a floor away.
    opt.lap_z_step = 3.0;
  } else if (scene != "corridor") {
    usage();
    return 2;
  }
  const std::string err = cfg.validate();
  if (!err.empty()) {
    std::fprintf(stderr, "invalid parameters: %s\n", err.c_str());
    return 2;
  }

  return -1;
}

/// The summary: decisions against the labels and the ATE of each trajectory.
void printSummary(const sim::Scene& s, const core::VerifierConfig& cfg, int tp, int fp, int tn, int fn,
                  core::Verifier& verifier, core::KeyframeGraph& accept_all) {
  std::vector<core::Pose> truth, odom;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    truth.push_back(kf.truth);
    odom.push_back(kf.vio);
  }
  const core::BatchSolveResult lf_all = accept_all.solveLikeLoopFusion(5);
  const core::BatchSolveResult lf_verified = verifier.solveLikeLoopFusion(5);
  std::printf("\nsummary: %d candidates (%d true, %d false): accepted %d, rejected %d\n",
              tp + fp + tn + fn, tp + fn, fp + tn, tp + fp, tn + fn);
  std::printf("  true positives %d, false positives %d, true negatives %d, false negatives %d\n", tp,
              fp, tn, fn);
  std::printf("  precision %s, recall %s (threshold %.2f m)\n", sim::ratioText(tp, tp + fp).c_str(),
              sim::ratioText(tp, tp + fn).c_str(), cfg.metric.threshold);
  std::printf("  ATE [m]: odometry %.3f | accept-all (loop_fusion) %.3f | verified (loop_fusion) %.3f | verifier estimate %.3f\n",
              sim::ate(odom, truth), sim::ate(lf_all.poses, truth), sim::ate(lf_verified.poses, truth),
              sim::ate(estimates(verifier), truth));
}

}  // namespace

int main(int argc, char** argv) {
  sim::LapsOptions opt;
  core::VerifierConfig cfg;
  std::string scene = "corridor";
  bool quiet = false;
  const int parsed = parseArguments(argc, argv, &opt, &cfg, &scene, &quiet);
  if (parsed >= 0) return parsed;

  const sim::Scene s = sim::makeLapsScene(opt);
  core::Verifier verifier(cfg);
  core::KeyframeGraph accept_all(cfg);  // what loop_fusion does without us: every candidate is used
  int tp = 0, fp = 0, tn = 0, fn = 0;
  size_t next = 0;
  std::printf("scene %s: %zu keyframes, %zu candidates (%d laps, sigma_t %.3f m, sigma_yaw %.4f rad)\n",
              scene.c_str(), s.keyframes.size(), s.candidates.size(), opt.laps, opt.sigma_t,
              opt.sigma_yaw);
  if (!quiet)
    std::printf("%6s %6s %5s %7s  %-8s %-22s %8s %5s %7s\n", "query", "match", "label", "dist[m]",
                "verdict", "reason", "score[m]", "iters", "ms");
  for (const sim::SimKeyframe& kf : s.keyframes) {
    for (const core::Status& st : {verifier.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q),
                                   accept_all.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q)}) {
      if (!st) {
        std::fprintf(stderr, "addKeyframe failed: %s\n", st.message.c_str());
        return 1;
      }
    }
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
      const sim::SimCandidate& c = s.candidates[next];
      const core::Verdict vd = verifier.verify(c.candidate);
      if (vd.accepted) verifier.commit(c.candidate);
      accept_all.addLoop(c.candidate);
      if (c.is_true) (vd.accepted ? tp : fn)++;
      else (vd.accepted ? fp : tn)++;
      if (!quiet)
        std::printf("%6lld %6lld %5s %7.2f  %-8s %-22s %8.3f %5d %7.2f\n",
                    static_cast<long long>(c.candidate.query_index),
                    static_cast<long long>(c.candidate.match_index), c.is_true ? "TRUE" : "FALSE",
                    c.truth_distance, vd.accepted ? "ACCEPT" : "REJECT", core::toString(vd.reason),
                    vd.score, vd.iterations, vd.elapsed_ms);
    }
  }

  printSummary(s, cfg, tp, fp, tn, fn, verifier, accept_all);
  return 0;
}
