"""Pose graphs in g2o format (../shared/data/posegraphs) as verifier scenarios, and outlier
loop closures injected into them.

A graph becomes what a verifier would see: keyframes = the odometry chain composed from the
edges between consecutive vertex ids (the "VIO"), true loop candidates = every other edge
(query = the later vertex, relative pose from the file), false candidates = injected outliers
(label 0). Candidates are verified in the order of their query vertex.

Outlier kinds (fixed seed), each a plausible relative pose (what a place recognition + PnP
front end would hand over: translation of about one odometry step, |yaw| < 30 deg) between
vertices whose true relative pose differs from it by at least `min_error` metres:
  random      any pair of vertices (span >= 10);
  local       pairs close in time (span 5 .. 30 vertices);
  grouped     groups of 10 consecutive pairs (q0+k, m0+k) that agree with each other and with
              the odometry (one wrong alignment of two stretches: a consistent false revisit);
  repetitive  a small relative pose between places 3 .. 15 m apart in truth, facing the same
              way within 30 deg (a look-alike place: the case this project exists for);
  near        near look-alikes in rows: the relative pose PnP returns at a look-alike 1 .. 3 m
              from the query's true place (2D: sideways or along the road; 3D: on the floor
              above or below, 1 .. 3.5 m), for ROW_SIZE consecutive queries at one offset (they
              agree with each other and with the odometry), the first row before the first
              true loop.
Outlier fraction p = outliers / (true + outliers).
"""
import os
from dataclasses import dataclass, field
from typing import List

import numpy as np

from . import geometry as g
from . import datasets
from .scenario import Candidate, Keyframe, Scenario

OUTLIER_KINDS = ("random", "local", "grouped", "repetitive", "near")
GROUP_SIZE = 10
ROW_SIZE = 5
NEAR_RADIUS = 1.0  # m: a look-alike's match is this close to the look-alike place

# name -> g2o file under ../shared/data (ground truth: groundtruth())
GRAPHS = {
    "manhattan3500": "posegraphs/manhattan3500.g2o",
    "ringCity": "posegraphs/ringCity.g2o",
    "ring": "posegraphs/ring.g2o",
    "kitti_00": "posegraphs/kitti_00.g2o",
    "parking-garage": "posegraphs/parking-garage.g2o",
}


@dataclass
class Edge:
    a: int
    b: int
    T: np.ndarray  # pose of b in a's frame (the g2o measurement), 4x4
    info: np.ndarray  # g2o information matrix: (x, y, theta) or (x, y, z, qx, qy, qz)

    @property
    def query(self):
        return max(self.a, self.b)

    @property
    def match(self):
        return min(self.a, self.b)

    @property
    def T_rel(self):
        """Pose of the query (later) vertex in the match's frame."""
        return self.T if self.a == self.match else g.inv(self.T)


@dataclass
class Graph:
    name: str
    dim: int  # 2 (SE2) or 3 (SE3)
    n: int  # vertices 0..n-1
    odometry: List[Edge]  # edge i connects i and i+1 (as in the file, a may be i+1)
    loops: List[Edge]
    vertices: dict = field(default_factory=dict)  # initial guesses in the file (may be empty)

    def odometry_poses(self):
        """The odometry chain composed from vertex 0 at the identity."""
        poses = [np.eye(4)]
        for i, e in enumerate(self.odometry):
            step = e.T if e.a == i else g.inv(e.T)
            poses.append(poses[-1] @ step)
        return poses

    def loop_info(self):
        """Information matrix given to injected outliers: the most common one of the file's loops."""
        keys = [tuple(np.round(e.info.ravel(), 9)) for e in self.loops]
        values, counts = np.unique(np.array(keys), axis=0, return_counts=True)
        k = values[int(np.argmax(counts))]
        return np.array(k).reshape(self.loops[0].info.shape)


def _symmetric(upper, dim):
    M = np.zeros((dim, dim))
    M[np.triu_indices(dim)] = upper
    return M + np.triu(M, 1).T


def se2(x, y, theta):
    return g.pose(g.rot_z(theta), [x, y, 0.0])


