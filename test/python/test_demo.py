"""The README's main command: launch/demo.launch replays the shipped bag into the ROVER and
accept-all verifier nodes, prints the summary and ends by itself (scripts/demo.sh runs the
same launch file after the set-up)."""
import os
import re
import socket
import subprocess


def free_port():
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]


def test_demo_prints_the_summary_and_ends():
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://localhost:{port}")
    out = subprocess.run(["roslaunch", "-p", str(port), "rover_loop_fusion", "demo.launch", "verbose:=false"],
                         env=env, capture_output=True, text=True, timeout=600)
    text = out.stdout + out.stderr
    assert out.returncode == 0, text[-3000:]
    assert "[replay] FAILED" not in text, text[-3000:]
    assert "360 keyframe poses, 80 loop candidates replayed" in text, text[-3000:]
    m = re.search(r"summary: 80 candidates \(40 true, 40 false\): accepted (\d+), rejected (\d+)", text)
    assert m, text[-3000:]
    assert "false positives 0, true negatives 40" in text  # every false loop rejected
    ate = re.search(r"ATE \[m\]: odometry ([\d.]+) \| accept-all \(loop_fusion\) ([\d.]+) \| "
                    r"verified \(loop_fusion\) ([\d.]+)", text)
    assert ate, text[-3000:]
    odometry, accept_all, verified = (float(x) for x in ate.groups())
    assert verified < accept_all < odometry
    assert "accept-all: accepted 80 of 80 (false positives 40" in text
