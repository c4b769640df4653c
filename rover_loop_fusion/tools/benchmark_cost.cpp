// Cost benchmark: time of one verification next to loop_fusion's own optimisation of the same
// graph, measured side by side in one run.
//
// For each graph size N (keyframes) and loop span S (keyframes between match and query) it
// builds a simulated graph the way loop_fusion grows it (keyframes in order, true loops
// committed as they come), then times
//   verify : Verifier::verify() of one more candidate (median of --repeats runs; verify does
//            not change the graph, so every run sees the same graph);
//   full   : Verifier::solveLikeLoopFusion(5): the whole graph from the earliest loop,
//            initialised from VIO, 5 iterations (what optimize4DoF does after every loop);
// and prints a table and writes CSV. The trial solve's time budget is lifted (the cost is what
// is measured; the verifier would reject a candidate whose solve ran past it). --mode 6dof
// times the 6-DoF graph (VO without IMU) instead.
//
//   rover_benchmark_cost [--sizes 1000,10000] [--spans 100,1000] [--repeats 20] [--mode 4dof|6dof]
//                        [--csv FILE]
#include "rover_loop_fusion/core/geometry.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

using namespace rover_loop_fusion;

namespace {

std::vector<int> parseList(const std::string& s) {
  std::vector<int> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(std::atoi(item.c_str()));
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

double peakRssMb() {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

struct Row {
  int n, span, window, iterations;
  double verify_ms, verify_p90_ms, full_ms, score, rss_mb;
  bool accepted;
};

Row run(int n, int span, int repeats, core::Mode mode) {
  // Laps of a rectangle whose perimeter is `span` keyframes: every revisit is one span back.
  sim::LapsOptions o;
  o.step = 0.5;
  const double perimeter = span * o.step;
  o.width = perimeter / 3.0;
  o.height = perimeter / 6.0;
  o.laps = std::max(2, (n + span - 1) / span);
  o.true_every = 10;  // a committed loop every 10 revisit keyframes
  o.false_every = 0;
  o.seed = 42;
  sim::Scene s = sim::makeLapsScene(o);
  s.keyframes.resize(std::min<size_t>(s.keyframes.size(), n));

  core::VerifierConfig cfg;
  cfg.mode = mode;
  cfg.time_budget_ms = 0.0;
  core::Verifier v(cfg);
  size_t next = 0;
  const sim::SimCandidate* last = nullptr;
  for (const sim::SimKeyframe& kf : s.keyframes) {
    v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q);
    for (; next < s.candidates.size() && s.candidates[next].candidate.query_index == kf.index; ++next) {
      last = &s.candidates[next];
      v.commit(last->candidate);
    }
  }
  // The measured candidate: the newest keyframe against its revisit one span back.
  const sim::SimKeyframe& q = s.keyframes.back();
  const sim::SimKeyframe& m = s.keyframes[s.keyframes.size() - 1 - span];
  core::LoopCandidate c;
  c.query_index = q.index;
  c.match_index = m.index;
  const core::Pose rel = sim::relative(m.truth, q.truth);
  c.relative_t = rel.t;
  c.relative_q = rel.q;
  c.relative_yaw = core::yawOf(rel.q);
  (void)last;

  Row r{};
  r.n = static_cast<int>(s.keyframes.size());
  r.span = span;
  std::vector<double> t_verify;
  core::Verdict vd;
  for (int i = 0; i < repeats; ++i) {
    vd = v.verify(c);
    t_verify.push_back(vd.elapsed_ms);
  }
  std::vector<double> t_full;
  for (int i = 0; i < std::max(3, repeats / 5); ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    const core::BatchSolveResult b = v.solveLikeLoopFusion(5);
    t_full.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    if (!b.ok) std::fprintf(stderr, "full solve failed: %s\n", b.message.c_str());
  }
  std::sort(t_verify.begin(), t_verify.end());
  r.verify_ms = median(t_verify);
  r.verify_p90_ms = t_verify[std::min(t_verify.size() - 1, t_verify.size() * 9 / 10)];
  r.full_ms = median(t_full);
  r.window = vd.window_size;
  r.iterations = vd.iterations;
  r.score = vd.score;
  r.accepted = vd.accepted;
  r.rss_mb = peakRssMb();
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<int> sizes = {1000, 10000};
  std::vector<int> spans = {100, 1000};
  int repeats = 20;
  core::Mode mode = core::Mode::kFourDof;
  std::string csv;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (i + 1 >= argc) {
      std::fprintf(stderr, "usage: rover_benchmark_cost [--sizes A,B] [--spans A,B] [--repeats N] [--mode 4dof|6dof] [--csv FILE]\n");
      return 2;
    }
    if (a == "--sizes") sizes = parseList(argv[++i]);
    else if (a == "--spans") spans = parseList(argv[++i]);
    else if (a == "--repeats") repeats = std::max(1, std::atoi(argv[++i]));
    else if (a == "--csv") csv = argv[++i];
    else if (a == "--mode") {
      if (!core::parseMode(argv[++i], &mode)) {
        std::fprintf(stderr, "--mode: 4dof or 6dof\n");
        return 2;
      }
    }
    else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return 2;
    }
  }
  std::printf("%9s %6s %7s %6s %12s %12s %14s %8s %7s %8s\n", "keyframes", "span", "window", "iters",
              "verify[ms]", "verify p90", "loop_fusion[ms]", "ratio", "score", "rss[MB]");
  FILE* f = csv.empty() ? nullptr : std::fopen(csv.c_str(), "w");
  if (f) std::fprintf(f, "keyframes,span,window,iterations,verify_median_ms,verify_p90_ms,loop_fusion_full_ms,ratio_full_over_verify,score,accepted,peak_rss_mb\n");
  for (int n : sizes) {
    for (int span : spans) {
      if (span >= n) continue;
      const Row r = run(n, span, repeats, mode);
      std::printf("%9d %6d %7d %6d %12.3f %12.3f %14.3f %8.2f %7.3f %8.1f\n", r.n, r.span, r.window,
                  r.iterations, r.verify_ms, r.verify_p90_ms, r.full_ms, r.full_ms / r.verify_ms,
                  r.score, r.rss_mb);
      std::fflush(stdout);
      if (f)
        std::fprintf(f, "%d,%d,%d,%d,%.4f,%.4f,%.4f,%.3f,%.4f,%d,%.1f\n", r.n, r.span, r.window,
                     r.iterations, r.verify_ms, r.verify_p90_ms, r.full_ms, r.full_ms / r.verify_ms,
                     r.score, r.accepted ? 1 : 0, r.rss_mb);
    }
  }
  if (f) std::fclose(f);
  return 0;
}
