// Cost benchmark: what one verification costs on realistic candidates, next to loop_fusion's
// own optimisation of the same graph, measured side by side in one run.
//
// A graph is a robot doing laps of a rectangle whose perimeter is P keyframes (0.5 m apart),
// VIO-like drift (yaw and translation random walks), and a loop committed every max(5, P/10)
// keyframes to the previous lap (an oracle: what a verifier that accepts the true loops builds).
// The last --queries keyframes are the measured ones: each, as it arrives, gets for every span
// S (keyframes from the match back to this query, a multiple of P) one true candidate (the
// true relative pose + PnP-like noise) and one false one (a look-alike --false-offset metres
// away laterally, vertically or along the track, + the same noise), as loop_fusion would hand
// them; nothing is committed while measuring, so every candidate sees the same graph. Spans from 10 to the whole run ("whole": the query's place in the first lap):
// P = min(S, --lap-max), so a span-10 graph is a 5 m circuit and a span-99000 one 99 laps of
// 500 m. Every verify() is timed from the call to the verdict, with the verifier's shipped
// time budget (--time-budget-ms, 0 lifts it) so that time_budget_exceeded is counted.
//
// loop_fusion's full optimisation: KeyframeGraph::solveLikeLoopFusion(5) (the whole graph from
// the earliest loop, initialised from VIO, 5 iterations, as optimize4DoF/6DoF after every
// loop) on a stand-in graph with the same keyframes and loops plus the last true candidate of
// the longest span, timed in the same process right after the verifications (median of
// --full-repeats). Each graph runs in its own child process so that its peak RSS is its own:
// verifier_rss_mb is the peak before loop_fusion's solve (graph, verifications, and the
// simulated trajectory), peak_rss_mb includes that solve.
//
// Output: a table on stdout, one row per (mode, graph size, span), and per graph a line with
// what commit() cost while the graph was built and for one loop from the newest keyframe back
// across the longest span, committed after everything else (the estimate's update after a
// loop that moves the whole run); --csv FILE the same rows (numeric columns only, for
// plotting); --verdicts FILE one row per candidate.
//
//   rover_benchmark_cost [--quick] [--sizes 1000,10000,20000,100000]
//       [--spans 10,100,1000,10000,whole] [--modes 4dof,6dof] [--queries 50]
//       [--config FILE] [--set NAME=VALUE]... [--time-budget-ms 200] [--full-repeats 3]
//       [--lap-max 1000] [--seed N] [--csv FILE] [--verdicts FILE]
//   The verifier runs with VerifierConfig's defaults (the indoor YAML's values), then --config
//   (a verifier YAML; repeatable, applied in order: --config config/rover_template.yaml --config
//   config/rover_outdoor.yaml), then each --set (any parameter of
//   docs/ros-api.md; --time-budget-ms MS is --set time_budget_ms=MS); the mode is per graph.
//   Two runs with the same seed and graph parameters see the same graphs and candidates
//   whatever their time budget (nothing measured is committed; the graph's own loops are
//   committed to convergence), so their --verdicts files can be compared row by row.
//   --quick: sizes 1000,2000, spans 10,100,whole, both modes, 5 queries, 1 full solve (CI).
//   --mode M and --repeats N are the older names of --modes and --queries.
#include "rover_loop_fusion/core/geometry.h"
#include "rover_loop_fusion/core/parameters.h"
#include "rover_loop_fusion/core/pose_graph.h"
#include "rover_loop_fusion/core/verifier.h"
#include "rover_loop_fusion/sim/scene.h"

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <sstream>
#include <string>
#include <vector>

using namespace rover_loop_fusion;

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct Options {
  std::vector<int> sizes = {1000, 10000, 20000, 100000};
  std::vector<std::string> spans = {"10", "100", "1000", "10000", "whole"};
  std::vector<core::Mode> modes = {core::Mode::kFourDof, core::Mode::kSixDof};
  int queries = 50;
  int full_repeats = 3;
  int lap_max = 1000;
  /// The verifier's parameters (defaults, --config FILE, --set NAME=VALUE; the mode is per graph).
  core::VerifierConfig config;
  // Drift per 0.5 m keyframe step: ~0.8 % of the distance over a 100 m lap, mostly from yaw.
  double sigma_t = 0.005;
  double sigma_yaw = 0.001;
  double candidate_sigma_t = 0.03;   // PnP noise of a candidate's relative pose [m]
  double candidate_sigma_yaw = 0.005;  // [rad]
  double false_offset_min = 1.0;     // look-alike distance [m], uniform in [min, max]
  double false_offset_max = 3.0;
  uint32_t seed = 42;
  std::string csv, verdicts;
};

