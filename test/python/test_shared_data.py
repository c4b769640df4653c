"""A clone without ../shared: the tests that need ../shared/data skip with a one-line reason
naming the missing file, and scripts/test_summary.py lists each skip with its reason above the
closing line; under ROVER_REQUIRE_SHARED=1 (.ci/run: CI has ../shared) they fail instead."""
import os
import shutil
import subprocess
import sys

from conftest import ROOT

NEEDS_DATA = '''
from conftest import shared_data
from roverlib import g2o


def test_reads_a_graph():
    with shared_data():
        g2o.load("ring")
'''


def run_pytest(tmp_path, require):
    """Runs NEEDS_DATA with ../shared/data elsewhere (ROVER_SHARED_DATA); (exit status, JUnit dir)."""
    test = tmp_path / "test_needs_data.py"
    test.write_text(NEEDS_DATA)
    shutil.copy(os.path.join(ROOT, "test", "python", "conftest.py"), str(tmp_path))  # pytest imports it beside the test
    env = dict(os.environ, ROVER_SHARED_DATA=str(tmp_path / "no_shared_data"))
    env.pop("ROVER_REQUIRE_SHARED", None)
    if require:
        env["ROVER_REQUIRE_SHARED"] = "1"
    results = tmp_path / ("required" if require else "clone")
    results.mkdir()
    rc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test),
                         f"--junitxml={results / 'pytest.xml'}"], env=env, capture_output=True, text=True,
                        cwd=str(tmp_path)).returncode
    return rc, results


def summary(results):
    out = subprocess.run([sys.executable, os.path.join(ROOT, "scripts", "test_summary.py"), str(results)],
                         capture_output=True, text=True)
    return out.returncode, out.stdout.strip().splitlines()


def test_without_shared_data_the_test_skips_naming_the_file(tmp_path):
    rc, results = run_pytest(tmp_path, require=False)
    assert rc == 0
    code, lines = summary(results)
    assert lines[-1] == "rover tests: 0 passed, 0 failed, 1 skipped"
    (skip,) = [line for line in lines if line.startswith("SKIPPED ")]
    assert "test_reads_a_graph: needs ../shared/data: " in skip
    assert os.path.join("no_shared_data", "posegraphs", "ring.g2o") + " not found" in skip


def test_ci_turns_the_skip_into_a_failure(tmp_path):
    rc, results = run_pytest(tmp_path, require=True)
    assert rc == 1
    code, lines = summary(results)
    assert code == 1 and lines[-1] == "rover tests: 0 passed, 1 failed, 0 skipped"


def test_ci_sets_the_variable_and_runs_the_readme_command():
    with open(os.path.join(ROOT, ".ci", "run")) as f:
        run = f.read()
    assert "export ROVER_REQUIRE_SHARED=1\n" in run
    assert run.rstrip().endswith("exec ./scripts/test.sh")
