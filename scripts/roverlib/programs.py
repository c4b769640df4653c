"""The programs under scripts/ as modules, to call their functions: a benchmark family's
setup() from another family (bench/agreement.py, identity.py, robustness.py), long_replay's
helpers (bench/fault_replay.py), simulate.main (make_shipped_data.py), and every program a test
calls (test/python/conftest.py). The programs are not a package and are not on the import path;
roverlib is the importable package (setup.py), so a program is loaded from its file.

  poc = programs.load("bench/poc.py")

A program is loaded once per process, as module "script_<path with _ for />" (e.g.
script_bench_poc); worker processes started by fork find its functions under that name."""
import importlib.util
import os
import sys

SCRIPTS = os.path.abspath(os.path.join(os.path.dirname(os.path.realpath(__file__)), ".."))  # scripts/ of the clone


def load(relpath):
    """scripts/<relpath> (e.g. "bench/poc.py") as a module, loaded on first use."""
    name = "script_" + relpath[:-3].replace("/", "_")
    if name in sys.modules:
        return sys.modules[name]
    path = os.path.join(SCRIPTS, relpath)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such program under scripts/")
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module