/// One graph: laps of `lap` keyframes, measured at the given spans (multiples of lap).
struct GraphPlan {
  core::Mode mode;
  int keyframes;
  int lap;
  std::vector<int> spans;
};

struct Measured {
  int span;
  bool is_true;
  double offset;  // look-alike distance [m], 0 for true candidates
  core::Verdict verdict;
  double ms;
};

std::vector<std::string> split(const std::string& s) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, ',')) if (!item.empty()) out.push_back(item);
  return out;
}

bool parsePositive(const std::string& s, int* v) {
  char* end = nullptr;
  const long x = std::strtol(s.c_str(), &end, 10);
  if (s.empty() || *end != '\0' || x <= 0 || x > 100000000) return false;
  *v = static_cast<int>(x);
  return true;
}

double percentile(std::vector<double> v, double p) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * v.size()));
  return v[std::min(v.size() - 1, rank > 0 ? rank - 1 : 0)];
}

double peakRssMb() {
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  return ru.ru_maxrss / 1024.0;
}

int dofOf(core::Mode m) { return m == core::Mode::kFourDof ? 4 : 6; }

/// The graph sizes' spans, resolved: "whole" is the longest span every query has; a span
/// longer than the run is skipped. Spans that share a lap length share a graph.
std::vector<GraphPlan> plan(const Options& o) {
  std::vector<GraphPlan> plans;
  for (core::Mode mode : o.modes) {
    for (int n : o.sizes) {
      std::map<int, std::vector<int>> by_lap;
      for (const std::string& s : o.spans) {
        const int longest = n - o.queries;
        int req = 0;
        if (s == "whole") req = longest;
        else if (!parsePositive(s, &req)) continue;  // checked in main
        if (req > longest || req < 1) {
          std::fprintf(stderr, "note: span %s skipped for %d keyframes (longest span with %d queries: %d)\n",
                       s.c_str(), n, o.queries, longest);
          continue;
        }
        const int lap = std::min(req, o.lap_max);
        const int span = req / lap * lap;
        std::vector<int>& spans = by_lap[lap];
        if (std::find(spans.begin(), spans.end(), span) == spans.end()) spans.push_back(span);
      }
      for (auto& kv : by_lap) {
        std::sort(kv.second.begin(), kv.second.end());
        plans.push_back(GraphPlan{mode, n, kv.first, kv.second});
      }
    }
  }
  return plans;
}

/// A true candidate: the true relative pose with PnP-like noise. A false one: the query seen
/// at a look-alike place `offset` metres away along x (the track), y (lateral) or z (a floor).
core::LoopCandidate makeCandidate(const Options& o, const sim::SimKeyframe& query,
                                  const sim::SimKeyframe& match, sim::Gaussian& g, bool is_true,
                                  double* offset) {
  core::Pose rel = sim::relative(match.truth, query.truth);
  *offset = 0.0;
  if (!is_true) {
    *offset = o.false_offset_min + (o.false_offset_max - o.false_offset_min) * g.uniform();
    const int axis = std::min(2, static_cast<int>(3 * g.uniform()));
    rel.t[axis] += g.uniform() < 0.5 ? -*offset : *offset;
  }
  rel.t += Eigen::Vector3d(g(o.candidate_sigma_t), g(o.candidate_sigma_t), g(o.candidate_sigma_t));
  rel.q = (core::yawRotation(g(o.candidate_sigma_yaw)) * rel.q).normalized();
  return sim::loopCandidate(query, match, rel);
}

/// Went through the whole test: the trial solve (metric decision) or the chi-square test,
/// not stopped by the innovation gate, held, or refused as invalid.
bool tested(core::Reason r) {
  return r == core::Reason::kAccepted || r == core::Reason::kScoreAboveThreshold ||
         r == core::Reason::kNotConverged || r == core::Reason::kTimeBudgetExceeded ||
         r == core::Reason::kInconsistentWithDrift || r == core::Reason::kLookalikeCloser;
}