def read(path, name=None):
    """Parses VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT lines; raises ValueError
    with file:line on anything else that is not a comment, and if the odometry chain (edges
    between consecutive ids) does not connect every vertex."""
    edges, vertices, dim = [], {}, None
    with open(path) as f:
        for ln, line in enumerate(f, 1):
            p = line.split()
            if not p or p[0].startswith("#"):
                continue
            try:
                if p[0] == "VERTEX_SE2":
                    vertices[int(p[1])] = se2(*map(float, p[2:5]))
                    d = 2
                elif p[0] == "VERTEX_SE3:QUAT":
                    vertices[int(p[1])] = g.pose_from_tq(list(map(float, p[2:5])), list(map(float, p[5:9])))
                    d = 3
                elif p[0] == "EDGE_SE2":
                    v = list(map(float, p[3:12]))
                    if len(v) != 9:
                        raise ValueError("EDGE_SE2 needs 3 + 6 numbers")
                    edges.append(Edge(int(p[1]), int(p[2]), se2(*v[:3]), _symmetric(v[3:], 3)))
                    d = 2
                elif p[0] == "EDGE_SE3:QUAT":
                    v = list(map(float, p[3:31]))
                    if len(v) != 28:
                        raise ValueError("EDGE_SE3:QUAT needs 7 + 21 numbers")
                    edges.append(Edge(int(p[1]), int(p[2]), g.pose_from_tq(v[:3], v[3:7]), _symmetric(v[7:], 6)))
                    d = 3
                else:
                    raise ValueError(f"unsupported element {p[0]}")
            except (ValueError, IndexError) as e:
                raise ValueError(f"{path}:{ln}: {e}") from None
            if dim is None:
                dim = d
            elif d != dim:
                raise ValueError(f"{path}:{ln}: mixes 2D and 3D elements")
    if not edges:
        raise ValueError(f"{path}: no edges")
    n = 1 + max(max(max(e.a, e.b) for e in edges), max(vertices) if vertices else 0)
    odo = [None] * (n - 1)
    loops = []
    for e in edges:
        if abs(e.a - e.b) == 1 and odo[e.match] is None:
            odo[e.match] = e
        else:
            loops.append(e)
    missing = [i for i, e in enumerate(odo) if e is None]
    if missing:
        raise ValueError(f"{path}: no odometry edge between vertices {missing[0]} and {missing[0] + 1}")
    return Graph(name or os.path.splitext(os.path.basename(path))[0], dim, n, odo, loops, vertices)


def load(name):
    return read(datasets.data_path(GRAPHS[name]), name)


def groundtruth(name, n):
    """Ground-truth poses (4x4, z = 0 for the planar graphs) of vertices 0..n-1, or None
    (parking-garage has none)."""
    if name == "manhattan3500":
        a = np.loadtxt(datasets.data_path("posegraphs/manhattan3500_groundtruth_nodes.dat"))
        poses = [se2(*r) for r in a]
    elif name in ("ringCity", "ring"):
        a = np.loadtxt(datasets.data_path(f"posegraphs/{name}_groundtruth_poses.txt"))
        by_id = {int(r[0]): se2(*r[1:4]) for r in a}
        poses = [by_id[i] for i in range(n)]
    elif name == "kitti_00":
        # node i = row i of the KITTI ground truth, planar: x = z_cam, y = -x_cam (datasets'
        # z-up conversion), heading = yaw; height dropped like the 2D graph does.
        _, kitti = datasets.load_kitti(datasets.data_path("kitti/00_groundtruth.txt"))
        poses = [se2(T[0, 3], T[1, 3], g.yaw_of(T[:3, :3])) for T in kitti]
    else:
        return None
    if len(poses) < n:
        raise ValueError(f"{name}: ground truth has {len(poses)} poses for {n} vertices")
    return poses[:n]


def subsample_loops(graph, max_loops, seed=0):
    """At most max_loops of the graph's loops (fixed seed), in file order."""
    if max_loops is None or len(graph.loops) <= max_loops:
        return list(graph.loops)
    rng = np.random.default_rng(seed)
    keep = np.sort(rng.choice(len(graph.loops), max_loops, replace=False))
    return [graph.loops[i] for i in keep]


def _plausible_pose(rng, dim, step, sigma_t=1.0, sigma_yaw_deg=10.0):
    yaw = float(np.clip(rng.normal(0.0, np.radians(sigma_yaw_deg)), -np.radians(29.0), np.radians(29.0)))
    t = rng.normal(0.0, sigma_t * step, 3)
    if dim == 2:
        t[2] = 0.0
        return g.pose(g.rot_z(yaw), t)
    t[2] *= 0.2
    R = g.rot_z(yaw) @ g.rot_x(rng.normal(0.0, np.radians(2.0))) @ g.rot_y(rng.normal(0.0, np.radians(2.0)))
    return g.pose(R, t)


