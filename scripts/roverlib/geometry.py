"""Poses as 4x4 homogeneous matrices (numpy); quaternions as (x, y, z, w)."""
import numpy as np


def quat_to_matrix(q):
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R):
    """Rotation matrix -> (x, y, z, w) with w >= 0."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = [0.0, 0.0, 0.0, (R[k, j] - R[j, k]) / s]
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def rot_z(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def pose(R=None, t=None):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = t
    return T


def pose_from_tq(t, q):
    return pose(quat_to_matrix(q), t)


def inv(T):
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def relative(Ta, Tb):
    """Pose of b in a's frame."""
    return inv(Ta) @ Tb


def yaw_of(R):
    """Yaw (Z-Y-X convention, as loop_fusion's R2ypr) in radians."""
    return float(np.arctan2(R[1, 0], R[0, 0]))


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def loop_yaw(R_match, R_rel):
    """loop_fusion's relative yaw of a loop (loop_info[7], here in radians): the difference of
    the world yaws of query and match, yaw(R_m R_rel) - yaw(R_m), wrapped; R_match is the match
    keyframe's VIO rotation, R_rel the query's rotation in the match frame. The 4-DoF graph
    compares it with yaw_q - yaw_m (core/pose_graph.cpp). It equals yaw_of(R_rel) only when R_m
    is a pure yaw (a planar body); on a tilted one (EuRoC's IMU) they differ by degrees."""
    return float(wrap(yaw_of(R_match @ R_rel) - yaw_of(R_match)))


def yaw_only(T):
    """The pose with its rotation reduced to the yaw (ZYX): loop_fusion's 4-DoF view of a pose
    whose roll and pitch the VIO keeps."""
    return pose(rot_z(yaw_of(T[:3, :3])), T[:3, 3])


def keyframes_by_distance(poses, min_distance, min_yaw=np.radians(15.0)):
    """Indices of poses kept as keyframes: a new one after moving min_distance or turning
    min_yaw (VINS selects keyframes by parallax; this is the geometric analogue)."""
    keep = [0]
    for i in range(1, len(poses)):
        a, b = poses[keep[-1]], poses[i]
        if (np.linalg.norm(b[:3, 3] - a[:3, 3]) >= min_distance or
                abs(wrap(yaw_of(b[:3, :3]) - yaw_of(a[:3, :3]))) >= min_yaw):
            keep.append(i)
    return keep
