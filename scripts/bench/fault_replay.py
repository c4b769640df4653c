#!/usr/bin/env python3
"""Fault-injection replay: a long simulated run played through rover_verifier_node twice, clean
and with faults injected, side by side. A benchmark, not a test: it prints figures and writes
results/fault_replay/ (summary.txt, clean/ and faulty/ verdict logs and node output).

  scripts/bench/fault_replay.py [--keyframes 20000] [--true 500] [--false 500] [--rate 40]
                                [--sigma 0.03] [--seed 3] [--out results/fault_replay]

The faulty run has, at eighths of the run (roverlib.faults):
  - one keyframe stamped 1000 s late;
  - two keyframes in a row stamped 1000 s late;
  - a stretch of 50 keyframes whose clock stands still (every stamp the first one's);
  - a second such stretch with one keyframe in it stamped 1000 s late (a stop with a glitch);
  - one keyframe never sent;
  - a repeated burst: 300 keyframes and their candidates published at once, each of those
    candidates sent 3 times, with the node's queue_size at 10 (raised to the node's minimum,
    1000, with a warning);
  - a full-disk episode: the verdict log on a small tmpfs that a filler file fills while 10 %
    of the candidates are decided, then frees (needs root to mount the tmpfs; skipped with
    the reason otherwise).
Candidates name their keyframes by stamp, as loop_fusion's are recorded; those that name a
keyframe of the stopped stretch by stamp are invalid (a stamp several keyframes carry names
none). Reported per run: verdicts received on ~loop_verdicts (one final per candidate?), true
and false loops accepted, recall; for the log: rows, whole rows, header, rows the node counted
lost. Both runs also go through rover_replay (the scenario as sent). True and false loops are
counted by candidate pair. The figure to read: the faulty run's recall beside the clean run's,
in both hosts; the exit status is 1 unless every candidate got one final verdict, the log is
whole and the faulty recall is within 0.02 of the clean one in both hosts.

Needs the package built and sourced (scripts/test.sh or scripts/demo.sh do that); runs its own
roscore on a free port."""
import argparse
import collections
import csv
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

from roverlib import bag as rbag
from roverlib import bench, faults, programs

REPEATS = 3  # copies of each candidate of the repeated burst

long_replay = programs.load("bench/long_replay.py")  # the corridor scene and a free port, as long_replay has them
add_scene_args, corridor_scene, free_port = long_replay.add_scene_args, long_replay.corridor_scene, long_replay.free_port


def make_runs(a):
    s = corridor_scene(a)
    n = len(s.keyframes)
    e = n // 8
    clean = faults.inject_all(s, "clean", [])
    faulty = faults.inject_all(s, "faulty", [
        faults.late(e, 1000.0),
        faults.late(2 * e, 1000.0), faults.late(2 * e + 1, 1000.0),
        faults.frozen_stretch(3 * e, 50),
        faults.frozen_stretch(4 * e, 50), faults.late(4 * e + 25, 1000.0),
        faults.deleted(5 * e),
        faults.burst(6 * e, 300),
    ], repeats=(6 * e, 6 * e + 300, REPEATS))
    what = (f"keyframe {e} stamped 1000 s late; keyframes {2 * e} and {2 * e + 1} stamped 1000 s late; "
            f"keyframes {3 * e}..{3 * e + 49} with one stamp; keyframes {4 * e}..{4 * e + 49} with one stamp and "
            f"keyframe {4 * e + 25} among them stamped 1000 s late; keyframe {5 * e} never sent; keyframes "
            f"{6 * e}..{6 * e + 299} and their candidates at once, each of those candidates sent {REPEATS} times")
    return s, clean, faulty, what


def figures(run, finals, n_cand, labels):
    """Recall and false loops by candidate pair: copies of one candidate count once."""
    accepted = {(q, m) for q, m, ok in finals if ok}
    true_pairs = {k for k, lab in labels.items() if lab == 1}
    tp = len(accepted & true_pairs)
    fp = sum(1 for k in accepted if labels.get(k) == 0)
    return dict(run=run, verdicts=len(finals), candidates=n_cand, tp=tp, fp=fp, n_true=len(true_pairs),
                recall=tp / len(true_pairs) if true_pairs else float("nan"))


def run_replay(run, f, out_dir):
    """rover_replay on the run's scenario (keyframes.csv as sent); a dict of figures."""
    scen = os.path.join(out_dir, "scenario")
    faults.write(f, scen)
    t0 = time.time()
    bench.replay(scen, os.path.join(out_dir, "replay"))
    with open(os.path.join(out_dir, "replay", "verdicts.csv"), newline="") as fh:
        rows = list(csv.DictReader(fh))
    labels = {(c.query, c.match): c.label for c in f.scenario.candidates}
    r = figures(run, [(int(x["query_index"]), int(x["match_index"]), x["accepted"] == "1") for x in rows],
                len(f.scenario.candidates), labels)
    r["wall"] = time.time() - t0
    r["reasons"] = collections.Counter(x["reason"] for x in rows)
    return r


