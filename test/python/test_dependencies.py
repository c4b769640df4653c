"""Dependencies: package.xml is the one list of what the package needs; scripts/setup.sh installs
what it derives from it through scripts/debian12-packages.yaml (rosdep key -> Debian 12
packages) plus that file's toolchain and hardening lists. Fails when a package.xml dependency
has no mapping or a mapped package is not among what the set-up installs (shown on broken
copies too), and when the generated message modules or a Python node that a launch or test
file starts do not import in a fresh system interpreter (/usr/bin/python3, not this venv, so
that a package from PyPI cannot stand in for a missing Debian package). And every key of
package.xml is one that was checked to be a rosdep key of ROS Noetic on Ubuntu 20.04
(scripts/noetic-rosdep-keys.yaml)."""
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import pytest
import yaml

from conftest import ROOT

SETUP = os.path.join("scripts", "setup.sh")
MAPPING = os.path.join("scripts", "debian12-packages.yaml")


def package_xml_keys(root):
    """Every dependency of package.xml (any *depend element), as written."""
    return sorted({e.text.strip() for e in ET.parse(os.path.join(root, "package.xml")).getroot()
                   if e.tag.endswith("depend")})


def setup_packages(root):
    """(packages scripts/setup.sh installs, its error output) for the package in `root`."""
    out = subprocess.run(["bash", os.path.join(root, SETUP), "--print-packages"], capture_output=True, text=True)
    return (set(out.stdout.split()) if out.returncode == 0 else None), out.stderr


def coverage_errors(root):
    """What is wrong with the dependencies of the package in `root`, in words; [] if nothing."""
    with open(os.path.join(root, MAPPING)) as f:
        mapping = yaml.safe_load(f)
    keys = mapping.get("keys") or {}
    errors = [f"package.xml dependency '{k}' has no Debian 12 packages in {MAPPING}"
              for k in package_xml_keys(root) if k not in keys]
    wanted = {p: k for k in package_xml_keys(root) for p in keys.get(k) or []}
    wanted.update({p: section for section in ("toolchain", "hardening") for p in mapping.get(section) or []})
    installed, stderr = setup_packages(root)
    if installed is None:
        return errors + [f"{SETUP} --print-packages failed: {stderr.strip()}"]
    errors += [f"{p} ({k}) is not installed by {SETUP}" for p, k in sorted(wanted.items()) if p not in installed]
    return errors


def copy_of_the_package(tmp_path):
    root = tmp_path / "pkg"
    (root / "scripts").mkdir(parents=True)
    for f in ("package.xml", SETUP, MAPPING):
        shutil.copy(os.path.join(ROOT, f), root / f)
    return root


def test_every_dependency_is_mapped_and_installed_by_the_setup():
    assert coverage_errors(ROOT) == []
    installed, _ = setup_packages(ROOT)
    # what was found missing on a fresh Debian 12
    assert {"build-essential", "cmake", "python3-geometry-msgs"} <= installed
    assert {"roscpp", "geometry_msgs", "rospy", "rostest"} <= set(package_xml_keys(ROOT))


def test_a_dependency_without_mapping_fails(tmp_path):
    root = copy_of_the_package(tmp_path)
    xml = (root / "package.xml").read_text()
    (root / "package.xml").write_text(xml.replace("<test_depend>rostest</test_depend>",
                                                  "<test_depend>rostest</test_depend>\n  <exec_depend>tf2_ros</exec_depend>"))
    errors = coverage_errors(root)
    print("\n".join(errors))
    assert f"package.xml dependency 'tf2_ros' has no Debian 12 packages in {MAPPING}" in errors
    # and the set-up itself refuses to go on, naming the key
    installed, stderr = setup_packages(root)
    assert installed is None and "'tf2_ros'" in stderr


def test_a_mapped_package_the_setup_does_not_install_fails(tmp_path):
    """A class of mistake: a set-up that installs a hand-kept list (here the list
    scripts/setup.sh had then) instead of what package.xml derives."""
    root = copy_of_the_package(tmp_path)
    setup = (root / SETUP).read_text()
    hand_kept = ("catkin ros-core-dev pluginlib-dev libtf2-dev libtf2-ros-dev libtf2-eigen-dev libceres-dev "
                 "libeigen3-dev libopencv-dev libgtest-dev googletest python3-nav-msgs python3-rosbag "
                 "python3-roslaunch python3-rostest python3-rosnode python3-rostopic python3-numpy python3-pytest "
                 "rosbash clang-14 libclang-rt-14-dev")
    marker = '\nif [ "${BASH_SOURCE[0]}" = "$0" ]'
    assert marker in setup
    (root / SETUP).write_text(setup.replace(
        marker, f"\nrover_debian_packages() {{ printf '%s\\n' {hand_kept}; }}{marker}", 1))
    errors = coverage_errors(root)
    print("\n".join(errors))
    assert f"python3-geometry-msgs (geometry_msgs) is not installed by {SETUP}" in errors
    assert f"build-essential (toolchain) is not installed by {SETUP}" in errors


