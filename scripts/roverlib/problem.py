"""A pose graph as the Python back ends (roverlib/robust.py) and the incremental peers
(roverlib/peers.py) see it: vertices 0..n-1 along the odometry, odometry edges i -> i+1 and loop
candidates in verification order, every edge with a covariance in gtsam's tangent order.

  from_g2o       a g2o graph: its own information matrices (what every method gets);
  from_scenario  keyframes + candidates (simulated scenes, real runs): covariances from the one
                 drift model (roverlib/drift_model.py) of the environment; on the keyframes
                 rover_replay kept (its intake.csv: bench.intake), as the product saw them
                 (Problem.on_keyframes).

4-DoF (loop_fusion with an IMU) is a gtsam Pose3 graph whose poses and measurements are all
pure-yaw rotations (the VIO's roll and pitch are kept out of the graph, as loop_fusion does:
a candidate's relative translation is rotated by the match's full VIO rotation, then expressed
in its yaw-only frame); `dof` = 4 is what chi-square tests count.
"""
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from . import geometry as g


@dataclass
class Edge:
    a: int  # from (the match, for a loop)
    b: int  # to (the query)
    T: np.ndarray  # pose of b in a's frame, 4x4
    cov: np.ndarray  # tangent covariance: Pose2 (x, y, theta); Pose3 (rx, ry, rz, tx, ty, tz)
    label: int = -1  # loops: 1 true, 0 false
    keyframes: Optional[Tuple[int, int]] = None  # loops: (query, match) keyframe indices, if not (b, a)

    @property
    def pair(self):
        """(query, match) keyframe indices, as verdict logs and candidates.csv name a candidate."""
        return self.keyframes if self.keyframes is not None else (self.b, self.a)


@dataclass
class Problem:
    name: str
    dim: int  # 2: gtsam Pose2; 3: Pose3
    dof: int  # 3 (Pose2), 4 (Pose3, yaw-only rotations), 6
    odometry: List[Edge]  # edge i: i -> i+1
    loops: List[Edge]  # candidates, in verification order
    truth: Optional[List[np.ndarray]] = None
    meta: dict = field(default_factory=dict)
    # from_scenario: (scenario, drift model, mode), for on_keyframes
    source: Optional[tuple] = field(default=None, repr=False, compare=False)

    @property
    def n(self):
        return len(self.odometry) + 1

    def odometry_poses(self):
        poses = [np.eye(4)]
        for e in self.odometry:
            poses.append(poses[-1] @ e.T)
        return poses

    def labels(self):
        return np.array([e.label for e in self.loops], dtype=int)

    def on_keyframes(self, kept):
        """This problem built again from its scenario (from_scenario) on the keyframes whose
        indices are in `kept` (what rover_replay kept: bench.intake)."""
        if self.source is None:
            raise ValueError(f"{self.name}: not built from a scenario (from_scenario), it cannot leave keyframes out")
        s, model, mode = self.source
        return from_scenario(s, model, mode, set(kept))

    def subset(self, pairs):
        """The loops whose (query, match) is in `pairs`, in verification order."""
        pairs = set(pairs)
        return [e for e in self.loops if e.pair in pairs]


def _g2o_cov(info, dim):
    cov = np.linalg.inv(np.asarray(info, dtype=float))
    if dim == 3:  # g2o (t, r) -> gtsam (r, t), as gtsam's own g2o reader does
        P = np.zeros((6, 6))
        P[:3, 3:] = np.eye(3)
        P[3:, :3] = np.eye(3)
        cov = P @ cov @ P.T
    return 0.5 * (cov + cov.T)


def from_g2o(graph, candidates, truth=None, name=None):
    """`candidates`: [(g2o.Edge, label)] in verification order (g2o.ordered_candidates)."""
    odo = []
    for i, e in enumerate(graph.odometry):
        T = e.T if e.a == i else g.inv(e.T)
        odo.append(Edge(i, i + 1, T, _g2o_cov(e.info, graph.dim)))
    loops = [Edge(e.match, e.query, e.T_rel, _g2o_cov(e.info, graph.dim), label) for e, label in candidates]
    return Problem(name or graph.name, graph.dim, 3 if graph.dim == 2 else 6, odo, loops, truth)


def from_scenario(s, model, mode="4dof", kept=None):
    """Keyframes in order, candidates in rover_replay's order (by query keyframe, file order
    within one), drift-model covariances. `kept`: the keyframe indices rover_replay kept
    (bench.intake of its run; None: every keyframe). A refused keyframe is no vertex
    (the odometry edge goes from the kept keyframe before it to the one after it, as the
    product's graph has it) and a candidate that names one is no loop, as the product cannot
    accept it: the peers get the keyframes and candidates the product got. Vertices are the
    kept keyframes in order; Edge.pair names a loop by its keyframe indices."""
    dof = 4 if mode == "4dof" else 6
    indices = [k.index for k in s.keyframes]
    if len(set(indices)) != len(indices):
        raise ValueError(f"{s.name}: a keyframe index appears twice (vertices are named by keyframe index)")
    keyframes = s.keyframes if kept is None else [k for k in s.keyframes if k.index in kept]
    refused = set(indices) - {k.index for k in keyframes}
    pos = {k.index: i for i, k in enumerate(keyframes)}
    vio = [k.T for k in keyframes]
    poses = [g.yaw_only(T) for T in vio] if dof == 4 else vio
    odo = []
    for i in range(len(poses) - 1):
        T = g.relative(poses[i], poses[i + 1])
        odo.append(Edge(i, i + 1, T, model.step_covariance(np.linalg.norm(T[:3, 3]), dof)))
    loops = []
    for c in sorted(s.candidates, key=lambda c: c.query):
        if c.query in refused or c.match in refused:
            continue
        m, q = pos[c.match], pos[c.query]
        if dof == 4:
            R_m = vio[m][:3, :3]
            t = g.rot_z(g.yaw_of(R_m)).T @ (R_m @ c.T_rel[:3, 3])
            T = g.pose(g.rot_z(g.loop_yaw(R_m, c.T_rel[:3, :3])), t)
        else:
            T = c.T_rel
        loops.append(Edge(m, q, T, model.loop_covariance(dof), c.label, (c.query, c.match)))
    truth = None
    if s.truth is not None:
        truth = [g.yaw_only(T) if dof == 4 else T for k, T in zip(s.keyframes, s.truth) if k.index in pos]
    meta = {"drift_model": model.name}
    if refused:
        meta["refused_keyframes"] = sorted(refused)
    return Problem(s.name, 3, dof, odo, loops, truth, meta, (s, model, mode))
