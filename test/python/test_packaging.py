"""roverlib is an installed package (setup.py: catkin_python_setup into the workspace,
scripts/venv.sh into the venv): no Python file of the repo adds a directory to the import path
to find it, a program beside it or a test helper; the venv's Python and /usr/bin/python3 under
the sourced workspace import it from any directory."""
import os
import re
import subprocess
import sys

import pytest

from conftest import ROOT

# What edits the import path: sys.path changed in place or assigned, sys.meta_path / path_hooks,
# `from sys import path`, site.addsitedir, PYTHONPATH set for a child. This file, which names
# them, is the one the scan leaves out.
PATH_EDITS = [
    (r"\bsys\s*\.\s*path\s*(?:\.\s*(?:insert|append|extend|remove|pop|clear)\s*\(|\[[^\]]*\]\s*=|\+=|=(?!=))",
     "changes sys.path"),
    (r"\bsys\s*\.\s*(?:meta_path|path_hooks|path_importer_cache)\b", "changes the import machinery"),
    (r"\bfrom\s+sys\s+import\s+[^\n]*\bpath\b", "imports sys.path to change it"),
    (r"\baddsitedir\b", "adds a site directory"),
    (r"\bPYTHONPATH\b", "sets the import path of a child process"),
]
# not the repo's files: git, the workspace, the venv, benchmark output; other hidden folders
# (caches, a user's own venv) too, but for .ci
SKIP_DIRS = {".git", ".ws", ".venv", "results", "__pycache__", "node_modules"}
SCANNED_HIDDEN = {".ci"}


def python_files(root):
    """Every Python file under root: *.py and files whose first line names python."""
    out = []
    for d, dirs, files in os.walk(root):
        dirs[:] = sorted(x for x in dirs if x not in SKIP_DIRS and (not x.startswith(".") or x in SCANNED_HIDDEN))
        for f in sorted(files):
            path = os.path.join(d, f)
            if f.endswith(".py"):
                out.append(path)
            elif "." not in f and os.path.isfile(path):
                with open(path, "rb") as fh:
                    first = fh.readline(200)
                if first.startswith(b"#!") and b"python" in first:
                    out.append(path)
    return out


def path_edits(root, skip=()):
    """["file:line: what (the line)"] for every import-path edit in root's Python files."""
    found = []
    for path in python_files(root):
        if os.path.abspath(path) in skip:
            continue
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        for pattern, what in PATH_EDITS:
            for m in re.finditer(pattern, text):
                line = text.count("\n", 0, m.start()) + 1
                found.append(f"{os.path.relpath(path, root)}:{line}: {what} "
                             f"({text.splitlines()[line - 1].strip()})")
    return found


def test_no_python_file_edits_the_import_path():
    files = {os.path.relpath(p, ROOT) for p in python_files(ROOT)}
    # the scan sees the programs, the library, both test folders and setup.py
    assert {"setup.py", "scripts/evaluate.py", "scripts/bench/poc.py", "scripts/roverlib/bench.py",
            "test/python/conftest.py", "test/ros/test_node_faults.py"} <= files
    edits = path_edits(ROOT, skip={os.path.abspath(__file__)})
    assert not edits, "import-path edits (roverlib is installed: setup.py; programs: roverlib.programs.load):\n" + \
        "\n".join(edits)


@pytest.mark.parametrize("code", [
    "import sys, os\nsys.path.insert(0, os.path.dirname(__file__))\n",
    "import sys\nsys.path.append('/x')\n",
    "import sys\nsys.path[:0] = ['/x']\n",
    "import sys\nsys.path = ['/x'] + sys.path\n",
    "import sys\nsys.path += ['/x']\n",
    "from sys import path\npath.insert(0, '/x')\n",
    "import site\nsite.addsitedir('/x')\n",
    "import os\nenv = dict(os.environ, PYTHONPATH='/x')\n",
    "code = f\"import sys; sys.path.insert(0, {'/x'!r})\"\n",  # in code run by a child
])
def test_each_kind_of_edit_is_found(tmp_path, code):
    (tmp_path / "tool.py").write_text(code)
    assert len(path_edits(str(tmp_path))) == 1


def test_an_edit_in_a_python_program_without_py_is_found(tmp_path):
    (tmp_path / "tool").write_text("#!/usr/bin/env python3\nimport sys\nsys.path.insert(0, '.')\n")
    (tmp_path / "notes").write_text("sys.path.insert(0, '.') in a text file is not code\n")
    assert [e.split(":")[0] for e in path_edits(str(tmp_path))] == ["tool"]


def test_reading_the_import_path_is_not_an_edit(tmp_path):
    (tmp_path / "tool.py").write_text("import sys\nprint(sys.path[0], len(sys.path) == 1)\nif sys.path == []:\n"
                                      "    pass\n")
    assert path_edits(str(tmp_path)) == []


def neutral_env():
    """This environment without PYTHONPATH entries that point into the clone's sources."""
    env = dict(os.environ)
    parts = [p for p in env.get("PYTHONPATH", "").split(os.pathsep)
             if p and not os.path.abspath(p).startswith(os.path.join(ROOT, "scripts"))]
    env["PYTHONPATH"] = os.pathsep.join(parts)
    return env


def test_the_venv_imports_roverlib_without_the_workspace(tmp_path):
    env = neutral_env()
    env.pop("PYTHONPATH")  # not even the workspace's devel space
    out = subprocess.run([sys.executable, "-c", "import roverlib.programs, roverlib.scenes as s; "
                          "print(roverlib.__file__); print(s.tilted_loop()[0].name)"],
                         capture_output=True, text=True, cwd=str(tmp_path), env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [os.path.join(ROOT, "scripts", "roverlib", "__init__.py"), "tilted_loop"]


def test_the_system_python_imports_roverlib_under_the_sourced_workspace(tmp_path):
    setup = os.path.join(os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws")), "devel", "setup.bash")
    if not os.path.exists(setup):
        pytest.fail(f"{setup} missing: build the workspace (scripts/setup.sh)")
    out = subprocess.run(["bash", "-c", f"source {setup} && /usr/bin/python3 -c "
                          "'import os, roverlib.programs; print(os.path.realpath(roverlib.programs.__file__))'"],
                         capture_output=True, text=True, cwd=str(tmp_path), env=neutral_env())
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [os.path.join(os.path.realpath(ROOT), "scripts", "roverlib", "programs.py")]


def test_a_program_loads_another_without_an_import_path(tmp_path):
    env = neutral_env()
    env.pop("PYTHONPATH")
    code = ("from roverlib import programs; poc = programs.load('bench/poc.py'); "
            "print(poc.__name__, callable(poc.setup), programs.load('bench/poc.py') is poc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(tmp_path), env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["script_bench_poc", "True", "True"]
