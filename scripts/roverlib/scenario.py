"""Scenario directories (docs/scenario-format.md): keyframes, labelled candidates, truth."""
import csv
import os
from dataclasses import dataclass, field
from typing import List, Optional

import numpy as np

from . import geometry as g

KEYFRAMES_HEADER = "index,stamp,sequence,x,y,z,qx,qy,qz,qw"
CANDIDATES_HEADER = "query_index,match_index,tx,ty,tz,qx,qy,qz,qw,relative_yaw,inliers,label"
TRUTH_HEADER = "index,x,y,z,qx,qy,qz,qw"
ODOMETRY_HEADER = "index,xx,xy,xz,xyaw,yy,yz,yyaw,zz,zyaw,yawyaw"


@dataclass
class Keyframe:
    index: int
    stamp: float
    sequence: int
    T: np.ndarray  # VIO pose, 4x4


@dataclass
class Candidate:
    query: int
    match: int
    T_rel: np.ndarray  # query in match frame, 4x4
    label: int  # 1 true, 0 false, -1 unknown
    inliers: int = -1
    kind: str = ""  # how it was made (revisit, lookalike, random); not written

    def relative_yaw(self, T_match):
        """loop_fusion's relative yaw [rad] (loop_info[7]): the difference of world yaws
        (geometry.loop_yaw), which needs T_match, the match keyframe's VIO pose; not the yaw
        of T_rel, which differs from it on a tilted body."""
        return g.loop_yaw(T_match[:3, :3], self.T_rel[:3, :3])


@dataclass
class Scenario:
    name: str
    keyframes: List[Keyframe]
    candidates: List[Candidate]
    truth: Optional[List[np.ndarray]] = None  # per keyframe, same order
    meta: dict = field(default_factory=dict)  # mode, alignment, threshold hints, provenance
    # Optional odometry.csv: keyframe index -> 4x4 covariance (x, y, z, yaw in that keyframe's
    # frame) of the odometry step that ends at it, where the data carries one (g2o files).
    step_covariance: Optional[dict] = None

    def relative_yaws(self):
        """loop_fusion's relative yaw [rad] of each candidate, in candidate order."""
        vio = {k.index: k.T for k in self.keyframes}
        unknown = [c.match for c in self.candidates if c.match not in vio]
        if unknown:
            raise ValueError(f"{self.name}: candidates name unknown match keyframes {sorted(set(unknown))[:5]}")
        return [c.relative_yaw(vio[c.match]) for c in self.candidates]


def _tq(T):
    return list(T[:3, 3]) + list(g.matrix_to_quat(T[:3, :3]))


def write(s: Scenario, directory: str):
    os.makedirs(directory, exist_ok=True)
    with open(os.path.join(directory, "keyframes.csv"), "w") as f:
        f.write(f"# scenario {s.name}\n" + "".join(f"# {k}: {v}\n" for k, v in sorted(s.meta.items())))
        f.write(KEYFRAMES_HEADER + "\n")
        for k in s.keyframes:
            f.write(",".join([str(k.index), f"{k.stamp:.9f}", str(k.sequence)] +
                             [f"{v:.9f}" for v in _tq(k.T)]) + "\n")
    with open(os.path.join(directory, "candidates.csv"), "w") as f:
        f.write(CANDIDATES_HEADER + "\n")
        for c, yaw in sorted(zip(s.candidates, s.relative_yaws()), key=lambda e: e[0].query):
            f.write(",".join([str(c.query), str(c.match)] + [f"{v:.9f}" for v in _tq(c.T_rel)] +
                             [f"{yaw:.9f}", str(c.inliers), str(c.label)]) + "\n")
    if s.step_covariance:
        iu = np.triu_indices(4)
        with open(os.path.join(directory, "odometry.csv"), "w") as f:
            f.write(ODOMETRY_HEADER + "\n")
            for index in sorted(s.step_covariance):
                C = np.asarray(s.step_covariance[index], dtype=float)
                f.write(",".join([str(index)] + [f"{v:.12g}" for v in C[iu]]) + "\n")
    if s.truth is not None:
        with open(os.path.join(directory, "groundtruth.csv"), "w") as f:
            f.write(TRUTH_HEADER + "\n")
            for k, T in zip(s.keyframes, s.truth):
                f.write(",".join([str(k.index)] + [f"{v:.9f}" for v in _tq(T)]) + "\n")


def _rows(path, header):
    with open(path) as f:
        lines = [l for l in f if l.strip() and not l.lstrip().startswith("#")]
    if not lines or lines[0].strip() != header:
        raise ValueError(f"{path}: expected the header '{header}'")
    return list(csv.reader(lines[1:]))


def read(directory: str) -> Scenario:
    kfs = [Keyframe(int(r[0]), float(r[1]), int(r[2]),
                    g.pose_from_tq([float(v) for v in r[3:6]], [float(v) for v in r[6:10]]))
           for r in _rows(os.path.join(directory, "keyframes.csv"), KEYFRAMES_HEADER)]
    cands = [Candidate(int(r[0]), int(r[1]),
                       g.pose_from_tq([float(v) for v in r[2:5]], [float(v) for v in r[5:9]]),
                       int(r[11]), int(r[10]))
             for r in _rows(os.path.join(directory, "candidates.csv"), CANDIDATES_HEADER)]
    truth = None
    gt_path = os.path.join(directory, "groundtruth.csv")
    if os.path.exists(gt_path):
        by_index = {int(r[0]): g.pose_from_tq([float(v) for v in r[1:4]], [float(v) for v in r[4:8]])
                    for r in _rows(gt_path, TRUTH_HEADER)}
        truth = [by_index.get(k.index) for k in kfs]
    step_covariance = None
    odo_path = os.path.join(directory, "odometry.csv")
    if os.path.exists(odo_path):
        step_covariance = {}
        for r in _rows(odo_path, ODOMETRY_HEADER):
            C = np.zeros((4, 4))
            C[np.triu_indices(4)] = [float(v) for v in r[1:11]]
            step_covariance[int(r[0])] = C + np.triu(C, 1).T
    return Scenario(os.path.basename(os.path.normpath(directory)), kfs, cands, truth,
                    step_covariance=step_covariance)
