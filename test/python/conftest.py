import os
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "scripts"))


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
