"""Simulated scenes: ground truth, VIO-like drifting odometry, labelled loop candidates.

The paper's proof-of-concept scenes (Room, Sports ground, Warehouse) plus a corridor loop and
a parking deck. Every scene knows its look-alike places ("twins"): the spot a feature matcher
confuses with the true one (the mirror-symmetric side of a room or track, the neighbouring
aisle, the same spot one floor over). False candidates pair a keyframe with a keyframe at
its twin and report the small relative pose PnP would return there.

Odometry noise level sigma (the paper's sigma): per keyframe step of length l the relative
translation gets N(0, (sigma*l)^2) per horizontal axis (half that vertically) and the relative
yaw N(0, (0.05*sigma*l)^2) rad; 6-DoF scenes also drift in roll and pitch.
"""
from dataclasses import dataclass
from typing import Callable, List

import numpy as np

from . import geometry as g
from .scenario import Candidate, Keyframe, Scenario

YAW_NOISE_PER_METRE = 0.05  # rad per metre travelled, per unit sigma


@dataclass
class Path:
    name: str
    truth: List[np.ndarray]
    twins: Callable[[np.ndarray], List[np.ndarray]]  # pose -> look-alike poses elsewhere
    dt: float = 0.5  # seconds between keyframes


def sample_polyline(points, step, z=None):
    """Keyframe poses every `step` metres along a polyline of (x, y[, z]) points, facing along it."""
    pts = np.array([p if len(p) == 3 else (p[0], p[1], 0.0) for p in points], dtype=float)
    poses, carry = [], 0.0
    for a, b in zip(pts[:-1], pts[1:]):
        d = b - a
        length = np.linalg.norm(d)
        if length < 1e-9:
            continue
        yaw = np.arctan2(d[1], d[0])
        s = carry
        while s < length:
            poses.append(g.pose(g.rot_z(yaw), a + d * (s / length)))
            s += step
        carry = s - length
    return poses


def rectangle(x0, y0, w, h):
    return [(x0, y0), (x0 + w, y0), (x0 + w, y0 + h), (x0, y0 + h), (x0, y0)]


def _mirror(center):
    c = np.asarray(center, dtype=float)

    def twins(T):
        p = T[:3, 3]
        q = np.array([2 * c[0] - p[0], 2 * c[1] - p[1], p[2]])
        return [g.pose(g.rot_z(g.yaw_of(T[:3, :3]) + np.pi), q)]
    return twins


def room(rng, laps=8, step=0.25):
    """An 8 m x 6 m room walked around 1 m from the walls, each lap a little off the last.
    Look-alike: the point-symmetric spot (a symmetric room looks the same from across)."""
    pts = []
    for _ in range(laps):
        o = rng.uniform(-0.25, 0.25)
        pts += rectangle(1.0 + o, 1.0 + o, 6.0 - 2 * o, 4.0 - 2 * o)[:-1]
    pts.append(pts[0])
    return Path("room", sample_polyline(pts, step), _mirror((4.0, 3.0)))


def sports_ground(rng, laps=4, step=0.5, straight=30.0, radius=10.0, lane=1.0):
    """Laps of an oval track, alternating between two lanes. Look-alike: the spot across the
    track (the opposite straight or bend)."""
    pts = []
    for lap in range(laps):
        r = radius + lane * (lap % 2)
        pts += [(0.0, -r), (straight, -r)]
        pts += [(straight + r * np.sin(a), r * -np.cos(a)) for a in np.linspace(0, np.pi, 24)[1:]]
        pts += [(0.0, r)]
        pts += [(-r * np.sin(a), r * np.cos(a)) for a in np.linspace(0, np.pi, 24)[1:]]
    return Path("sports_ground", sample_polyline(pts, step), _mirror((straight / 2, 0.0)))