def inject_outliers(graph, n_true, kind, fraction, places, seed=0, min_error=1.5, distance=(3.0, 15.0),
                    first_true_query=None):
    """Outlier edges (list of Edge, a = match, b = query) of one kind. `places`: 4x4 truth (or
    reference) poses of the vertices, used to make sure every outlier is wrong by at least
    `min_error` metres (`near`: 1 m) and to find look-alike places for `repetitive` and `near`
    (whose first row ends before `first_true_query`). The count is
    round(n_true * fraction / (1 - fraction))."""
    if kind not in OUTLIER_KINDS:
        raise ValueError(f"unknown outlier kind {kind}")
    if not 0.0 <= fraction < 1.0:
        raise ValueError("fraction must be in [0, 1)")
    count = int(round(n_true * fraction / (1.0 - fraction)))
    rng = np.random.default_rng([seed, OUTLIER_KINDS.index(kind), int(round(fraction * 1000))])
    n = graph.n
    odo = graph.odometry_poses()
    P = np.array([T[:3, 3] for T in places])
    Y = np.array([g.yaw_of(T[:3, :3]) for T in places])
    steps = [np.linalg.norm(e.T[:3, 3]) for e in graph.odometry]
    step = float(np.median(steps)) if steps else 1.0
    info = graph.loop_info()
    taken = {(e.match, e.query) for e in graph.loops}
    out = []

    def wrong_enough(m, q, T):
        truth = g.relative(places[m], places[q])
        return np.linalg.norm(truth[:3, 3] - T[:3, 3]) >= min_error

    def add(m, q, T):
        taken.add((m, q))
        out.append(Edge(m, q, T, info.copy()))

    if kind == "near":
        min_error = min(min_error, 0.9)
    tries = 0
    while len(out) < count and tries < 200 * max(count, 1):
        tries += 1
        if kind == "random":
            q = int(rng.integers(10, n))
            m = int(rng.integers(0, q - 9))
        elif kind == "local":
            q = int(rng.integers(30, n))
            m = q - int(rng.integers(5, 31))
        elif kind == "repetitive":
            q = int(rng.integers(10, n))
            d = np.linalg.norm(P[:q - 9] - P[q], axis=1)
            ok = np.flatnonzero((d >= distance[0]) & (d <= distance[1]) &
                                (np.abs(g.wrap(Y[:q - 9] - Y[q])) < np.radians(30.0)))
            if ok.size == 0:
                continue
            m = int(rng.choice(ok))
        elif kind == "near":
            size = min(ROW_SIZE, count - len(out))
            # the first row before the first true loop, while such a row can be found
            first = not out and first_true_query is not None and tries < 50 * max(count, 1)
            hi = (first_true_query - size) if first else n - size
            if hi <= 10:
                continue
            row = _near_row(rng, P, Y, int(rng.integers(10, hi)), size, graph.dim)
            if row is None or any((m, q) in taken for m, q, _ in row):
                continue
            group = [(m, q, g.relative(places[m], g.pose(places[q][:3, :3], places[q][:3, 3] + w))) for m, q, w in row]
            if not all(wrong_enough(m, q, T) for m, q, T in group):
                continue
            for m, q, T in group:
                add(m, q, T)
            continue
        else:  # grouped
            size = min(GROUP_SIZE, count - len(out))
            q0 = int(rng.integers(10, n - size))
            m0 = int(rng.integers(0, q0 - 9 - size)) if q0 - 9 - size > 0 else -1
            if m0 < 0:
                continue
            T0 = _plausible_pose(rng, graph.dim, step)
            group = []
            for k in range(size):
                # consistent with T0 and the odometry: the two stretches moved as one
                Tk = g.relative(odo[m0], odo[m0 + k]) if k else np.eye(4)
                Tk = g.inv(Tk) @ T0 @ g.relative(odo[q0], odo[q0 + k])
                group.append((m0 + k, q0 + k, Tk))
            if any((m, q) in taken or not wrong_enough(m, q, T) for m, q, T in group):
                continue
            for m, q, T in group:
                add(m, q, T)
            continue
        T = _plausible_pose(rng, graph.dim, step, sigma_t=0.3 if kind == "repetitive" else 1.0,
                            sigma_yaw_deg=5.0 if kind == "repetitive" else 10.0)
        if (m, q) in taken or not wrong_enough(m, q, T):
            continue
        add(m, q, T)
    if len(out) < count:
        raise RuntimeError(f"{graph.name}: could only place {len(out)} of {count} {kind} outliers")
    return out