class DiskEpisode:
    """A tmpfs for the verdict log that a filler file fills between two verdict counts."""

    def __init__(self, size_kb):
        self.dir = tempfile.mkdtemp(prefix="rover_fault_disk_")
        self.mounted = False
        self.why_not = ""
        if os.geteuid() != 0:
            self.why_not = "not root: no tmpfs can be mounted (the full-disk episode is left out)"
            return
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", self.dir],
                           capture_output=True, text=True)
        if r.returncode != 0:
            self.why_not = "mount tmpfs failed: " + r.stderr.strip()
            return
        self.mounted = True
        self.filler = os.path.join(self.dir, "filler")
        self.state = "before"

    def step(self, done, start, end):
        """Fill the disk when `done` reaches start, free it when it reaches end."""
        if not self.mounted:
            return
        if self.state == "before" and done >= start:
            fd = os.open(self.filler, os.O_WRONLY | os.O_CREAT, 0o600)
            try:
                while os.write(fd, b"\0" * 4096) > 0:
                    pass
            except OSError:  # full
                pass
            finally:
                os.close(fd)
            self.state = "full"
        elif self.state == "full" and done >= end:
            os.remove(self.filler)
            self.state = "freed"

    def close(self):
        if self.mounted:
            subprocess.run(["umount", self.dir], check=False)
        shutil.rmtree(self.dir, ignore_errors=True)


def read_log(path):
    """(rows, whole rows, header ok): a log row is whole when it has every column of the header."""
    if not os.path.exists(path):
        return 0, 0, False
    with open(path, newline="") as f:
        lines = f.read().splitlines()
    if not lines:
        return 0, 0, False
    header = next(csv.reader([lines[0]]))
    ok = header[:4] == ["query_stamp", "match_stamp", "query_index", "match_index"]
    rows = list(csv.reader(lines[1:]))
    whole = sum(1 for r in rows if len(r) == len(header))
    return len(rows), whole, ok


