"""The Python that runs under ROS keeps to Python 3.8 (Ubuntu 20.04's, ROS Noetic's): the
roverlib package, the programs the package installs (catkin_install_python in CMakeLists.txt),
the Python nodes that launch and rostest files start, the rostest scripts and setup.py, checked
by vermin (scripts/requirements.txt) against target 3.8. The benchmarks and the evaluator
(scripts/bench/, evaluate.py, ...) run in the venv on Debian 12 only and are not checked.
Shown failing on Python 3.9+ constructs."""
import glob
import os
import re
import subprocess
import sys

from conftest import ROOT

TARGET = "3.8"


def ros_python_files(root):
    """Every Python file of the package that a ROS user runs with the system Python."""
    files = set(glob.glob(os.path.join(root, "scripts", "roverlib", "*.py")))
    files |= set(glob.glob(os.path.join(root, "test", "ros", "*.py")))
    files.add(os.path.join(root, "setup.py"))
    with open(os.path.join(root, "CMakeLists.txt")) as f:
        cmake = f.read()
    for block in re.findall(r"catkin_install_python\(PROGRAMS(.*?)DESTINATION", cmake, re.S):
        files |= {os.path.join(root, p) for p in block.split()}
    for launch in glob.glob(os.path.join(root, "launch", "*.launch")) + glob.glob(os.path.join(root, "test", "ros", "*.test")):
        with open(launch) as f:
            for node in re.findall(r'type="([^"]+\.py)"', f.read()):
                found = glob.glob(os.path.join(root, "scripts", node)) + glob.glob(os.path.join(root, "test", "ros", node))
                assert found, f"{launch} starts {node}, which is neither in scripts/ nor in test/ros/"
                files |= set(found)
    return sorted(files)


def vermin(paths):
    """(exit status, output) of vermin with target TARGET (or older) on `paths`."""
    exe = os.path.join(os.path.dirname(sys.executable), "vermin")
    out = subprocess.run([exe, f"-t={TARGET}-", "--no-tips", "--violations", "--eval-annotations", *paths],
                         capture_output=True, text=True)
    return out.returncode, out.stdout + out.stderr


def test_the_python_that_runs_under_ros_needs_at_most_python_3_8():
    files = ros_python_files(ROOT)
    names = {os.path.relpath(f, ROOT) for f in files}
    assert {"scripts/replay_bag.py", "scripts/roverlib/bag_replay.py", "scripts/roverlib/alignment.py",
            "test/ros/test_bag_regression.py", "setup.py"} <= names
    assert all(os.path.exists(f) for f in files)
    rc, out = vermin(files)
    assert rc == 0, out


def test_a_python_3_9_construct_fails(tmp_path):
    for i, code in enumerate(['merged = {"a": 1} | {"b": 2}\n',              # dict union
                              'name = "rover_x".removeprefix("rover_")\n',   # str.removeprefix
                              'def f(x: list[int]) -> None:\n    pass\n']):  # builtin generic annotation
        bad = tmp_path / f"bad{i}.py"
        bad.write_text(code)
        rc, out = vermin([str(bad)])
        assert rc != 0 and "requires !2, 3.9" in out, out
