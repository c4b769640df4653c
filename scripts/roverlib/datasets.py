"""The data sets in ../shared/data that the real-drift scenarios (roverlib/real_data.py), the KITTI
route scenes (roverlib/scenes.py) and the pose graphs (roverlib/g2o.py) read: where they are
(ROVER_SHARED_DATA overrides), how a missing file is reported (MissingData, a
FileNotFoundError that names it), and the readers of their TUM and KITTI trajectory files.

A user's clone has no ../shared: whatever needs these files raises MissingData, and the tests
that need them skip, naming the file (test/python/conftest.py)."""
import os

import numpy as np

from . import geometry as g

DATA = os.environ.get("ROVER_SHARED_DATA",
                      os.path.join(os.path.dirname(os.path.realpath(__file__)), "..", "..", "..", "shared", "data"))

# KITTI camera frame (x right, y down, z forward) -> z-up, x-forward frame.
_KITTI = g.pose(np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]))


class MissingData(FileNotFoundError):
    """A file of ../shared/data is not there (str(e) names it)."""


def data_path(rel):
    """The path of `rel` under ../shared/data (an absolute `rel` as it is); MissingData if it
    does not exist."""
    p = os.path.normpath(os.path.join(DATA, rel))
    if not os.path.exists(p):
        raise MissingData(f"{p} not found: the real data is read from ../shared/data "
                          f"(or set ROVER_SHARED_DATA)")
    return p


def load_tum(file):
    """(stamps, 4x4 poses) of a TUM trajectory file (stamp tx ty tz qx qy qz qw)."""
    a = np.loadtxt(file, comments="#")
    return a[:, 0], [g.pose_from_tq(r[1:4], r[4:8]) for r in a]


def load_kitti(file, dt=0.1):
    """(stamps every dt, 4x4 poses in a z-up, x-forward frame) of a KITTI pose file (3x4 rows)."""
    a = np.loadtxt(file)
    poses = []
    for r in a:
        T = g.pose(r.reshape(3, 4)[:, :3], r.reshape(3, 4)[:, 3])
        poses.append(_KITTI @ T @ g.inv(_KITTI))
    return np.arange(len(poses)) * dt, poses