def run_node(a, run, name, messages, labels, n_cand, env, out_dir, queue_size, disk=None):
    """Plays `messages` into a fresh node; returns a dict of figures."""
    import rospy
    from roverlib import bag_replay
    os.makedirs(out_dir, exist_ok=True)
    bag_path = os.path.join(out_dir, "run.bag")
    rbag.write_messages(messages, bag_path)
    log = os.path.join(disk.dir if disk and disk.mounted else out_dir, "verdicts.csv")
    if os.path.exists(log):
        os.remove(log)
    node_out = open(os.path.join(out_dir, "node.txt"), "w")
    node = subprocess.Popen(
        ["rosrun", "rover_loop_fusion", "rover_verifier_node", f"__name:={name}", f"_verdict_log:={log}",
         "_optimize_period:=0", "_publish_markers:=false", f"_queue_size:={queue_size}"],
        env=env, stdout=node_out, stderr=subprocess.STDOUT, start_new_session=True)
    client = bag_replay.VerifierClient("/" + name)
    deadline = time.time() + 60
    while not client.connected() and time.time() < deadline:
        time.sleep(0.1)
    start = time.time()
    play = subprocess.Popen(["rosbag", "play", "-q", "--wait-for-subscribers", "--queue=100000", "-r", str(a.rate),
                             bag_path], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    last, last_change = -1, time.time()
    try:
        while True:
            with client._cond:
                done = len(client.verdicts) + sum(len(h) for h in client.pending.values())
            if disk:
                disk.step(done, int(0.45 * n_cand), int(0.55 * n_cand))
            if done != last:
                last, last_change = done, time.time()
            if done >= n_cand and play.poll() is not None:
                break
            if play.poll() is not None and time.time() - last_change > 60:
                break
            if rospy.is_shutdown():
                break
            time.sleep(0.2)
        wall = time.time() - start
    finally:
        for p in (play, node):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
        for p in (play, node):
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        node_out.close()
    rows, whole, header = read_log(log)
    if disk and disk.mounted:
        shutil.copy(log, os.path.join(out_dir, "verdicts.csv"))
    with client._cond:
        finals = list(client.verdicts)
        held = sum(len(h) for h in client.pending.values())
        n_msgs = len(client.messages)
    r = figures(run, [(v.query_index, v.match_index, v.accepted) for v in finals], n_cand, labels)
    text = open(os.path.join(out_dir, "node.txt")).read()
    lost = re.findall(r"(\d+) of (\d+) verdict rows were not written", text)
    reasons = collections.Counter(v.reason for v in finals)
    r.update(held=held, messages=n_msgs, wall=wall, rows=rows, whole=whole, header=header,
             lost=f"{lost[-1][0]} of {lost[-1][1]}" if lost else "none reported",
             reasons=reasons, raised="raised to" in text and "queue_size" in text)
    return r


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_scene_args(ap, 40.0, "rosbag play -r (keyframes every 0.5 s of bag time)")
    ap.add_argument("--disk-kb", type=int, default=4096, help="size of the tmpfs holding the faulty run's log")
    ap.add_argument("--out", default=os.path.join(bench.RESULTS, "fault_replay"))
    a = ap.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    t0 = time.time()
    s, clean, faulty, what = make_runs(a)
    print(f"scenario: corridor sigma {a.sigma:g} seed {a.seed}, {len(s.keyframes)} keyframes, "
          f"{len(s.candidates)} candidates ({sum(c.label == 1 for c in s.candidates)} true), made in "
          f"{time.time() - t0:.0f} s\nfaults: {what}", flush=True)

    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{free_port()}")
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    port = env["ROS_MASTER_URI"].rsplit(":", 1)[1]
    core = subprocess.Popen(["roscore", "-p", port], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    disk = DiskEpisode(a.disk_kb)
    results = []
    try:
        time.sleep(3)
        for path in bench.config_paths("indoor"):  # the template, then the override
            for ns in ("/rover_clean/rover", "/rover_faulty/rover"):
                subprocess.run(["rosparam", "load", path, ns], env=env, check=True)
        import rospy
        rospy.init_node("fault_replay", disable_signals=True)
        for run, f, name, queue, d in (("clean", clean, "rover_clean", 100000, None),
                                       ("faulty", faulty, "rover_faulty", 10, disk)):
            labels = {(c.query, c.match): c.label for c in f.scenario.candidates}
            r = run_node(a, run, name, f.messages, labels, len(f.scenario.candidates), env,
                         os.path.join(a.out, run), queue, d)
            results.append(r)
            print(f"{run}: {r['verdicts']} final verdicts (+{r['held']} held at the end) of {r['candidates']} "
                  f"candidates in {r['wall']:.0f} s", flush=True)
    finally:
        disk.close()
        os.killpg(core.pid, signal.SIGINT)
        core.wait(timeout=30)

    replays = []
    for run, fr in (("clean", clean), ("faulty", faulty)):
        r = run_replay(run, fr, os.path.join(a.out, run))
        replays.append(r)
        print(f"rover_replay {run}: {r['verdicts']} verdicts of {r['candidates']} candidates in {r['wall']:.0f} s",
              flush=True)

    c, f = results
    lines = [f"fault replay: corridor sigma {a.sigma:g} seed {a.seed}, {len(s.keyframes)} keyframes, "
             f"{len(s.candidates)} candidates, rosbag play -r {a.rate:g}, shipped indoor YAML",
             f"  faults: {what}; full disk: " +
             (f"the faulty run's log on a {a.disk_kb} kB tmpfs, filled while candidates 45 %..55 % were decided"
              if disk.mounted else disk.why_not),
             "  run     verdicts (final+held at the end/candidates)  true acc  false acc  recall   log rows (whole, header)  lost rows (node)"]
    for r in results:
        lines.append(f"  {r['run']:7s} {r['verdicts']:>6d}+{r['held']}/{r['candidates']:<6d}                  {r['tp']:>5d}/{r['n_true']:<5d}"
                     f"  {r['fp']:>5d}    {r['recall']:.3f}    {r['rows']} ({r['whole']} whole, header "
                     f"{'ok' if r['header'] else 'MISSING'})   {r['lost']}")
        lines.append("          reasons: " + ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items())))
    lines.append(f"  recall faulty - clean: {f['recall'] - c['recall']:+.3f}; queue_size 10 raised with a warning: "
                 f"{'yes' if f['raised'] else 'no'}")
    lines.append("  rover_replay on the same runs (keyframes.csv as sent; no burst, disk or queue there):")
    lines.append("  run     verdicts/candidates  true acc  false acc  recall")
    for r in replays:
        lines.append(f"  {r['run']:7s} {r['verdicts']:>6d}/{r['candidates']:<6d}        {r['tp']:>5d}/{r['n_true']:<5d}"
                     f"  {r['fp']:>5d}    {r['recall']:.3f}")
        lines.append("          reasons: " + ", ".join(f"{k} {v}" for k, v in sorted(r["reasons"].items())))
    rc, rf = replays
    lines.append(f"  recall faulty - clean: {rf['recall'] - rc['recall']:+.3f}")
    lines.append("  (true and false loops counted by candidate pair: the copies of a candidate count once)")
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(a.out, "summary.txt"), "w") as out:
        out.write(text + "\n")
    ok = all(r["verdicts"] + r["held"] == r["candidates"] and r["rows"] == r["whole"] and r["header"] for r in results)
    ok = ok and all(r["verdicts"] == r["candidates"] for r in replays)
    ok = ok and f["recall"] >= c["recall"] - 0.02 and rf["recall"] >= rc["recall"] - 0.02
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
