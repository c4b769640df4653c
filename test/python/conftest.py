import importlib.util
import os
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


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
