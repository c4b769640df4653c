import contextlib
import importlib.util
import os
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
# CI (.ci/run) has ../shared and sets ROVER_REQUIRE_SHARED=1: a test that needs ../shared/data
# then fails where it would skip in a user's clone.
REQUIRE_SHARED = os.environ.get("ROVER_REQUIRE_SHARED", "") not in ("", "0")


def missing_shared_data(what):
    """Skips the calling test, naming what of ../shared/data is missing (a user's clone has no
    ../shared); fails it instead under ROVER_REQUIRE_SHARED=1."""
    import pytest
    reason = f"needs ../shared/data: {what}"
    if REQUIRE_SHARED:
        pytest.fail(f"{reason} (ROVER_REQUIRE_SHARED=1: CI has ../shared)")
    pytest.skip(reason)


@contextlib.contextmanager
def shared_data():
    """Around test code that reads ../shared/data (roverlib/datasets.py): a missing file
    (datasets.MissingData, also from a worker process) skips the test or fails it, as
    missing_shared_data() says."""
    from roverlib import datasets
    try:
        yield
    except datasets.MissingData as e:
        missing_shared_data(str(e))


def script(relpath):
    """A script under scripts/ (e.g. "bench/poc.py") loaded as a module, to call its main():
    scripts are programs, not a package; roverlib is the importable package (setup.py)."""
    path = os.path.join(ROOT, "scripts", relpath)
    spec = importlib.util.spec_from_file_location("script_" + relpath[:-3].replace("/", "_"), path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # so that worker processes (fork) find its functions by name
    spec.loader.exec_module(module)
    return module


def devel_tool(name):
    """Path of a built tool in the catkin workspace (scripts/test.sh builds it first)."""
    ws = os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws"))
    return os.path.join(ws, "devel", "lib", "rover_loop_fusion", name)


def built_tool(name):
    """devel_tool(name); fails the calling test (not skips) when it has not been built."""
    import pytest
    tool = devel_tool(name)
    if not os.path.exists(tool):
        pytest.fail(f"{tool} not built: run scripts/test.sh")
    return tool


def tilted_loop_scenario():
    """Two laps of a 3 m circle (sequence 1, VIO = truth) by a body pitched 60 deg and rolled
    30 deg, as EuRoC's IMU is tilted, and one exact loop between headings 18 deg apart: its
    relative rotation's yaw is 8.8 deg, loop_fusion's relative yaw (the difference of world
    yaws) 18 deg. Returns (scenario, candidate)."""
    import numpy as np
    from roverlib import geometry as g, scenario
    tilt = g.rot_x(np.radians(30.0)) @ g.rot_y(np.radians(-60.0))
    n, r = 40, 3.0
    T = [g.pose(g.rot_z(2 * np.pi * k / n + np.pi / 2) @ tilt,
                [r * np.cos(2 * np.pi * k / n), r * np.sin(2 * np.pi * k / n), 0.0]) for k in range(2 * n)]
    q, m = n + 20, 18
    c = scenario.Candidate(q, m, g.relative(T[m], T[q]), 1, 40)
    keyframes = [scenario.Keyframe(k, 100.0 + 0.5 * k, 1, T[k]) for k in range(len(T))]
    return scenario.Scenario("tilted_loop", keyframes, [c], list(T)), c
