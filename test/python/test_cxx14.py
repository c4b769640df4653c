"""Our C++ builds as C++14 without a warning: in the build this suite runs (scripts/setup.sh sets
ROVER_WERROR), every C++ target of the package compiles with -std=c++14 (not gnu++14) -Wall
-Wextra -Werror, so a warning fails the build. Read from CMake's generated flags."""
import glob
import os

import pytest

from conftest import ROOT

WANT = ("-std=c++14", "-Wall", "-Wextra", "-Werror")


def target_flags(build_dir):
    """{target: its CXX_FLAGS} of every C++ target under build_dir (CMake's flags.make files)."""
    out = {}
    for path in glob.glob(os.path.join(build_dir, "CMakeFiles", "*.dir", "flags.make")):
        with open(path) as f:
            flags = [line.split("=", 1)[1].split() for line in f if line.startswith("CXX_FLAGS")]
        if flags:
            out[os.path.basename(os.path.dirname(path))[:-len(".dir")]] = flags[0]
    return out


def missing_flags(flags):
    """{target: the WANT flags it lacks, or a gnu++ standard} for targets that are not built as wanted."""
    bad = {}
    for target, f in flags.items():
        lacks = [w for w in WANT if w not in f] + [x for x in f if x.startswith("-std=gnu++")]
        if lacks:
            bad[target] = lacks
    return bad


def test_every_cxx_target_builds_as_cxx14_with_warnings_as_errors():
    ws = os.environ.get("ROVER_WS", os.path.join(ROOT, ".ws"))
    build = os.path.join(ws, "build", "rover_loop_fusion")
    if not os.path.isdir(build):
        pytest.fail(f"{build} not found: run scripts/test.sh")
    flags = target_flags(build)
    assert {"rover_loop_fusion_core", "rover_verifier_node", "rover_loop_fusion_adapter", "test_core"} <= set(flags)
    assert missing_flags(flags) == {}


def test_a_target_without_them_is_named():
    flags = {"ok": ["-O3", "-Wall", "-Wextra", "-Werror", "-std=c++14"],
             "gnu": ["-O3", "-Wall", "-Wextra", "-Werror", "-std=gnu++14"],
             "lax": ["-O3", "-Wall", "-std=c++14"]}
    assert missing_flags(flags) == {"gnu": ["-std=c++14", "-std=gnu++14"], "lax": ["-Wextra", "-Werror"]}