const char* kHeader =
    "dof keyframes  span  window cand tested gated T_acc/T F_acc/F  tbe over iters   p50[ms]   p99[ms]   max[ms] "
    "lf_full[ms] full/p50 full/p99 rss_verif[MB] rss_peak[MB]\n";
const char* kCsvHeader =
    "dof,keyframes,span,lap,window,candidates,true_candidates,false_candidates,tested,gated,deferred,invalid,"
    "true_accepted,false_accepted,time_budget_exceeded,over_budget,iterations,iterations_max,verify_median_ms,"
    "verify_p90_ms,verify_p99_ms,verify_max_ms,loop_fusion_full_ms,loop_fusion_iterations,"
    "ratio_full_over_verify,ratio_full_over_verify_p99,time_budget_ms,build_commits_cut,verifier_rss_mb,"
    "peak_rss_mb\n";
const char* kVerdictsHeader =
    "dof,keyframes,span,lap,query_index,match_index,is_true,offset_m,accepted,reason,score,threshold,"
    "innovation,path_length,iterations,window,solve_ms,verify_ms\n";

/// The laps scene of a graph plan: odometry only (the candidates are made as it is measured).
sim::Scene graphScene(const Options& o, const GraphPlan& p) {
  sim::LapsOptions lo;
  lo.step = 0.5;
  const double perimeter = p.lap * lo.step;
  lo.width = perimeter / 3.0;
  lo.height = perimeter / 6.0;
  lo.laps = (p.keyframes + p.lap - 1) / p.lap;
  lo.sigma_t = o.sigma_t;
  lo.sigma_yaw = o.sigma_yaw;
  lo.true_every = 0;
  lo.false_every = 0;
  lo.seed = o.seed;
  sim::Scene s = sim::makeLapsScene(lo);
  s.keyframes.resize(std::min<size_t>(s.keyframes.size(), p.keyframes));
  return s;
}

/// What one graph's verifier measured.
struct GraphRun {
  std::vector<core::LoopCandidate> committed;  // the graph's own loops, as built
  std::vector<Measured> results;
  int commits_cut = 0;  // refused, or the estimate's update stopped by the budget (under load)
  double verifier_rss = 0;
  std::vector<double> commit_ms;  // the graph's own loops' commits
  double last_commit_ms = -1;     // after the measurements: the longest span's last true candidate
};

/// Builds the graph in a verifier (a true loop every lap / 10 keyframes) and verifies a true and
/// a false candidate per span at each of the last o.queries keyframes; false if a keyframe is refused.
bool measureGraph(const Options& o, const GraphPlan& p, const sim::Scene& s, const core::VerifierConfig& cfg,
                  GraphRun* run) {
  const int n = static_cast<int>(s.keyframes.size());
  const int measure_from = n - o.queries;
  sim::Gaussian g(o.seed + 1000u * static_cast<uint32_t>(p.lap));
  const int loop_every = std::max(5, p.lap / 10);
  core::LoopCandidate last_true;  // query_index -1: none
  core::Verifier v(cfg);
  for (int k = 0; k < n; ++k) {
    const sim::SimKeyframe& kf = s.keyframes[k];
    const core::Status added = v.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q);
    if (!added) {
      std::fprintf(stderr, "keyframe %d refused: %s\n", k, added.message.c_str());
      return false;
    }
    double offset;
    if (k < measure_from) {
      if (k >= p.lap && k % loop_every == 0) {
        const core::LoopCandidate c = makeCandidate(o, kf, s.keyframes[k - p.lap], g, true, &offset);
        const auto t0 = Clock::now();
        const core::Status st = v.commit(c);
        run->commit_ms.push_back(msSince(t0));
        if (!st || st.warning()) ++run->commits_cut;
        if (st) run->committed.push_back(c);
      }
      continue;
    }
    for (int span : p.spans) {
      for (bool is_true : {true, false}) {
        const core::LoopCandidate c = makeCandidate(o, kf, s.keyframes[k - span], g, is_true, &offset);
        const auto t0 = Clock::now();
        const core::Verdict vd = v.verify(c);
        const double ms = msSince(t0);
        run->results.push_back(Measured{span, is_true, offset, vd, ms});
        if (is_true && span == p.spans.back()) last_true = c;
      }
    }
  }
  run->verifier_rss = peakRssMb();
  // What a commit costs when a loop ties the newest keyframe to the run's start (the update
  // of the estimate every decision rule keeps; chi2's re-places the keyframes of every chain
  // whose ends moved): measured once, after everything else.
  if (last_true.query_index >= 0) {
    const auto t0 = Clock::now();
    if (v.commit(last_true)) run->last_commit_ms = msSince(t0);
  }
  return true;
}