def _near_row(rng, P, Y, q0, size, dim):
    """[(match, query, offset)] for queries q0 .. q0+size-1: one offset w (from q0 to an older
    place 1-3 m away, 2D; on another floor, 3D) and, for each query, the older vertex nearest to
    its place + w (within NEAR_RADIUS, facing the same way); None if a query has none."""
    older = np.arange(0, q0 - 9)
    v = P[older] - P[q0]
    same_way = np.abs(g.wrap(Y[older] - Y[q0])) < np.radians(30.0)
    if dim == 2:
        ok = same_way & (np.linalg.norm(v, axis=1) >= 1.0) & (np.linalg.norm(v, axis=1) <= 3.0)
    else:
        ok = same_way & (np.linalg.norm(v[:, :2], axis=1) <= NEAR_RADIUS) & (np.abs(v[:, 2]) >= 1.0) & \
            (np.abs(v[:, 2]) <= 3.5)
    if not ok.any():
        return None
    w = v[int(rng.choice(np.flatnonzero(ok)))]
    row = []
    for q in range(q0, q0 + size):
        older = np.arange(0, q - 9)
        d = np.linalg.norm(P[older] - (P[q] + w), axis=1)
        d[np.abs(g.wrap(Y[older] - Y[q])) >= np.radians(30.0)] = np.inf
        k = int(np.argmin(d))
        if d[k] > NEAR_RADIUS:
            return None
        row.append((int(older[k]), q, w))
    return row


def ordered_candidates(true_loops, outliers, seed=0):
    """[(Edge, label)] in verification order: by query vertex, random order within one query
    (fixed seed); the order of to_scenario's candidates and of every method."""
    both = [(e, 1) for e in true_loops] + [(e, 0) for e in outliers]
    order = np.random.default_rng(seed).permutation(len(both))
    return sorted((both[i] for i in order), key=lambda x: x[0].query)


def to_scenario(graph, true_loops, outliers, truth=None, seed=0, meta=None):
    """A Scenario: keyframes = odometry chain (stamp = vertex id), candidates = true loops
    (label 1) + outliers (label 0) sorted by query vertex (random order within one query)."""
    kfs = [Keyframe(i, float(i), 1, T) for i, T in enumerate(graph.odometry_poses())]
    cands = [Candidate(e.query, e.match, e.T_rel, label, 40, "loop" if label else "outlier")
             for e, label in ordered_candidates(true_loops, outliers, seed)]
    m = {"source": GRAPHS.get(graph.name, graph.name), "mode": "4dof" if graph.dim == 2 else "6dof",
         "true_candidates": len(true_loops), "false_candidates": len(outliers)}
    m.update(meta or {})
    return Scenario(graph.name, kfs, cands, truth, m, step_covariance=step_covariances(graph))


# A 2-D graph has no z: its steps get this variance in z [m^2] (z stays 0, so it only keeps the
# covariance positive definite).
PLANAR_Z_VARIANCE = 1e-6


def step_covariances(graph):
    """{i + 1: the covariance of odometry edge i -> i + 1} in the verifier's step order (x, y, z,
    yaw in the frame of vertex i + 1: g2o's error is a right perturbation of the measurement),
    from the file's information: what the verifier's uncertainty uses instead of a drift model
    (rover_replay reads them from odometry.csv)."""
    out = {}
    for i, e in enumerate(graph.odometry):
        cov = np.linalg.inv(np.asarray(e.info, dtype=float))
        cov = 0.5 * (cov + cov.T)
        C = np.zeros((4, 4))
        if graph.dim == 2:  # (x, y, theta)
            idx = [0, 1, 2]
            C[np.ix_([0, 1, 3], [0, 1, 3])] = cov[np.ix_(idx, idx)]
            C[2, 2] = PLANAR_Z_VARIANCE
        else:  # (x, y, z, qx, qy, qz): the rotation block read as gtsam's g2o reader reads it
            idx = [0, 1, 2, 5]
            C = cov[np.ix_(idx, idx)]
        out[i + 1] = C
    return out
