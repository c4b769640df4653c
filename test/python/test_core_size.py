"""The files of a candidate's way through the verifier (core/verifier.cpp, its stages and what
it hands a candidate to: the emitter, the store of held candidates, the accepted loops,
revocation, the global pass's releases) stay readable: at most 500 lines a file, at most 80 lines a function.
The measure is shown failing on a deliberately long text."""
import os
import re

from conftest import ROOT

CORE = os.path.join(ROOT, "rover_loop_fusion", "core")
PIPELINE = ["verifier.cpp", "verifier.h", "verdict_emitter.cpp", "verdict_emitter.h", "held_candidates.cpp",
            "held_candidates.h", "accepted_loops.cpp", "accepted_loops.h", "revocation.cpp", "global_release.cpp",
            "stage.h", "stage_input.cpp", "stage_input.h", "copies.cpp", "copies.h", "stage_prior.cpp",
            "stage_prior.h", "stage_decide.cpp", "stage_decide.h", "stage_hold.cpp", "stage_hold.h"]
MAX_FILE, MAX_FUNCTION = 500, 80
# The line that opens a function's body: its header's ')' then '{' (a namespace, class or
# struct has no ')'); its header may begin on lines above.
OPENS = re.compile(r"^\s*[A-Za-z_].*\)\s*(const\s*)?(override\s*)?\{\s*$")


def function_lengths(text):
    """(first line of its header, lines from header to closing brace) of every function whose
    body closes with a brace at column 0."""
    lines = text.split("\n")
    out, start = [], None
    for i, line in enumerate(lines):
        if start is None and OPENS.match(line):
            start = i
            # a header over several lines: back to the line after the last ';', '}' or blank
            while start > 0 and lines[start - 1].strip() and not re.search(r"[;}{]\s*$|^\s*//|^#", lines[start - 1]):
                start -= 1
        elif start is not None and line.startswith("}"):
            out.append((lines[start].strip(), i - start + 1))
            start = None
    return out


def read(name):
    with open(os.path.join(CORE, name)) as f:
        return f.read()


def test_pipeline_files_are_short():
    long = [(n, read(n).count("\n")) for n in PIPELINE if read(n).count("\n") > MAX_FILE]
    assert not long, f"over {MAX_FILE} lines: {long}"


def test_pipeline_functions_are_short():
    long = [(n, head, k) for n in PIPELINE if n.endswith(".cpp") for head, k in function_lengths(read(n))
            if k > MAX_FUNCTION]
    assert not long, f"functions over {MAX_FUNCTION} lines: {long}"


def test_the_measure_sees_a_long_function():
    text = "namespace a {\n\nint Verifier::f(int x,\n               int y) {\n" + "  ++x;\n" * 90 + "}\n\n}  // namespace a\n"
    (head, k), = function_lengths(text)
    assert head.startswith("int Verifier::f(") and k == 93
