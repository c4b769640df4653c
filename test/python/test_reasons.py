"""The verdict reasons are one list per language: the C++ enum core::Reason with its names in
core::toString(Reason) (rover_loop_fusion/core/types.h, types.cpp) is the source; Python's
roverlib/reasons.py, the constants of msg/LoopVerdict.msg and the table of docs/ros-api.md must
name exactly the same reasons, and no other Python file under scripts/ keeps a list of its own.
Each check is shown failing on a deliberately broken copy."""
import ast
import os
import re

from conftest import ROOT
from roverlib import reasons

TYPES_H = os.path.join(ROOT, "rover_loop_fusion", "core", "types.h")
TYPES_CPP = os.path.join(ROOT, "rover_loop_fusion", "core", "types.cpp")
MSG = os.path.join(ROOT, "msg", "LoopVerdict.msg")
ROS_API = os.path.join(ROOT, "docs", "ros-api.md")
REASONS_PY = os.path.join(ROOT, "scripts", "roverlib", "reasons.py")


def read(path):
    with open(path) as f:
        return f.read()


def cpp_reasons(types_h, types_cpp):
    """(the reason names in the order of the C++ enum, what is wrong in words): every enumerator
    of `enum class Reason` needs exactly one `case Reason::kX: return "x";` in types.cpp."""
    enum = re.search(r"enum class Reason\s*\{(.*?)\};", types_h, re.S)
    if not enum:
        return [], ["types.h: no 'enum class Reason { ... };'"]
    body = re.sub(r"//[^\n]*", "", enum.group(1))
    enumerators = re.findall(r"\b(k\w+)\b", body)
    cases = re.findall(r'case\s+Reason::(k\w+)\s*:\s*return\s+"([^"]*)"\s*;', types_cpp)
    names = {}
    errors = []
    for k, name in cases:
        if k in names:
            errors.append(f"types.cpp: Reason::{k} has two cases")
        names[k] = name
    errors += [f"types.cpp: toString(Reason) has no case for Reason::{k}" for k in enumerators if k not in names]
    errors += [f"types.cpp: case Reason::{k} is not an enumerator of types.h" for k in names if k not in enumerators]
    listed = [names[k] for k in enumerators if k in names]
    errors += [f"types.cpp: reason name '{n}' is not snake_case" for n in listed if not re.fullmatch(r"[a-z][a-z0-9_]*", n)]
    errors += [f"types.cpp: reason name '{n}' is used twice" for n in sorted(set(listed)) if listed.count(n) > 1]
    return listed, errors


def msg_reasons(msg):
    """{value: NAME} of LoopVerdict.msg's string constants above its '# decision' constants."""
    out = {}
    for line in msg.splitlines():
        if line.strip().startswith("# decision"):
            break
        m = re.match(r"\s*string\s+(\w+)\s*=\s*(\S+)", line)
        if m:
            out[m.group(2)] = m.group(1)
    return out


def doc_reasons(md):
    """The reasons in the first column of the table under '### Verdict reasons'."""
    sec = re.search(r"^### Verdict reasons\n(.*?)(?=^#|\Z)", md, re.S | re.M)
    if not sec:
        return None
    return [m.group(1) for m in re.finditer(r"^\|\s*`([a-z0-9_]+)`\s*\|", sec.group(1), re.M)]


