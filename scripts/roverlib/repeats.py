"""Repeated candidate messages: the same query -> match sent several times (loop_fusion
re-detects a pair, a bag is replayed twice, a driver retransmits). Copies are one piece of
evidence (core/verifier.h): each must get what its first candidate got, in rover_replay, in
rover_verifier_node and in evaluate.py alike (test/ros/test_repeats.py,
test/python/test_replay_repeats.py).

  relocated(s, first, dx, false_pair)  a scenario whose VIO relocated: keyframes from `first`
                                       on shifted by dx metres along x, with the true candidates
                                       of s and the false candidate `false_pair` of s
  repeated(s, n)                       every candidate of s sent n times, interleaved: the copies
                                       of the candidates of one query keyframe take turns
  check_copies(once, rows, n)          what is wrong with the rows of a run with n copies, per
                                       pair, given the rows of the run sent once (see there)"""
import copy


def relocated(s, first=180, dx=100.0, false_pair=(204, 21)):
    """s with every keyframe from index `first` on shifted dx metres along x (the VIO
    relocated), its true candidates and its false candidate false_pair (query, match)."""
    out = copy.deepcopy(s)
    out.name = f"{s.name}+relocated_{first}"
    for k in out.keyframes:
        if k.index >= first:
            k.T = k.T.copy()
            k.T[0, 3] += dx
    false = [c for c in out.candidates if (c.query, c.match) == tuple(false_pair)]
    if len(false) != 1 or false[0].label != 0:
        raise ValueError(f"{s.name} has no single false candidate {false_pair[0]} -> {false_pair[1]}")
    out.candidates = [c for c in out.candidates if c.label == 1 or c is false[0]]
    return out


def repeated(s, n):
    """s with every candidate n times: round after round of all candidates (a scenario file and
    its bag keep the candidates of one query keyframe in that order)."""
    out = copy.copy(s)
    out.candidates = [c for _ in range(n) for c in s.candidates]
    return out


def by_pair(rows):
    """{(query, match): [row, ...]} of verdicts.csv-like rows (dicts), in row order."""
    out = {}
    for r in rows:
        out.setdefault((int(r["query_index"]), int(r["match_index"])), []).append(r)
    return out


def outcome(r):
    """What a row says about its candidate: accepted, reason and the kind of its final decision."""
    return (r["accepted"], r["reason"], r.get("decision", "verify"))


def check_copies(once, rows, n):
    """The problems (a list of strings; empty if none) of the rows of a run where every candidate
    was sent n times, against the rows of the same run sent once: per (query, match) n rows; the
    first as sent once (accepted, reason, decision, score); each copy as its first candidate
    (held with it and given its decision, or given its rejection) or, where the first was
    accepted and its loop was in the graph when the copy came, refused: invalid_input, "already
    in the graph"."""
    problems = []
    first, got = by_pair(once), by_pair(rows)
    if set(first) != set(got):
        problems.append(f"pairs differ: {sorted(set(first) ^ set(got))[:5]}")
    for key, want_rows in sorted(first.items()):
        have = got.get(key, [])
        if len(want_rows) != 1:
            problems.append(f"{key}: {len(want_rows)} rows sent once (pairs must be unique)")
            continue
        want = want_rows[0]
        if len(have) != n:
            problems.append(f"{key}: {len(have)} rows, sent {n} times")
            continue
        if outcome(have[0]) != outcome(want) or not _same_score(have[0]["score"], want["score"]):
            problems.append(f"{key}: first of {n}: {outcome(have[0])} score {have[0]['score']}, sent once "
                            f"{outcome(want)} score {want['score']} ({have[0]['detail'][:160]!r})")
        for r in have[1:]:
            ok = outcome(r) == outcome(want) and _same_score(r["score"], want["score"])
            if want["accepted"] == "1" and not ok:
                ok = r["accepted"] == "0" and r["reason"] == "invalid_input" and "already in the graph" in r["detail"]
            if not ok:
                problems.append(f"{key}: a copy: {outcome(r)} {r['detail'][:160]!r}; its first candidate "
                                f"{outcome(want)} {want['detail'][:160]!r}")
    return problems


def score(r):
    """A row's score rounded to 1e-5 (the node's and rover_replay's logs print it alike), or
    "nan"."""
    x = float(r["score"])
    return "nan" if x != x else round(x, 5)


def _same_score(a, b):
    a, b = float(a), float(b)
    return (a != a and b != b) or abs(a - b) <= 1e-5
