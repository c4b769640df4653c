#!/usr/bin/env python3
"""Sequential verification at several thresholds over the simulated scenes and EuRoC: what a
user gets from each fixed threshold (or threshold_per_metre) in the product's own mode
(every candidate verified when it arrives, accepted ones committed).

  threshold_sweep.py [--thresholds 0.1,0.15,0.2,0.3,0.5] [--per-metre 0]
                     [--sigmas 0.05,0.1,0.175] [--quick] [--out results/threshold_sweep]

Prints one line per threshold (TP, FP, FN summed over all scenarios, and the scenarios with
false positives or more than 30 % missed true loops) and writes results.csv. Run with
/usr/bin/python3 after the package is built (scripts/test.sh or scripts/demo.sh)."""
import argparse
import csv
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

HERE = os.path.dirname(os.path.abspath(__file__))

from roverlib import real_data, scenario, scenes  # noqa: E402

ROOT = os.path.dirname(HERE)
REPLAY = os.path.join(os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws")),
                      "devel", "lib", "rover_loop_fusion", "rover_replay")
SIM_SCENES = ("room", "sports_ground", "warehouse", "corridor", "parking_deck")
REAL = ("euroc_mh01", "euroc_mh03", "euroc_mh05", "euroc_mh04_mono0")


def make_scenarios(out, sigmas, quick):
    dirs = []
    names = SIM_SCENES[:3] if quick else SIM_SCENES
    for name in names:
        for sigma in sigmas:
            d = os.path.join(out, "scenarios", f"{name}_s{sigma:g}")
            if not os.path.exists(os.path.join(d, "candidates.csv")):
                scenario.write(scenes.make_scene(name, sigma, seed=0), d)
            dirs.append(d)
    for name in REAL[:1] if quick else REAL:
        d = os.path.join(out, "scenarios", name)
        if not os.path.exists(os.path.join(d, "candidates.csv")):
            scenario.write(real_data.make_real(name, seed=0), d)
        dirs.append(d)
    return dirs


def replay(scn, out, threshold, per_metre):
    res = subprocess.run([REPLAY, "--scenario", scn, "--out", out, "--protocol", "sequential",
                          "--threshold", str(threshold), "--threshold_per_metre", str(per_metre),
                          "--quiet"], capture_output=True, text=True, check=True)
    for line in res.stdout.splitlines():
        if " TP " in line:
            f = line.split()
            return int(f[2]), int(f[4]), int(f[6]), int(f[8])
    return 0, 0, 0, 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--thresholds", default="0.1,0.15,0.2,0.3,0.5")
    ap.add_argument("--per-metre", type=float, default=0.0)
    ap.add_argument("--sigmas", default="0.05,0.1,0.175")
    ap.add_argument("--quick", action="store_true", help="3 scenes, 1 EuRoC run (for CI)")
    ap.add_argument("--out", default=os.path.join(ROOT, "results", "threshold_sweep"))
    a = ap.parse_args(argv)
    if not os.path.exists(REPLAY):
        sys.exit(f"{REPLAY} not found: build first (scripts/test.sh)")
    sigmas = [float(s) for s in a.sigmas.split(",")]
    thresholds = [float(t) for t in a.thresholds.split(",")]
    dirs = make_scenarios(a.out, sigmas, a.quick)
    rows = []
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        for th in thresholds:
            jobs = {d: pool.submit(replay, d, os.path.join(a.out, "runs", f"{os.path.basename(d)}_t{th:g}"),
                                   th, a.per_metre) for d in dirs}
            tp = fp = fn = 0
            notes = []
            for d, job in jobs.items():
                t, f, tn, n = job.result()
                rows.append({"scenario": os.path.basename(d), "threshold": th, "per_metre": a.per_metre,
                             "tp": t, "fp": f, "tn": tn, "fn": n})
                tp, fp, fn = tp + t, fp + f, fn + n
                if f:
                    notes.append(f"{os.path.basename(d)}:FP{f}")
                if t + n and n > 0.3 * (t + n):
                    notes.append(f"{os.path.basename(d)}:FN{n}/{t + n}")
            precision = tp / (tp + fp) if tp + fp else 1.0
            recall = tp / (tp + fn) if tp + fn else 0.0
            print(f"threshold {th:5.2f} (+{a.per_metre:g}/m): TP {tp:5d} FP {fp:5d} FN {fn:5d}  "
                  f"precision {precision:.3f} recall {recall:.3f}  | {' '.join(notes) or '-'}", flush=True)
    os.makedirs(a.out, exist_ok=True)
    with open(os.path.join(a.out, "results.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {os.path.join(a.out, 'results.csv')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