def warehouse(rng, aisles=6, spacing=3.0, length=20.0, passes=3, step=0.5):
    """Serpentine through parallel aisles, three passes, the second shifted by one aisle so
    that neighbouring aisles are driven in the same direction. Look-alike: the same spot in
    the neighbouring aisle."""
    pts = [(0.0, -2.0)]
    for p in range(passes):
        first = p % 2
        for i, a in enumerate(range(first, aisles)):
            x = a * spacing
            ys = (0.0, length) if i % 2 == 0 else (length, 0.0)
            pts += [(x, ys[0]), (x, ys[1])]
        pts += [(pts[-1][0], -2.0), (0.0, -2.0)]

    def twins(T):
        out = []
        p = T[:3, 3]
        if not (-0.1 < p[1] < length + 0.1):
            return out
        for dx in (-spacing, spacing):
            if -0.1 < p[0] + dx < (aisles - 1) * spacing + 0.1:
                Q = T.copy()
                Q[0, 3] += dx
                out.append(Q)
        return out
    return Path("warehouse", sample_polyline(pts, step), twins)


def parking_deck(rng, floors=4, step=0.5, w=30.0, h=16.0, floor_height=3.0):
    """A spiral up a parking deck, one lap per floor. Look-alike: the same spot one floor up
    or down."""
    corners = rectangle(0.0, 0.0, w, h)
    perimeter = 2 * (w + h)
    pts, s = [], 0.0
    for f in range(floors):
        for a, b in zip(corners[:-1], corners[1:]):
            pts.append((a[0], a[1], floor_height * (f + s / perimeter)))
            s = (s + np.hypot(b[0] - a[0], b[1] - a[1])) % perimeter
    pts.append((0.0, 0.0, floor_height * floors))

    def twins(T):
        out = []
        for dz in (-floor_height, floor_height):
            Q = T.copy()
            Q[2, 3] += dz
            out.append(Q)
        return out
    return Path("parking_deck", sample_polyline(pts, step), twins)


def corridor(rng, laps=3, step=0.5):
    """A 20 m x 10 m corridor loop driven three times. Look-alike: a spot 3 m along the
    corridor (identical doors every 3 m)."""
    pts = rectangle(0.0, 0.0, 20.0, 10.0) * laps

    def twins(T):
        out = []
        for d in (-3.0, 3.0):
            Q = T.copy()
            Q[:3, 3] += T[:3, :3] @ np.array([d, 0.0, 0.0])
            out.append(Q)
        return out
    return Path("corridor", sample_polyline(pts, step), twins)


SCENES = {"room": room, "sports_ground": sports_ground, "warehouse": warehouse,
          "parking_deck": parking_deck, "corridor": corridor}
POC_SCENES = ("room", "sports_ground", "warehouse")


def add_drift(truth, sigma, rng, six_dof=False):
    """VIO-like odometry: the truth's relative motions with noise, integrated."""
    vio = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:]):
        rel = g.relative(a, b)
        length = np.linalg.norm(rel[:3, 3])
        noisy = rel.copy()
        noisy[:3, 3] += rng.normal(0.0, sigma * length, 3) * np.array([1.0, 1.0, 0.5])
        R = g.rot_z(rng.normal(0.0, YAW_NOISE_PER_METRE * sigma * length))
        if six_dof:
            R = R @ g.rot_x(rng.normal(0.0, 0.5 * YAW_NOISE_PER_METRE * sigma * length)) @ \
                g.rot_y(rng.normal(0.0, 0.5 * YAW_NOISE_PER_METRE * sigma * length))
        noisy[:3, :3] = R @ rel[:3, :3]
        vio.append(vio[-1] @ noisy)
    return vio


def small_pose(rng, sigma_t=0.3, sigma_yaw=np.radians(5.0)):
    return g.pose(g.rot_z(rng.normal(0.0, sigma_yaw)),
                  rng.normal(0.0, 1.0, 3) * np.array([sigma_t, sigma_t, 0.2 * sigma_t]))


