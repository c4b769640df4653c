"""The peers get the keyframes the product kept: rover_replay writes what its intake kept and
refused (intake.csv), and the benchmarks build the peers' pose graph (problem.from_scenario,
methods.evaluate) on those keyframes. A scene with one keyframe at x += 1e155 (refused, a
glitch: failure catalogue row 34) gives every peer finite covariances and a finite ATE."""
import math
import types

import numpy as np
import pytest

from conftest import built_tool
from roverlib import bench, drift_model, methods, metrics, problem, scenario, scenes
from roverlib import geometry as g

GLITCH = 1e155


def room_with_a_glitch(refused=True):
    """The room (10 true, 10 false candidates) with, if `refused`, one keyframe at x += 1e155:
    a keyframe that a candidate names as its match. Returns (scenario, that keyframe's index,
    the candidates that name it)."""
    s = scenes.make_scene("room", 0.05, seed=3, n_true=10, n_false=10)
    named = sorted({c.match for c in s.candidates if c.label == 1})
    k = named[len(named) // 2]
    if refused:
        i = [kf.index for kf in s.keyframes].index(k)
        T = s.keyframes[i].T.copy()
        T[0, 3] += GLITCH
        s.keyframes[i] = scenario.Keyframe(k, s.keyframes[i].stamp, s.keyframes[i].sequence, T)
    return s, k, [c for c in s.candidates if k in (c.query, c.match)]


def case(name):
    return types.SimpleNamespace(name=name, family="intake", split="test", notes="", environment="indoor")


def test_rover_replay_writes_the_keyframes_it_kept_and_refused(tmp_path):
    built_tool("rover_replay")
    s, k, _ = room_with_a_glitch()
    scenario.write(s, str(tmp_path / "scene"))
    run = bench.replay(str(tmp_path / "scene"), str(tmp_path / "run"), "sequential",
                       bench.shipped("indoor", "--mode", "4dof"))
    rows = bench.intake(run)
    assert [i for i, _ in rows] == [kf.index for kf in s.keyframes]  # every keyframe, in the file's order
    assert [i for i, kept in rows if not kept] == [k]
    with open(tmp_path / "run" / "intake.csv") as f:
        lines = f.read().splitlines()
    assert lines[0] == "index,sequence,stamp,kept,message"
    refused = [l for l in lines[1:] if l.split(",")[0] == str(k)]
    assert len(refused) == 1 and refused[0].startswith(f"{k},1,") and ",0," in refused[0]
    assert f'"keyframe {k}: position (1e+155' in refused[0] and "not a VIO pose" in refused[0]  # addKeyframe's message
    assert all(l.endswith(',1,""') for l in lines[1:] if l not in refused)  # the others clean
    # the trajectories hold the kept keyframes only
    assert len(metrics.read_tum(str(tmp_path / "run" / "odometry.tum")).timestamps) == len(s.keyframes) - 1


def test_a_refused_keyframe_is_no_vertex_and_its_candidates_no_loops():
    s, k, naming = room_with_a_glitch()
    assert naming
    kept = {kf.index for kf in s.keyframes} - {k}
    p = problem.from_scenario(s, drift_model.INDOOR, "4dof", kept)
    assert p.n == len(s.keyframes) - 1 and len(p.truth) == p.n
    assert len(p.loops) == len(s.candidates) - len(naming)
    assert not {(c.query, c.match) for c in naming} & {e.pair for e in p.loops}
    assert p.meta["refused_keyframes"] == [k]
    for e in p.odometry + p.loops:
        assert np.isfinite(e.T).all() and np.isfinite(e.cov).all()
    # the odometry edge over the refused keyframe joins its neighbours, as the product's graph does
    pos = [kf.index for kf in s.keyframes].index(k)
    before, after = s.keyframes[pos - 1].T, s.keyframes[pos + 1].T
    assert np.allclose(p.odometry[pos - 1].T, g.relative(g.yaw_only(before), g.yaw_only(after)), atol=1e-9)
    # a loop is still named by its keyframes, whose vertices moved down by one after the refused keyframe
    late = [e for e in p.loops if e.pair[0] > k]
    assert late and all(e.b == e.pair[0] - 1 for e in late)
    # the same problem, rebuilt from the one with every keyframe
    full = problem.from_scenario(s, drift_model.INDOOR, "4dof")
    again = full.on_keyframes(kept)
    assert again.n == p.n and [e.pair for e in again.loops] == [e.pair for e in p.loops]


def test_a_g2o_problem_cannot_leave_keyframes_out():
    s, _, _ = room_with_a_glitch(refused=False)
    p = problem.from_scenario(s, drift_model.INDOOR)
    p.source = None
    with pytest.raises(ValueError, match="not built from a scenario"):
        p.on_keyframes([0, 1])


@pytest.mark.parametrize("glitch", [False, True])
def test_every_peer_gets_finite_figures_on_a_scene_with_a_refused_keyframe(tmp_path, glitch):
    built_tool("rover_replay")
    s, k, naming = room_with_a_glitch(refused=glitch)
    d = str(tmp_path / "scene")
    scenario.write(s, d)
    prob = problem.from_scenario(s, drift_model.INDOOR, "4dof")  # as the families' setup() builds it
    info, rows = methods.evaluate(case("room_glitch" if glitch else "room"), d, prob, [], str(tmp_path / "out"),
                                  snapshots=3, time_limit=120.0)
    by = {r["method"]: r for r in rows}
    assert {"rover+lf", "rover+lm", "pcm+lf", "pcm+lm", "ipc+lf", "ipc+lm", "gnc", "dcs"} <= set(by)
    for m, r in by.items():
        assert math.isfinite(r["ate"]), f"{m}: ATE {r['ate']}"
    for m in ("rover+lm", "pcm+lm", "ipc+lm"):
        assert math.isfinite(by[m]["tate"]), f"{m}: tATE {by[m]['tate']}"
    assert math.isfinite(info["ate_true_only_lm"])
    # every method is judged on the candidates the product could accept (none names the refused keyframe)
    judged = len(s.candidates) - (len(naming) if glitch else 0)
    for m in ("rover+lf", "pcm+lm", "gnc"):
        assert by[m]["tp"] + by[m]["fn"] + by[m]["fp"] <= judged
        assert by[m]["tp"] + by[m]["fn"] == info["true"]
    assert info["true"] + info["false"] == judged
