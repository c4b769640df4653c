"""g2o parsing, pose-graph scenarios, outlier injection and the gtsam baselines."""
import numpy as np
import pytest

from conftest import shared_data
from roverlib import g2o, metrics, problem, robust
from roverlib import geometry as g

SMALL_SE2 = """# a square walked once, one loop back to the start, stored reversed (newer -> older)
VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0
EDGE_SE2 0 1 1 0 0 10 0 0 10 0 20
EDGE_SE2 1 2 1 0 1.5707963267948966 10 0 0 10 0 20
EDGE_SE2 3 2 -1 0 0 10 0 0 10 0 20
EDGE_SE2 3 4 1 0 1.5707963267948966 10 0 0 10 0 20
EDGE_SE2 4 0 0.1 0.2 0.3 5 1 0 6 0 7
"""


def _data(name):
    with shared_data():
        return g2o.load(name)


def test_parse_se2_odometry_loops_and_information(tmp_path):
    p = tmp_path / "small.g2o"
    p.write_text(SMALL_SE2)
    G = g2o.read(str(p))
    assert (G.dim, G.n, len(G.odometry), len(G.loops)) == (2, 5, 4, 1)
    poses = G.odometry_poses()
    # 1 m forward, turn left after vertex 1, the reversed edge 3 -> 2 is inverted
    assert np.allclose(poses[2][:3, 3], [2, 0, 0]) and np.isclose(g.yaw_of(poses[2][:3, :3]), np.pi / 2)
    assert np.allclose(poses[3][:3, 3], [2, 1, 0])
    loop = G.loops[0]
    assert (loop.query, loop.match) == (4, 0)
    assert np.allclose(loop.T_rel, g.inv(g2o.se2(0.1, 0.2, 0.3)))
    assert np.allclose(loop.info, [[5, 1, 0], [1, 6, 0], [0, 0, 7]])
    assert np.allclose(G.vertices[1][:3, 3], [1, 0, 0])


def test_parse_se3_quat(tmp_path):
    q = g.matrix_to_quat(g.rot_z(0.5))
    info = " ".join(["1 0 0 0 0 0", "1 0 0 0 0", "1 0 0 0", "1 0 0", "1 0", "1"])
    lines = [f"EDGE_SE3:QUAT {i} {i + 1} 1 0 0 {q[0]} {q[1]} {q[2]} {q[3]} {info}" for i in range(12)]
    lines.append(f"EDGE_SE3:QUAT 0 12 0 0.5 3 0 0 0 1 {info}")
    p = tmp_path / "s.g2o"
    p.write_text("\n".join(lines) + "\n")
    G = g2o.read(str(p))
    assert (G.dim, G.n, len(G.loops)) == (3, 13, 1)
    assert np.allclose(G.loops[0].T_rel[:3, 3], [0, 0.5, 3]) and np.allclose(G.loops[0].info, np.eye(6))
    assert np.isclose(g.yaw_of(G.odometry_poses()[2][:3, :3]), 1.0)


@pytest.mark.parametrize("text,message", [
    ("EDGE_SE2 0 1 1 0\n", "small.g2o:1: EDGE_SE2 needs"),
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nFOO 1 2\n", "small.g2o:2: unsupported element FOO"),
    ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n", "between vertices 1 and 2"),
    ("EDGE_SE2 0 1 x 0 0 1 0 0 1 0 1\n", "small.g2o:1"),
])
def test_parse_errors_name_file_and_line(tmp_path, text, message):
    p = tmp_path / "small.g2o"
    p.write_text(text)
    with pytest.raises(ValueError, match=message):
        g2o.read(str(p))


def test_shared_graphs_and_ground_truth():
    ring = _data("ring")
    assert (ring.n, len(ring.loops)) == (434, 26)
    # the file's vertices are its odometry
    assert np.allclose(ring.odometry_poses()[200][:3, 3], ring.vertices[200][:3, 3], atol=1e-4)
    for name, n, loops in (("manhattan3500", 3500, 2099), ("kitti_00", 4541, 137)):
        G = _data(name)
        assert (G.n, len(G.loops)) == (n, loops)
        gt = g2o.groundtruth(name, G.n)
        assert len(gt) == n and all(abs(T[2, 3]) < 1e-12 for T in gt)
        # true loops agree with the ground truth (to a few decimetres)
        errs = [np.linalg.norm(g.relative(gt[e.match], gt[e.query])[:3, 3] - e.T_rel[:3, 3]) for e in G.loops[:50]]
        assert np.median(errs) < 0.5, name
    assert g2o.groundtruth("parking-garage", 1661) is None