/// loop_fusion's stand-in: the same keyframes and loops, plus the last true candidate of the
/// longest span (loop_fusion optimises after accepting a loop); the median of o.full_repeats
/// solves [ms] and the iterations of the last.
std::pair<double, int> loopFusionFull(const Options& o, const GraphPlan& p, const sim::Scene& s,
                                      const core::VerifierConfig& cfg, const GraphRun& run) {
  core::KeyframeGraph lf(cfg);
  for (const sim::SimKeyframe& kf : s.keyframes) lf.addKeyframe(kf.index, kf.stamp, 1, kf.vio.t, kf.vio.q);
  for (const core::LoopCandidate& c : run.committed) lf.addLoop(c);
  for (auto it = run.results.rbegin(); it != run.results.rend(); ++it) {
    if (it->is_true && it->span == p.spans.back()) {
      const sim::SimKeyframe& q = s.keyframes[it->verdict.query_index];
      const sim::SimKeyframe& m = s.keyframes[it->verdict.match_index];
      lf.addLoop(sim::loopCandidate(q, m, sim::relative(m.truth, q.truth)));
      break;
    }
  }
  std::vector<double> full_ms;
  int full_iterations = 0;
  for (int r = 0; r < o.full_repeats; ++r) {
    const auto t0 = Clock::now();
    const core::BatchSolveResult b = lf.solveLikeLoopFusion(5);
    full_ms.push_back(msSince(t0));
    full_iterations = b.iterations;
    if (!b.ok) std::fprintf(stderr, "loop_fusion's solve failed: %s\n", b.message.c_str());
  }
  return std::make_pair(percentile(full_ms, 50), full_iterations);
}

/// One span's figures.
struct SpanFigures {
  std::vector<double> ms, iters, windows;
  int cand = 0, t = 0, f = 0, n_tested = 0, gated = 0, deferred = 0, invalid = 0, t_acc = 0, f_acc = 0, tbe = 0;
  int over = 0, it_max = 0;

  void add(const Measured& m, double time_budget_ms) {
    const core::Verdict& vd = m.verdict;
    ++cand;
    ms.push_back(m.ms);
    (m.is_true ? t : f) += 1;
    if (vd.accepted) (m.is_true ? t_acc : f_acc) += 1;
    if (vd.reason == core::Reason::kTimeBudgetExceeded) ++tbe;
    if (time_budget_ms > 0 && m.ms > time_budget_ms) ++over;
    if (vd.reason == core::Reason::kInnovationAboveBound) ++gated;
    if (vd.reason == core::Reason::kInvalidInput) ++invalid;
    if (vd.reason == core::Reason::kDeferred) ++deferred;
    if (tested(vd.reason)) {
      ++n_tested;
      iters.push_back(vd.iterations);
      it_max = std::max(it_max, vd.iterations);
      if (vd.window_size > 0) windows.push_back(vd.window_size);
    }
  }
};