def test_a_mapping_line_the_setup_cannot_read_fails(tmp_path):
    root = copy_of_the_package(tmp_path)
    text = (root / MAPPING).read_text()
    # valid YAML, but not one entry a line: the set-up must say so, not skip it
    broken = text.replace("  nav_msgs: [ros-nav-msgs, libnav-msgs-dev, python3-nav-msgs]",
                          "  nav_msgs:\n    - ros-nav-msgs\n    - libnav-msgs-dev\n    - python3-nav-msgs")
    assert broken != text
    (root / MAPPING).write_text(broken)
    assert yaml.safe_load(broken)["keys"]["nav_msgs"] == ["ros-nav-msgs", "libnav-msgs-dev", "python3-nav-msgs"]
    errors = coverage_errors(root)
    print("\n".join(errors))
    assert len(errors) == 1 and "cannot read" in errors[0] and "'nav_msgs'" in errors[0]


NOETIC_KEYS = os.path.join("scripts", "noetic-rosdep-keys.yaml")


def noetic_errors(root):
    """Where package.xml and the list of keys checked against ROS Noetic on Ubuntu 20.04 differ."""
    with open(os.path.join(root, NOETIC_KEYS)) as f:
        checked = yaml.safe_load(f).get("keys") or {}
    keys = package_xml_keys(root)
    errors = [f"package.xml dependency '{k}' was not checked as a rosdep key of Noetic on focal ({NOETIC_KEYS})"
              for k in keys if k not in checked]
    errors += [f"{NOETIC_KEYS} lists '{k}', which package.xml does not name" for k in checked if k not in keys]
    errors += [f"{NOETIC_KEYS}: '{k}' does not say where it was found" for k, where in checked.items()
               if not (isinstance(where, str) and where.startswith(("noetic/distribution.yaml", "rosdep/")))]
    return errors


def test_every_key_was_checked_against_noetic_on_focal():
    """Offline: package.xml names only the keys that scripts/noetic-rosdep-keys.yaml lists as
    checked by hand in ros/rosdistro (docs/testing.md); a new key fails until it is checked."""
    assert noetic_errors(ROOT) == []


def test_an_unchecked_key_fails(tmp_path):
    root = copy_of_the_package(tmp_path)
    shutil.copy(os.path.join(ROOT, NOETIC_KEYS), root / NOETIC_KEYS)
    xml = (root / "package.xml").read_text()
    (root / "package.xml").write_text(xml.replace("<test_depend>rostest</test_depend>",
                                                  "<test_depend>rostest</test_depend>\n  <exec_depend>tf2_ros</exec_depend>"))
    keys = (root / NOETIC_KEYS).read_text()
    (root / NOETIC_KEYS).write_text(keys.replace("  rosunit: noetic/distribution.yaml, repository ros\n", ""))
    errors = noetic_errors(root)
    print("\n".join(errors))
    assert f"package.xml dependency 'tf2_ros' was not checked as a rosdep key of Noetic on focal ({NOETIC_KEYS})" in errors
    assert f"package.xml dependency 'rosunit' was not checked as a rosdep key of Noetic on focal ({NOETIC_KEYS})" in errors


def fresh_python(code, cwd="/"):
    """Runs code in /usr/bin/python3 with this environment (the sourced catkin workspace), in
    directory cwd (python3 -c imports from there, as a program imports from its own directory)."""
    return subprocess.run(["/usr/bin/python3", "-c", code], capture_output=True, text=True, cwd=cwd)


def test_generated_messages_import_in_a_fresh_interpreter():
    out = fresh_python("import rover_loop_fusion.msg as m, rover_loop_fusion.srv as s; "
                       "print(m.LoopCandidate._type, m.LoopVerdict._type, s.Optimize._type)")
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["rover_loop_fusion/LoopCandidate", "rover_loop_fusion/LoopVerdict",
                                  "rover_loop_fusion/Optimize"]


def python_nodes():
    """(file, script path) of every Python node or test of this package that a file of launch/
    or a rostest file of test/ros/ starts."""
    found = []
    for d in ("launch", os.path.join("test", "ros")):
        for name in sorted(os.listdir(os.path.join(ROOT, d))):
            if not name.endswith((".launch", ".test")):
                continue
            text = open(os.path.join(ROOT, d, name)).read()
            for tag in re.findall(r"<(?:node|test)\b[^>]*>", text):
                pkg, typ = re.search(r'pkg="([^"]+)"', tag), re.search(r'type="([^"]+)"', tag)
                if pkg and typ and pkg.group(1) == "rover_loop_fusion" and typ.group(1).endswith(".py"):
                    found.append((os.path.join(d, name), typ.group(1)))
    return found


def script_path(name):
    hits = [os.path.join(ROOT, d, name) for d in ("scripts", os.path.join("test", "ros"))
            if os.path.exists(os.path.join(ROOT, d, name))]
    assert len(hits) == 1, f"{name}: {hits}"
    return hits[0]


def test_the_launch_and_test_files_start_python_nodes():
    started = {t for _, t in python_nodes()}
    assert "replay_bag.py" in started and "test_bag_regression.py" in started


@pytest.mark.parametrize("where,node", python_nodes())
def test_python_node_imports_in_a_fresh_interpreter(where, node):
    path = script_path(node)
    assert os.access(path, os.X_OK), f"{path} is not executable"
    # the module's top level (its imports) without running main(), from the node's directory as
    # when it runs as a program (its own directory first on the import path, nothing else added)
    out = fresh_python(f"import importlib.util as u; s = u.spec_from_file_location('node', {path!r}); "
                       f"s.loader.exec_module(u.module_from_spec(s))", cwd=os.path.dirname(path))
    assert out.returncode == 0, f"{node} (started by {where}): {out.stderr[-2000:]}"