def perturb(T, rng, sigma_t=0.03, sigma_yaw=np.radians(0.5)):
    """What PnP returns for a relative pose: the pose with a little noise."""
    Q = T.copy()
    Q[:3, :3] = g.rot_z(rng.normal(0.0, sigma_yaw)) @ T[:3, :3]
    Q[:3, 3] += rng.normal(0.0, sigma_t, 3)
    return Q


def make_candidates(truth, twins, rng, n_true=100, n_false=100, min_gap=50, radius=0.5,
                    yaw_tol=np.radians(25.0), random_fraction=0.2, min_false_distance=1.0):
    """True candidates at ground-truth revisits, false ones at look-alike places (twins) and a
    fraction of random pairs; at most one candidate per query keyframe, the earliest match (as
    loop_fusion's detectLoop picks the oldest good match). Returns a list of Candidate."""
    n = len(truth)
    P = np.array([T[:3, 3] for T in truth])
    Y = np.array([g.yaw_of(T[:3, :3]) for T in truth])

    def earliest_near(p, yaw, q, exclude_near=None):
        older = np.arange(0, max(0, q - min_gap))
        if older.size == 0:
            return None
        ok = (np.linalg.norm(P[older] - p, axis=1) < radius) & (np.abs(g.wrap(Y[older] - yaw)) < yaw_tol)
        if exclude_near is not None:
            ok &= np.linalg.norm(P[older] - exclude_near, axis=1) > min_false_distance
        idx = older[ok]
        return int(idx[0]) if idx.size else None

    true_pool, false_pool = [], []
    for q in range(min_gap, n):
        m = earliest_near(P[q], Y[q], q)
        if m is not None:
            true_pool.append(Candidate(q, m, perturb(g.relative(truth[m], truth[q]), rng), 1, 40, "revisit"))
        for T_twin in twins(truth[q]):
            m = earliest_near(T_twin[:3, 3], g.yaw_of(T_twin[:3, :3]), q, exclude_near=P[q])
            if m is not None:
                false_pool.append(Candidate(q, m, perturb(g.relative(truth[m], T_twin), rng), 0, 40, "lookalike"))
                break

    chosen, used = [], set()

    def take(pool, k):
        order = rng.permutation(len(pool))
        got = 0
        for i in order:
            if got >= k:
                break
            if pool[i].query in used:
                continue
            used.add(pool[i].query)
            chosen.append(pool[i])
            got += 1
        return got

    take(true_pool, n_true)
    n_random = int(round(n_false * random_fraction))
    got = take(false_pool, n_false - n_random)
    # Random pairs: any two places far apart, with a small relative pose.
    tries = 0
    while got < n_false and tries < 100 * n_false:
        tries += 1
        q = int(rng.integers(min_gap + 1, n))
        m = int(rng.integers(0, q - min_gap))
        if q in used or np.linalg.norm(P[q] - P[m]) < 5.0:
            continue
        used.add(q)
        chosen.append(Candidate(q, m, small_pose(rng), 0, 40, "random"))
        got += 1
    return sorted(chosen, key=lambda c: c.query)


def make_scene(name, sigma=0.05, seed=0, n_true=100, n_false=100, six_dof=False, **scene_args):
    """A Scenario for one simulated scene at odometry noise `sigma`."""
    rng = np.random.default_rng(seed)
    path = SCENES[name](rng, **scene_args)
    vio = add_drift(path.truth, sigma, rng, six_dof)
    cands = make_candidates(path.truth, path.twins, rng, n_true, n_false)
    kfs = [Keyframe(i, 1000.0 + i * path.dt, 1, T) for i, T in enumerate(vio)]
    meta = {"scene": name, "sigma": sigma, "seed": seed, "mode": "6dof" if six_dof else "4dof",
            "true_candidates": sum(c.label == 1 for c in cands),
            "false_candidates": sum(c.label == 0 for c in cands)}
    return Scenario(f"{name}_s{sigma:g}_seed{seed}", kfs, cands, path.truth, meta)
