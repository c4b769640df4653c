#!/usr/bin/env python3
"""Long replay: a simulated run of many keyframes played fast through rover_verifier_node.
Reports whether every candidate got a verdict (none dropped), the node's memory over the run
and the distribution of verification latency. A benchmark, not a test: it prints figures and
writes results/long_replay/ (summary.txt, rss.csv, verdicts.csv).

  scripts/bench/long_replay.py [--keyframes 20000] [--true 500] [--false 500] [--rate 200]
                       [--sigma 0.03] [--seed 3] [--optimize-period 0] [--out results/long_replay]
                       [--config config/rover_template.yaml --config config/rover_indoor.yaml]
                       [--set decision=chi2 ...]

The scene is the corridor loop (120 keyframes a lap, odometry noise --sigma: 0.03 is a good
VIO, whose first loop is accepted; at 0.05 some seeds lose it, docs/method.md) driven
until --keyframes; candidates are
verified as loop_fusion would produce them (the earliest matching keyframe), so their span
grows with the run. The bag is played with `rosbag play -r RATE` (keyframes every 0.5 s in
bag time: -r 200 is 400 keyframes a second), faster than the node verifies, so the node's
queues and the candidate bookkeeping are exercised too. Needs the package built and sourced
(scripts/demo.sh or scripts/test.sh do that); runs its own roscore on a free port."""
import argparse
import csv
import os
import signal
import socket
import subprocess
import sys
import time

import yaml