/// Prints and appends the rows of one graph (its spans' figures and, with --verdicts, every verdict).
void report(const Options& o, const GraphPlan& p, int n, const core::VerifierConfig& cfg, const GraphRun& run,
            double full, int full_iterations, double peak_rss) {
  FILE* csv = o.csv.empty() ? nullptr : std::fopen(o.csv.c_str(), "a");
  FILE* vcsv = o.verdicts.empty() ? nullptr : std::fopen(o.verdicts.c_str(), "a");
  for (int span : p.spans) {
    SpanFigures x;
    for (const Measured& m : run.results) {
      if (m.span != span) continue;
      x.add(m, cfg.trial.time_budget_ms);
      const core::Verdict& vd = m.verdict;
      if (vcsv)
        std::fprintf(vcsv, "%d,%d,%d,%d,%lld,%lld,%d,%.3f,%d,%s,%.6f,%.6f,%.6f,%.3f,%d,%d,%.4f,%.4f\n",
                     dofOf(p.mode), n, span, p.lap, static_cast<long long>(vd.query_index),
                     static_cast<long long>(vd.match_index), m.is_true ? 1 : 0, m.offset, vd.accepted ? 1 : 0,
                     core::toString(vd.reason), vd.score, vd.threshold, vd.innovation, vd.path_length,
                     vd.iterations, vd.window_size, vd.solve_ms, m.ms);
    }
    const double p50 = percentile(x.ms, 50), p90 = percentile(x.ms, 90), p99 = percentile(x.ms, 99),
                 mx = percentile(x.ms, 100);
    const int window = x.windows.empty() ? 0 : static_cast<int>(percentile(x.windows, 50));
    const int it_med = x.iters.empty() ? 0 : static_cast<int>(percentile(x.iters, 50));
    std::printf("%3d %9d %5d %7d %4d %6d %5d %3d/%-3d %3d/%-3d %4d %4d %5d %9.3f %9.3f %9.3f %11.1f %8.1f %8.1f %13.1f %12.1f\n",
                dofOf(p.mode), n, span, window, x.cand, x.n_tested, x.gated, x.t_acc, x.t, x.f_acc, x.f, x.tbe, x.over,
                it_med, p50, p99, mx, full, full / p50, full / p99, run.verifier_rss, peak_rss);
    if (csv)
      std::fprintf(csv, "%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%.4f,%.4f,%.4f,%.4f,%.4f,%d,%.3f,%.3f,%.1f,%d,%.1f,%.1f\n",
                   dofOf(p.mode), n, span, p.lap, window, x.cand, x.t, x.f, x.n_tested, x.gated, x.deferred, x.invalid,
                   x.t_acc, x.f_acc, x.tbe, x.over, it_med, x.it_max, p50, p90, p99, mx, full, full_iterations,
                   full / p50, full / p99, cfg.trial.time_budget_ms, run.commits_cut, run.verifier_rss, peak_rss);
  }
  if (!run.commit_ms.empty()) {
    char last[64] = "refused";
    if (run.last_commit_ms >= 0) std::snprintf(last, sizeof(last), "%.3f ms", run.last_commit_ms);
    std::printf("    commits while building the graph: %zu, p50 %.3f ms, p99 %.3f ms, max %.3f ms; the last true "
                "candidate of span %d committed after the measurements: %s\n",
                run.commit_ms.size(), percentile(run.commit_ms, 50), percentile(run.commit_ms, 99),
                percentile(run.commit_ms, 100), p.spans.back(), last);
  }
  std::fflush(stdout);
  if (csv) std::fclose(csv);
  if (vcsv) std::fclose(vcsv);
}

/// Builds one graph, measures its spans, and appends its rows (runs in a child process).
int runGraph(const Options& o, const GraphPlan& p) {
  const sim::Scene s = graphScene(o, p);
  const int n = static_cast<int>(s.keyframes.size());
  core::VerifierConfig cfg = o.config;
  cfg.mode = p.mode;
  GraphRun run;
  if (!measureGraph(o, p, s, cfg, &run)) return 1;
  if (run.commits_cut > 0)
    std::fprintf(stderr, "note: %d-DoF %d keyframes, lap %d: %d of the graph's loop commits were refused or their "
                 "update of the estimate was cut by the time budget\n", dofOf(p.mode), n, p.lap, run.commits_cut);
  const std::pair<double, int> full = loopFusionFull(o, p, s, cfg, run);
  report(o, p, n, cfg, run, full.first, full.second, peakRssMb());
  return 0;
}

int usage() {
  std::fprintf(stderr,
               "usage: rover_benchmark_cost [--quick] [--sizes A,B] [--spans 10,100,whole] [--modes 4dof,6dof]\n"
               "         [--queries N] [--config FILE] [--set NAME=VALUE] [--time-budget-ms MS] [--full-repeats N]\n"
               "         [--lap-max N] [--seed N]\n"
               "         [--csv FILE] [--verdicts FILE]   (older names: --mode, --repeats)\n");
  return 2;
}

