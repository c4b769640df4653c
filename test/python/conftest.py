import contextlib
import os

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
    """A program under scripts/ (e.g. "bench/poc.py") as a module, to call its main():
    roverlib.programs.load (the programs are not a package; roverlib is, setup.py)."""
    from roverlib import programs
    return programs.load(relpath)


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