from roverlib import bag as rbag
from roverlib import bench, scenario, scenes


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mb(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def count_final_rows(path):
    """Candidates decided so far: verdict rows that are final (a held candidate's deferred row,
    final=0, is not; nor is a line still being written)."""
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            if not reader.fieldnames or "final" not in reader.fieldnames:
                return sum(1 for _ in reader)
            return sum(1 for r in reader if r.get("final") == "1")
    except OSError:
        return 0


def percentile(values, q):
    if not values:
        return float("nan")
    v = sorted(values)
    return v[min(len(v) - 1, int(q * len(v)))]


def add_scene_args(ap, rate, rate_help="rosbag play -r"):
    """The long corridor scene's options (this benchmark's and fault_replay's)."""
    ap.add_argument("--keyframes", type=int, default=20000)
    ap.add_argument("--true", dest="n_true", type=int, default=500)
    ap.add_argument("--false", dest="n_false", type=int, default=500)
    ap.add_argument("--rate", type=float, default=rate, help=rate_help)
    ap.add_argument("--sigma", type=float, default=0.03, help="odometry noise level")
    ap.add_argument("--seed", type=int, default=3)


def corridor_scene(a):
    """The corridor driven until a.keyframes, with its candidates up to there."""
    laps = (a.keyframes + 119) // 120
    s = scenes.make_scene("corridor", a.sigma, seed=a.seed, n_true=a.n_true, n_false=a.n_false, laps=laps)
    s.keyframes = s.keyframes[:a.keyframes]
    s.truth = s.truth[:a.keyframes]
    s.candidates = [c for c in s.candidates if c.query < a.keyframes]
    return s


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_args(ap, 200.0)
    ap.add_argument("--optimize-period", type=float, default=0.0,
                    help="node's loop_fusion-like optimisation period [s]; 0: only at the end")
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "long_replay"))
    ap.add_argument("--config", action="append", metavar="FILE",
                    help="verifier YAML loaded into the node's verifier namespace, in order; repeatable "
                         "(default: config/rover_template.yaml then config/rover_indoor.yaml)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="a verifier parameter set after --config (e.g. decision=chi2); repeatable")
    a = ap.parse_args(argv)
    a.config = a.config or bench.config_paths("indoor")
    for o in a.overrides:
        if "=" not in o:
            ap.error(f"--set {o}: expected KEY=VALUE")
    os.makedirs(a.out, exist_ok=True)
    scn_dir = os.path.join(a.out, "scenario")
    log = os.path.join(a.out, "verdicts.csv")
    if os.path.exists(log):
        os.remove(log)

    t0 = time.time()
    s = corridor_scene(a)
    scenario.write(s, scn_dir)
    bag_path = os.path.join(scn_dir, "scenario.bag")
    rbag.write_bag(s, bag_path)
    n_cand = len(s.candidates)
    print(f"scenario: {len(s.keyframes)} keyframes, {n_cand} candidates "
          f"({sum(c.label == 1 for c in s.candidates)} true), bag {os.path.getsize(bag_path) / 1e6:.1f} MB, "
          f"made in {time.time() - t0:.0f} s", flush=True)

    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{free_port()}")
    port = env["ROS_MASTER_URI"].rsplit(":", 1)[1]
    procs = []
    try:
        core = subprocess.Popen(["roscore", "-p", port], env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True)
        procs.append(core)
        time.sleep(3)
        for path in a.config:
            subprocess.run(["rosparam", "load", path, "/rover_verifier/rover"], env=env, check=True)
        for o in a.overrides:
            key, value = o.split("=", 1)
            subprocess.run(["rosparam", "set", f"/rover_verifier/rover/{key}", value], env=env, check=True)
        node = subprocess.Popen(
            ["rosrun", "rover_loop_fusion", "rover_verifier_node", "__name:=rover_verifier",
             f"_verdict_log:={log}", f"_optimize_period:={a.optimize_period}", "_publish_markers:=false"],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
        procs.append(node)
        time.sleep(3)
        # rosrun execs the node: its PID is the process's own.
        start = time.time()
        play = subprocess.Popen(["rosbag", "play", "-q", "--wait-for-subscribers", "--queue=100000",
                                 "-r", str(a.rate), bag_path], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        procs.append(play)
        rss_rows = []
        play_end = None
        last_count, last_change = 0, time.time()
        while True:
            now = time.time()
            done = count_final_rows(log)
            rss_rows.append((now - start, done, rss_mb(node.pid)))
            if play_end is None and play.poll() is not None:
                play_end = now - start
            if done != last_count:
                last_count, last_change = done, now
            if done >= n_cand or node.poll() is not None:
                break
            if play_end is not None and now - last_change > 120:
                break  # nothing new for 2 minutes after the bag ended
            time.sleep(0.5)
        wall = time.time() - start
        alive = node.poll() is None
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in reversed(procs):
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)

    rows = list(csv.DictReader(open(log))) if os.path.exists(log) else []
    rows = [r for r in rows if r.get("final", "1") != "0"]  # a held candidate's deferred verdict
    lat = [float(r["elapsed_ms"]) for r in rows]
    reasons = {}
    for r in rows:
        reasons[r["reason"]] = reasons.get(r["reason"], 0) + 1
    stamps = {k.index: k.stamp for k in s.keyframes}
    by_stamp = {(round(stamps[c.query], 3), round(stamps[c.match], 3)): c.label for c in s.candidates}
    label_of = [by_stamp.get((round(float(r["query_stamp"]), 3), round(float(r["match_stamp"]), 3))) for r in rows]
    fp = sum(1 for r, lab in zip(rows, label_of) if r["accepted"] == "1" and lab == 0)
    tp = sum(1 for r, lab in zip(rows, label_of) if r["accepted"] == "1" and lab == 1)
    by_label = {1: {}, 0: {}}
    for r, lab in zip(rows, label_of):
        if lab in by_label:
            by_label[lab][r["reason"]] = by_label[lab].get(r["reason"], 0) + 1
    # The verifier's time budget (the YAML's, or a --set): verifications that took longer.
    budget_ms = 0.0
    for path in a.config:  # later files win, as in the node's namespace
        with open(path) as f:
            budget_ms = float((yaml.safe_load(f) or {}).get("time_budget_ms", budget_ms))
    for o in a.overrides:
        key, value = o.split("=", 1)
        if key == "time_budget_ms":
            budget_ms = float(value)
    over = sum(1 for v in lat if budget_ms > 0 and v > budget_ms)
    rss = [r[2] for r in rss_rows if r[2] == r[2]]
    with open(os.path.join(a.out, "rss.csv"), "w") as f:
        f.write("seconds,verdicts,rss_mb\n")
        for r in rss_rows:
            f.write(f"{r[0]:.1f},{r[1]},{r[2]:.1f}\n")
    # RSS when the first and the last quarter of verdicts were done: growth per keyframe played.
    quarter = [r for r in rss_rows if r[1] >= n_cand // 4]
    lines = [
        f"long replay: corridor sigma {a.sigma:g} seed {a.seed}, {len(s.keyframes)} keyframes, {n_cand} candidates, rosbag play -r {a.rate:g} "
        f"(bag {len(s.keyframes) * 0.5 / a.rate:.0f} s), node optimize_period {a.optimize_period:g} s",
        f"  verifier: {' + '.join(os.path.relpath(p, bench.ROOT) for p in a.config)}" + "".join(f", {o}" for o in a.overrides),
        f"  verdicts: {len(rows)} of {n_cand} candidates ({n_cand - len(rows)} dropped); node "
        f"{'still running' if alive else 'EXITED'} after {wall:.0f} s",
        "  reasons: " + ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())),
        f"  accepted: {tp} true, {fp} false (labels)",
        *(f"  {name} candidates: " + ", ".join(f"{k} {v}" for k, v in sorted(by_label[lab].items()))
          for name, lab in (("true", 1), ("false", 0))),
        f"  verification latency [ms]: p50 {percentile(lat, .5):.2f}  p90 {percentile(lat, .9):.2f}  "
        f"p99 {percentile(lat, .99):.2f}  max {max(lat) if lat else float('nan'):.2f}; "
        f"over the {budget_ms:g} ms budget: {over}",
        f"  node RSS [MB]: start {rss[0] if rss else float('nan'):.1f}, after a quarter of the verdicts "
        f"{quarter[0][2] if quarter else float('nan'):.1f}, peak {max(rss) if rss else float('nan'):.1f}, "
        f"end {rss[-1] if rss else float('nan'):.1f}",
    ]
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(a.out, "summary.txt"), "w") as f:
        f.write(text + "\n")
    print(f"wrote {a.out}/summary.txt, rss.csv, verdicts.csv")
    return 0 if len(rows) == n_cand and alive else 1


if __name__ == "__main__":
    sys.exit(main())