/// Parses the command line into *o; returns -1 to run, or the exit status.
int parseArguments(int argc, char** argv, Options* o_out) {
  Options& o = *o_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--quick") {
      o.sizes = {1000, 2000};
      o.spans = {"10", "100", "whole"};
      o.queries = 5;
      o.full_repeats = 1;
      continue;
    }
    if (a == "--help" || a == "-h") return usage();
    if (i + 1 >= argc) return usage();
    const std::string v = argv[++i];
    bool ok = true;
    if (a == "--sizes") {
      o.sizes.clear();
      for (const std::string& s : split(v)) {
        int n = 0;
        ok = ok && parsePositive(s, &n);
        o.sizes.push_back(n);
      }
      ok = ok && !o.sizes.empty();
    } else if (a == "--spans") {
      o.spans = split(v);
      for (const std::string& s : o.spans) {
        int n = 0;
        ok = ok && (s == "whole" || parsePositive(s, &n));
      }
      ok = ok && !o.spans.empty();
    } else if (a == "--modes" || a == "--mode") {
      o.modes.clear();
      for (const std::string& s : split(v)) {
        core::Mode m;
        ok = ok && core::parseMode(s, &m);
        o.modes.push_back(m);
      }
      ok = ok && !o.modes.empty();
    } else if (a == "--queries" || a == "--repeats") {
      ok = parsePositive(v, &o.queries);
    } else if (a == "--full-repeats") {
      ok = parsePositive(v, &o.full_repeats);
    } else if (a == "--lap-max") {
      ok = parsePositive(v, &o.lap_max);
    } else if (a == "--seed") {
      int seed = 0;
      ok = parsePositive(v, &seed);
      o.seed = static_cast<uint32_t>(seed);
    } else if (a == "--config" || a == "--set" || a == "--time-budget-ms") {
      // A verifier parameter file (as rover_replay --config), one NAME=VALUE, or the budget.
      std::string error;
      if (a == "--config") {
        ok = core::readParameterFile(v, &o.config, &error);
      } else {
        const std::string assignment = a == "--set" ? v : "time_budget_ms=" + v;
        const size_t eq = assignment.find('=');
        const core::Parameter* row = eq == std::string::npos ? nullptr : core::findParameter(assignment.substr(0, eq));
        ok = row && core::assignParameter(*row, core::ParameterValue::parse(assignment.substr(eq + 1)), &o.config,
                                          &error);
        if (!row) error = "not NAME=VALUE with a verifier parameter's name";
      }
      if (!ok) {
        std::fprintf(stderr, "%s %s: %s\n", a.c_str(), v.c_str(), error.c_str());
        return 2;
      }
    } else if (a == "--csv") {
      o.csv = v;
    } else if (a == "--verdicts") {
      o.verdicts = v;
    } else {
      std::fprintf(stderr, "unknown option %s\n", a.c_str());
      return usage();
    }
    if (!ok) {
      std::fprintf(stderr, "bad value for %s: %s\n", a.c_str(), v.c_str());
      return usage();
    }
  }
  return -1;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  const int parsed = parseArguments(argc, argv, &o);
  if (parsed >= 0) return parsed;
  const std::string bad = o.config.validate();
  if (!bad.empty()) {
    std::fprintf(stderr, "%s\n", bad.c_str());
    return 2;
  }
  for (const std::pair<std::string, const char*>& f :
       {std::make_pair(o.csv, kCsvHeader), std::make_pair(o.verdicts, kVerdictsHeader)}) {
    if (f.first.empty()) continue;
    FILE* h = std::fopen(f.first.c_str(), "w");
    if (!h) {
      std::fprintf(stderr, "cannot write %s\n", f.first.c_str());
      return 1;
    }
    std::fputs(f.second, h);
    std::fclose(h);
  }
  std::printf("verification cost on realistic candidates, one process per graph; verifier: %s\n",
              core::describe(o.config).c_str());
  std::fputs(kHeader, stdout);
  std::fflush(stdout);
  int status = 0;
  for (const GraphPlan& p : plan(o)) {
    std::fflush(stdout);
    std::fflush(stderr);
    const pid_t pid = fork();
    if (pid < 0) {
      std::perror("fork");
      return 1;
    }
    if (pid == 0) {
      const int rc = runGraph(o, p);
      std::fflush(stdout);
      std::fflush(stderr);
      _exit(rc);
    }
    int ws = 0;
    if (waitpid(pid, &ws, 0) < 0 || !WIFEXITED(ws) || WEXITSTATUS(ws) != 0) {
      std::fprintf(stderr, "graph %d-DoF, %d keyframes, lap %d failed (status %d)\n", dofOf(p.mode), p.keyframes,
                   p.lap, ws);
      status = 1;
    }
  }
  return status;
}