def drift(types_h, types_cpp, python_reasons, msg, md):
    """Everything that does not match the C++ enum, in words; [] if nothing."""
    cpp, errors = cpp_reasons(types_h, types_cpp)
    want = set(cpp)
    if not cpp:
        return errors + ["no reason found in the C++ enum"]

    def compare(what, got):
        out = [f"{what} lacks '{r}'" for r in cpp if r not in got]
        out += [f"{what} has '{r}', which the C++ enum does not" for r in sorted(set(got) - want)]
        out += [f"{what} lists '{r}' twice" for r in sorted(set(got)) if list(got).count(r) > 1]
        return out

    errors += compare("roverlib/reasons.py", list(python_reasons))
    constants = msg_reasons(msg)
    errors += compare("msg/LoopVerdict.msg", list(constants))
    errors += [f"msg/LoopVerdict.msg: constant {n}={v} should be named {v.upper()}"
               for v, n in constants.items() if n != v.upper()]
    listed = doc_reasons(md)
    errors += ["docs/ros-api.md: no '### Verdict reasons' table"] if listed is None else \
        compare("docs/ros-api.md's table of verdict reasons", listed)
    return errors


def current():
    return read(TYPES_H), read(TYPES_CPP), reasons.REASONS, read(MSG), read(ROS_API)


def test_the_python_list_the_message_and_the_docs_match_the_cpp_enum():
    cpp, errors = cpp_reasons(*current()[:2])
    assert errors == []
    assert {"accepted", "score_above_threshold", "invalid_input", "revoked"} <= set(cpp)
    assert drift(*current()) == []
    assert set(reasons.NOTES) == set(reasons.REASONS) and set(reasons.SCORED) <= set(reasons.REASONS)
    assert set(reasons.TRIALLED) <= set(reasons.REASONS)


def test_a_reason_added_to_the_cpp_enum_only_is_found():
    types_h, types_cpp, py, msg, md = current()
    h = types_h.replace("enum class Reason {", "enum class Reason {\n  kNewReason,  ///< new")
    cpp = types_cpp.replace("switch (reason) {", 'switch (reason) {\n    case Reason::kNewReason: return "new_reason";')
    errors = drift(h, cpp, py, msg, md)
    print("\n".join(errors))
    assert "roverlib/reasons.py lacks 'new_reason'" in errors
    assert "msg/LoopVerdict.msg lacks 'new_reason'" in errors
    assert "docs/ros-api.md's table of verdict reasons lacks 'new_reason'" in errors
    # an enumerator without its name in toString(Reason)
    assert "types.cpp: toString(Reason) has no case for Reason::kNewReason" in drift(h, types_cpp, py, msg, md)


def test_a_stale_or_renamed_reason_outside_cpp_is_found():
    types_h, types_cpp, py, msg, md = current()
    stale = [r for r in py if r != "revoked"] + ["rejected"]
    errors = drift(types_h, types_cpp, stale, msg.replace("string REVOKED=revoked\n", ""),
                   md.replace("| `lookalike_closer` |", "| `look_alike_closer` |"))
    print("\n".join(errors))
    assert "roverlib/reasons.py lacks 'revoked'" in errors
    assert "roverlib/reasons.py has 'rejected', which the C++ enum does not" in errors
    assert "msg/LoopVerdict.msg lacks 'revoked'" in errors
    assert "docs/ros-api.md's table of verdict reasons has 'look_alike_closer', which the C++ enum does not" in errors


def reason_literals(source):
    """The distinct reason names that appear as string literals in Python source."""
    return {n.value for n in ast.walk(ast.parse(source))
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and n.value in reasons.REASONS}


def copies_of_the_list(root):
    """Python files under scripts/ other than roverlib/reasons.py with three or more reason names
    as string literals: a list of reasons of their own."""
    out = []
    for d, _, files in os.walk(os.path.join(root, "scripts")):
        for f in files:
            path = os.path.join(d, f)
            if f.endswith(".py") and os.path.realpath(path) != os.path.realpath(REASONS_PY):
                if len(reason_literals(read(path))) >= 3:
                    out.append(os.path.relpath(path, root))
    return out


def test_no_python_file_keeps_its_own_list_of_reasons():
    assert copies_of_the_list(ROOT) == []
    # what bag_replay.py had before roverlib/reasons.py
    old = 'NOTES = {"accepted": "a", "innovation_above_bound": "b", "score_above_threshold": "c"}'
    assert len(reason_literals(old)) == 3
