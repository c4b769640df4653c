"""The pages, code comments, tests and scripts name topics, not steps of the work: a heading or
comment that says which step of the work made something goes stale with the next commit. The
history has one place, CHANGELOG.md at the repository root; everywhere else a step name fails
this test. Also the page budgets: README.md at most 200 lines, docs/results.md at most 500, and
no commit hashes in the user pages. Each check is shown failing on a deliberately bad text."""
import os
import re
import subprocess

from conftest import ROOT

# The names of steps of the work (the patterns are written so that this file does not match them).
STEP_WORDS = [
    re.compile(r"\bstops?\s+[0-9]", re.I),          # a numbered step of the work
    re.compile(r"\bthis\s+round\b", re.I),
    re.compile(r"\brounds?\s+before\b", re.I),
    re.compile(r"\b(earlier|previous|next|last)\s+rounds?\b", re.I),
    re.compile(r"\bthe\s+lab\b", re.I),               # a workbench, not a place a reader can go
]
HISTORY = {"CHANGELOG.md"}
SKIP_DIRS = {".git", ".ws", ".venv", "__pycache__", "node_modules"}
SKIP_TOP = {"results"}  # the benchmarks' git-ignored output (docs/results/ is a page folder)
MAX_LINES = {"README.md": 200, os.path.join("docs", "results.md"): 500}
# The pages a user reads: they cite no commit (design-notes.md, a developer's record, may).
USER_PAGES = ["README.md", os.path.join("docs", "results.md"), os.path.join("docs", "method.md"),
              os.path.join("docs", "vins-fusion.md"), os.path.join("docs", "results", "targets.md"),
              os.path.join("docs", "results", "posegraph.md"), os.path.join("patches", "README.md"),
              os.path.join("data", "README.md")]
HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
# VINS-Fusion's commit that the patch applies to (patches/README.md): a user needs it.
UPSTREAM = {"be55a93"}


def repo_files(root):
    """The repository's text files, relative to root: git's tracked and untracked-but-not-ignored
    files when root is a git work tree, else a walk that leaves build and cache folders out."""
    try:
        out = subprocess.run(["git", "-C", root, "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                             check=True, capture_output=True).stdout.decode()
        paths = [p for p in out.split("\0") if p]
    except (OSError, subprocess.CalledProcessError):
        paths = []
        for d, dirs, files in os.walk(root):
            dirs[:] = [x for x in dirs if x not in SKIP_DIRS and not (d == root and x in SKIP_TOP)]
            paths += [os.path.relpath(os.path.join(d, f), root) for f in files]
    texts = []
    for p in sorted(set(paths)):
        full = os.path.join(root, p)
        if not os.path.isfile(full) or os.path.getsize(full) > 2_000_000:
            continue
        with open(full, "rb") as f:
            data = f.read()
        if b"\0" in data:
            continue
        try:
            texts.append((p, data.decode("utf-8")))
        except UnicodeDecodeError:
            continue
    return texts


def step_words(files):
    """'path:line: text' for every line outside HISTORY that names a step of the work."""
    found = []
    for path, text in files:
        if os.path.basename(path) in HISTORY and os.path.dirname(path) == "":
            continue
        for n, line in enumerate(text.splitlines(), 1):
            if any(p.search(line) for p in STEP_WORDS):
                found.append(f"{path}:{n}: {line.strip()[:160]}")
    return found


def over_budget(files):
    """'path: N lines, at most M' for every page above its line budget."""
    lines = {p: len(t.splitlines()) for p, t in files}
    return [f"{p}: {lines[p]} lines, at most {m}" for p, m in MAX_LINES.items() if lines.get(p, 0) > m]


def commit_hashes(files):
    """'path:line: hash' for every commit hash cited in a user page."""
    pages = dict(files)
    found = []
    for p in USER_PAGES:
        for n, line in enumerate(pages.get(p, "").splitlines(), 1):
            # Links and code spans may hold hex that is not a commit (a colour, a checksum).
            prose = re.sub(r"`[^`]*`|\]\([^)]*\)", "", line)
            found += [f"{p}:{n}: {m.group(0)}" for m in HASH.finditer(prose)
                      if m.group(0) not in UPSTREAM]
    return found


def test_no_step_of_the_work_is_named_outside_the_changelog():
    found = step_words(repo_files(ROOT))
    assert not found, "name the topic, not the step of the work (history goes to CHANGELOG.md):\n" + "\n".join(found)


def test_the_pages_keep_their_budgets():
    found = over_budget(repo_files(ROOT))
    assert not found, "a page over its line budget:\n" + "\n".join(found)


def test_the_user_pages_cite_no_commit():
    found = commit_hashes(repo_files(ROOT))
    assert not found, "a user page names what ships, not the commit that made it:\n" + "\n".join(found)


def test_the_checks_fail_on_bad_text():
    bad = [("docs/x.md", "## " + "St" + "op 39: revisits\n"),
           ("rover_loop_fusion/core/a.cpp", "// as " + "the" + " lab's bags showed\n"),
           ("scripts/b.py", "# measured in " + "this" + " round\n"),
           ("docs/y.md", "### The " + "round" + " before\n"),
           ("docs/z.md", "the " + "earlier" + " rounds' figures\n")]
    assert len(step_words(bad)) == len(bad)
    assert step_words([("CHANGELOG.md", "## " + "St" + "op 39\n")]) == []
    assert step_words([("docs/CHANGELOG.md", "## " + "St" + "op 39\n")]) != []  # only the root's
    assert step_words([("a.py", "x = round(y)  # the label, a round trip, stopped 3 times\n")]) == []
    long_readme = [("README.md", "line\n" * 201), (os.path.join("docs", "results.md"), "line\n" * 500)]
    assert over_budget(long_readme) == ["README.md: 201 lines, at most 200"]
    assert commit_hashes([("README.md", "measured at d57e563 and 7d3dc2c\n")]) == [
        "README.md:1: d57e563", "README.md:1: 7d3dc2c"]
    not_commits = "100000 keyframes, `sha256 deadbeef01`, [x](#a1b2c3d4), upstream be55a93\n"
    assert commit_hashes([("README.md", not_commits)]) == []
