"""The code stays readable: every file of the ROS-free core (rover_loop_fusion/core/) at most
500 lines, and every function of the package's C++ (core, ros, sim, tools: top-level functions,
methods defined in a class, templates) at most 80 lines, header to closing brace. The measure is
shown failing on deliberately long texts."""
import glob
import os
import re

from conftest import ROOT

PACKAGE = os.path.join(ROOT, "rover_loop_fusion")
CORE = os.path.join(PACKAGE, "core")
MAX_FILE, MAX_FUNCTION = 500, 80
# The line that opens a function's body: its header's ')' then '{' (a namespace, class or
# struct has no ')'); its header may begin on lines above.
OPENS = re.compile(r"^\s*[A-Za-z_~].*\)\s*(const\s*)?(noexcept\s*)?(override\s*)?(->\s*[\w:<>]+\s*)?\{\s*(//.*)?$")
CONTROL = re.compile(r"^\s*(\}\s*)?(if|for|while|switch|else|do|catch)\b")
LITERALS = re.compile(r'"(\\.|[^"\\])*"|\'(\\.|[^\'\\])*\'')


def braces(line):
    """'{' minus '}' of a line, string and character literals and // comments aside."""
    code = LITERALS.sub("", line).split("//", 1)[0]
    return code.count("{") - code.count("}")


def function_lengths(text):
    """(first line of its header, lines from header to closing brace) of every function body that
    is not inside another function (lambdas and blocks inside one count as its lines)."""
    lines = text.split("\n")
    out, start, depth = [], None, 0
    for i, line in enumerate(lines):
        if start is None:
            if OPENS.match(line) and not CONTROL.match(line):
                start, depth = i, braces(line)
                # a header over several lines: back to the line after the last ';', '}', '{' or blank
                while start > 0 and lines[start - 1].strip() and \
                        not re.search(r"[;}{]\s*$|^\s*//|^\s*#|^\s*(public|private|protected):", lines[start - 1]):
                    start -= 1
        else:
            depth += braces(line)
        if start is not None and depth <= 0:
            out.append((lines[start].strip(), i - start + 1))
            start = None
    return out


def sources():
    return sorted(p for ext in ("cpp", "h") for p in glob.glob(os.path.join(PACKAGE, "**", f"*.{ext}"), recursive=True))


def read(path):
    with open(path) as f:
        return f.read()


def test_core_files_are_short():
    long = [(os.path.relpath(p, ROOT), read(p).count("\n")) for p in sources()
            if p.startswith(CORE + os.sep) and read(p).count("\n") > MAX_FILE]
    assert not long, f"core files over {MAX_FILE} lines: {long}"


def test_functions_are_short():
    long = [(os.path.relpath(p, ROOT), head, k) for p in sources() for head, k in function_lengths(read(p))
            if k > MAX_FUNCTION]
    assert not long, f"functions over {MAX_FUNCTION} lines: {long}"


def test_the_measure_sees_a_long_function():
    text = "namespace a {\n\nint Verifier::f(int x,\n               int y) {\n" + "  ++x;\n" * 90 + "}\n\n}  // namespace a\n"
    (head, k), = function_lengths(text)
    assert head.startswith("int Verifier::f(") and k == 93


def test_the_measure_sees_a_long_method_in_a_class_with_a_lambda():
    body = "    auto f = [&](int y) {\n      return y;\n    };\n" + "    if (x) {\n      ++x;\n    }\n" * 30
    text = ("class A {\n public:\n  int g(int x) const {\n" + body + "    return \"}\" == 0 ? x : '{';\n  }\n"
            "  void h() {}\n};\n")
    found = function_lengths(text)
    # the header, the lambda's 3 lines, 30 blocks of 3, the return and the closing brace
    assert len(found) == 1 and found[0][0].startswith("int g(int x) const {") and found[0][1] == 1 + 3 + 90 + 2, found