@pytest.mark.parametrize("kind", g2o.OUTLIER_KINDS)
def test_outlier_injection_properties(kind):
    G = _data("manhattan3500")
    gt = g2o.groundtruth("manhattan3500", G.n)
    true_loops = g2o.subsample_loops(G, 100)
    out = g2o.inject_outliers(G, len(true_loops), kind, 0.5, gt)
    assert len(out) == 100
    assert len(g2o.inject_outliers(G, len(true_loops), kind, 0.2, gt)) == 25
    again = g2o.inject_outliers(G, len(true_loops), kind, 0.5, gt)
    assert [(e.match, e.query) for e in out] == [(e.match, e.query) for e in again], "fixed seed"
    pairs = {(e.match, e.query) for e in out}
    assert len(pairs) == len(out) and not pairs & {(e.match, e.query) for e in G.loops}
    for e in out:
        assert e.a == e.match < e.query == e.b
        err = np.linalg.norm(g.relative(gt[e.match], gt[e.query])[:3, 3] - e.T_rel[:3, 3])
        assert err >= (0.9 if kind == "near" else 1.5), "an outlier is wrong by metres"
        span = e.query - e.match
        if kind == "local":
            assert 5 <= span <= 30
        else:
            assert span >= 10
        if kind != "grouped":
            assert abs(g.yaw_of(e.T_rel[:3, :3])) < np.radians(30.0) and np.linalg.norm(e.T_rel[:3, 3]) < 5.0
        if kind == "near":
            assert err >= 0.9 and np.linalg.norm(e.T_rel[:3, 3]) < 1.5
        if kind == "repetitive":
            d = np.linalg.norm(gt[e.query][:3, 3] - gt[e.match][:3, 3])
            assert 3.0 <= d <= 15.0
            assert abs(g.wrap(g.yaw_of(gt[e.query][:3, :3]) - g.yaw_of(gt[e.match][:3, :3]))) < np.radians(30.0)
    if kind == "grouped":
        odo = G.odometry_poses()
        for a, b in zip(out[:-1], out[1:]):
            if b.match == a.match + 1 and b.query == a.query + 1:
                # consecutive members agree with each other through the odometry
                predicted = g.inv(g.relative(odo[a.match], odo[b.match])) @ a.T_rel @ g.relative(odo[a.query], odo[b.query])
                assert np.allclose(predicted, b.T_rel, atol=1e-9)
        starts = sum(1 for a, b in zip(out[:-1], out[1:]) if not (b.match == a.match + 1 and b.query == a.query + 1))
        assert starts + 1 == 10, "ten groups of ten"


def test_scenario_order_and_labels():
    G = _data("ring")
    gt = g2o.groundtruth("ring", G.n)
    out = g2o.inject_outliers(G, len(G.loops), "random", 0.2, gt)
    s = g2o.to_scenario(G, G.loops, out, gt)
    assert [c.query for c in s.candidates] == sorted(c.query for c in s.candidates)
    assert sum(c.label == 1 for c in s.candidates) == 26 and sum(c.label == 0 for c in s.candidates) == len(out)
    assert [k.index for k in s.keyframes] == list(range(G.n))


def test_gtsam_baselines_on_ring():
    G = _data("ring")
    gt = g2o.groundtruth("ring", G.n)
    ref = metrics.trajectory(np.arange(G.n, dtype=float), [T[:3, 3] for T in gt])

    def ate(poses):
        return metrics.ate(ref, metrics.trajectory(np.arange(G.n, dtype=float), [T[:3, 3] for T in poses]))

    out = g2o.inject_outliers(G, len(G.loops), "repetitive", 0.2, gt)
    p = problem.from_g2o(G, g2o.ordered_candidates(G.loops, out), gt)
    odo = p.odometry_poses()
    assert np.allclose(odo[200][:3, 3], G.odometry_poses()[200][:3, 3])
    lm = robust.solve_lm(p, p.subset({(e.query, e.match) for e in G.loops}))
    assert ate(lm) < 0.5 * ate(odo)
    poses, accepted = robust.solve_gnc(p, p.loops)
    assert len(accepted) == len(p.loops)
    assert not any(a for a, e in zip(accepted, p.loops) if e.label == 0), "GNC drops these outliers"
    assert ate(poses) == pytest.approx(ate(lm), rel=0.05)


def test_near_outliers_are_rows_of_agreeing_look_alikes_one_before_the_first_true_loop():
    G = _data("kitti_00")
    gt = g2o.groundtruth("kitti_00", G.n)
    first = min(e.query for e in G.loops)
    out = g2o.inject_outliers(G, len(G.loops), "near", 0.2, gt, seed=3, first_true_query=first)
    assert len(out) == round(len(G.loops) * 0.25)
    assert max(e.query for e in out[:g2o.ROW_SIZE]) < first, "the first row comes before the first true loop"
    for k in range(0, len(out) - g2o.ROW_SIZE + 1, g2o.ROW_SIZE):
        row = out[k:k + g2o.ROW_SIZE]
        assert [e.query for e in row] == list(range(row[0].query, row[0].query + g2o.ROW_SIZE))
        # each claims its query is at the true place + the same offset w, 1-3 m long
        w = [(gt[e.match] @ e.T_rel)[:3, 3] - gt[e.query][:3, 3] for e in row]
        assert all(np.allclose(x, w[0], atol=1e-6) for x in w) and 1.0 <= np.linalg.norm(w[0]) <= 3.0
