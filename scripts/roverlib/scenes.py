"""Simulated scenes: ground truth, VIO-like drifting odometry, labelled loop candidates.

The paper's proof-of-concept scenes (Room, Sports ground, Warehouse) plus a corridor loop, a
parking deck, a city block driven in two lanes and real street routes (KITTI ground truth with
simulated drift). Every scene knows its look-alike places ("twins"): the spot a feature matcher
confuses with the true one (the mirror-symmetric side of a room or track, the neighbouring
aisle, the same spot one floor over, the next identical door, the other lane). False candidates
pair a keyframe with a keyframe at its twin and report the relative pose PnP would return
there: the candidate then claims the query is at the twin, wrong by exactly the twin's offset
(the look-alike distance: aisle spacing, floor height, door spacing, lane width).

Hard cases (make_scene options): `rows` look-alikes in a row (consecutive query keyframes, one
twin: they agree with each other and with the odometry, the grouped-consistent case);
`early_lookalike` (a row of look-alikes before the first true loop: every true candidate comes
after it); scene parameters for near twins (aisles, floors, doors 1-3 m apart), many laps
(matches many laps old) and long laps (city scale, the first loop after a long stretch).

Odometry noise level sigma (the paper's sigma): per keyframe step of length l the relative
translation gets N(0, (sigma*l)^2) per horizontal axis (half that vertically) and the relative
yaw N(0, (0.05*sigma*l)^2) rad; 6-DoF scenes also drift in roll and pitch. That is a random
walk, the drift model the verifier assumes. Real VIO also drifts steadily (a gyro bias turns the
yaw by the same angle every metre, a wrong scale stretches every step): `yaw_bias` (degrees per
metre) and `scale_error` (fraction) add that on top, which no drift model sigma describes.
"""
from dataclasses import dataclass
from typing import Callable, List

import numpy as np

try:
    from scipy.spatial import cKDTree
except ImportError:  # the system Python (scripts/simulate.py) has no scipy: the plain scan
    cKDTree = None

from . import datasets
from . import geometry as g
from .scenario import Candidate, Keyframe, Scenario

YAW_NOISE_PER_METRE = 0.05  # rad per metre travelled, per unit sigma


@dataclass
class Path:
    name: str
    truth: List[np.ndarray]
    twins: Callable[[np.ndarray], List[np.ndarray]]  # pose -> look-alike poses elsewhere
    dt: float = 0.5  # seconds between keyframes
    revisit_radius: float = 0.5  # m: a true revisit (and a match at a twin) is this close
    min_gap: int = 50  # keyframes between a query and its match


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


def room(rng, laps=8, step=0.25, width=8.0, depth=6.0):
    """A width x depth room (8 m x 6 m) walked around 1 m from the walls, each lap a little off
    the last. Look-alike: the point-symmetric spot (a symmetric room looks the same from across)."""
    pts = []
    for _ in range(laps):
        o = rng.uniform(-0.25, 0.25)
        pts += rectangle(1.0 + o, 1.0 + o, width - 2.0 - 2 * o, depth - 2.0 - 2 * o)[:-1]
    pts.append(pts[0])
    return Path("room", sample_polyline(pts, step), _mirror((width / 2, depth / 2)))


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


def parking_deck(rng, floors=4, step=0.5, w=30.0, h=16.0, floor_height=3.0, ascents=1):
    """A spiral up a parking deck, one lap per floor. Look-alike: the same spot one floor up
    or down. One ascent never revisits a place (no true loops); with ascents > 1 the robot
    takes a lift beside the deck back down and spirals up again (true loops on every later
    ascent; look-alikes one floor off from the first floor on)."""
    corners = rectangle(0.0, 0.0, w, h)
    perimeter = 2 * (w + h)
    pts = []
    for ascent in range(ascents):
        if ascent:  # out to the lift, down, back in
            top = floor_height * floors
            pts += [(-6.0, 0.0, top), (-6.0, 0.0, 0.0)]
        s = 0.0
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


def corridor(rng, laps=3, step=0.5, door_spacing=3.0, width=20.0, depth=10.0):
    """A 20 m x 10 m corridor loop driven three times. Look-alike: a spot door_spacing (3 m)
    along the corridor (identical doors). Many laps: loop_fusion matches the oldest look-alike
    and the oldest revisit, laps back."""
    pts = rectangle(0.0, 0.0, width, depth) * laps

    def twins(T):
        out = []
        for d in (-door_spacing, door_spacing):
            Q = T.copy()
            Q[:3, 3] += T[:3, :3] @ np.array([d, 0.0, 0.0])
            out.append(Q)
        return out
    return Path("corridor", sample_polyline(pts, step), twins)


def _lane_and_along_twins(lane, along):
    """Twins of a road: the same spot in the neighbouring lane (left, then right) and the next
    identical facade along the road (ahead, then behind), at the query's heading."""
    def twins(T):
        out = []
        for d in ((0.0, lane), (0.0, -lane), (along, 0.0), (-along, 0.0)):
            Q = T.copy()
            Q[:3, 3] += T[:3, :3] @ np.array([d[0], d[1], 0.0])
            out.append(Q)
        return out
    return twins


def city(rng, laps=4, step=2.0, block=(200.0, 100.0), lane=3.5, along=3.0):
    """A city block (200 m x 100 m: 600 m a lap) driven `laps` times, alternating between two
    lanes `lane` metres apart: the first true revisit comes two laps (1200 m) after the place
    was first seen, look-alikes in the other lane one lap after. Look-alikes: the other lane,
    identical facades `along` metres ahead or behind."""
    pts = []
    for lap in range(laps):
        o = lane * (lap % 2)
        pts += rectangle(-o, -o, block[0] + 2 * o, block[1] + 2 * o)[:-1]
    pts.append(pts[0])
    return Path("city", sample_polyline(pts, step), _lane_and_along_twins(lane, along), dt=0.2,
                revisit_radius=1.5, min_gap=100)


def kitti_route(rng, sequence="00", step=2.0, lane=3.5, along=3.0):
    """A real street route: the KITTI ground truth of `sequence` (../shared/data/kitti), a
    keyframe every `step` metres, flattened to the ground plane (heading kept). Look-alikes as
    in city(). The drift is simulated (make_scene's sigma), the layout and revisits are real."""
    _, poses = datasets.load_kitti(datasets.data_path(f"kitti/{sequence}_groundtruth.txt"))
    flat = [g.pose(g.rot_z(g.yaw_of(T[:3, :3])), [T[0, 3], T[1, 3], 0.0]) for T in poses]
    keep = g.keyframes_by_distance(flat, step, min_yaw=np.radians(30.0))
    return Path(f"kitti_{sequence}_route", [flat[i] for i in keep], _lane_and_along_twins(lane, along), dt=0.2,
                revisit_radius=1.5, min_gap=100)


SCENES = {"room": room, "sports_ground": sports_ground, "warehouse": warehouse,
          "parking_deck": parking_deck, "corridor": corridor, "city": city, "kitti_route": kitti_route}
# The scene parameter that sets how far a look-alike is from the true place (room and sports
# ground mirror across the scene: fixed by its size).
LOOKALIKE_DISTANCE = {"warehouse": "spacing", "parking_deck": "floor_height", "corridor": "door_spacing",
                      "city": "along", "kitti_route": "along"}
POC_SCENES = ("room", "sports_ground", "warehouse")


def add_drift(truth, sigma, rng, six_dof=False, yaw_bias=0.0, scale_error=0.0):
    """VIO-like odometry: the truth's relative motions with noise, integrated; `yaw_bias` degrees
    of yaw per metre and a translation scale of 1 + `scale_error` on top (steady drift)."""
    vio = [truth[0].copy()]
    for a, b in zip(truth[:-1], truth[1:]):
        rel = g.relative(a, b)
        length = np.linalg.norm(rel[:3, 3])
        noisy = rel.copy()
        noisy[:3, 3] = (1.0 + scale_error) * noisy[:3, 3] + rng.normal(0.0, sigma * length, 3) * np.array([1.0, 1.0, 0.5])
        R = g.rot_z(rng.normal(0.0, YAW_NOISE_PER_METRE * sigma * length) + np.radians(yaw_bias) * length)
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


def candidate_pools(truth, twins, rng, min_gap=50, radius=0.5, yaw_tol=np.radians(25.0), min_false_distance=1.0,
                    older=None):
    """Every possible candidate, one pass over the query keyframes: (true pool, false pool, twin
    index of each false one). True: the earliest keyframe at the query's place (as loop_fusion's
    detectLoop picks the oldest good match); false: the earliest keyframe at the query's first
    twin that has one (not near the query itself). `older(q)`: the keyframes a query may match
    (default: all up to q - min_gap)."""
    n = len(truth)
    P = np.array([T[:3, 3] for T in truth])
    Y = np.array([g.yaw_of(T[:3, :3]) for T in truth])
    # Only keyframes within `radius` can match: a k-d tree finds them without scanning every
    # older keyframe (the same earliest match; the 100k-keyframe long replay needs it).
    tree = cKDTree(P) if older is None and cKDTree is not None else None

    def earliest_near(p, yaw, q, exclude_near=None):
        if tree is not None:
            cands = np.array(sorted(i for i in tree.query_ball_point(p, radius) if i < q - min_gap), dtype=int)
        else:
            cands = np.arange(0, max(0, q - min_gap)) if older is None else older(q)
        if cands.size == 0:
            return None
        ok = (np.linalg.norm(P[cands] - p, axis=1) < radius) & (np.abs(g.wrap(Y[cands] - yaw)) < yaw_tol)
        if exclude_near is not None:
            ok &= np.linalg.norm(P[cands] - exclude_near, axis=1) > min_false_distance
        idx = cands[ok]
        return int(idx[0]) if idx.size else None

    true_pool, false_pool, false_twin = [], [], []
    for q in range(min_gap, n):
        m = earliest_near(P[q], Y[q], q)
        if m is not None:
            true_pool.append(Candidate(q, m, perturb(g.relative(truth[m], truth[q]), rng), 1, 40, "revisit"))
        for k, T_twin in enumerate(twins(truth[q])):
            m = earliest_near(T_twin[:3, 3], g.yaw_of(T_twin[:3, :3]), q, exclude_near=P[q])
            if m is not None:
                false_pool.append(Candidate(q, m, perturb(g.relative(truth[m], T_twin), rng), 0, 40, "lookalike"))
                false_twin.append(k)
                break
    return true_pool, false_pool, false_twin


def select_candidates(true_pool, false_pool, false_twin, rng, n_true, n_false, rows=1, early_lookalike=False):
    """n_true true and n_false false candidates from the pools, at most one per query keyframe.
    rows = 1: both drawn at random (true first). rows > 1: false ones in rows of `rows`
    consecutive query keyframes at the same twin (all agreeing with each other);
    early_lookalike: the earliest such row is taken first and only true candidates after it
    are drawn, so a row of look-alikes arrives before the first true loop."""
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

    if rows <= 1 and not early_lookalike:
        return chosen, take(true_pool, n_true), take(false_pool, n_false), used
    by_query = {c.query: i for i, c in enumerate(false_pool)}
    runs = []
    for i, c in enumerate(false_pool):
        members = [by_query.get(c.query + d) for d in range(rows)]
        if all(j is not None and false_twin[j] == false_twin[i] for j in members):
            runs.append(members)

    def take_run(members):
        if any(false_pool[j].query in used for j in members):
            return 0
        for j in members:
            used.add(false_pool[j].query)
            chosen.append(false_pool[j])
        return len(members)

    got_false = 0
    if early_lookalike and runs and n_false >= rows:
        first = runs[0]  # the pool is in query order: the earliest row
        got_false += take_run(first)
        last = false_pool[first[-1]].query
        true_pool = [c for c in true_pool if c.query > last]
    # rows first: at a revisit the query often has a true match and a twin; rows need
    # consecutive free queries, single true candidates do not
    for r in rng.permutation(len(runs)):
        if got_false + rows > n_false:
            break
        got_false += take_run(runs[r])
    got_true = take(true_pool, n_true)
    return chosen, got_true, got_false, used


def make_candidates(truth, twins, rng, n_true=100, n_false=100, min_gap=50, radius=0.5,
                    yaw_tol=np.radians(25.0), random_fraction=0.2, min_false_distance=1.0, rows=1,
                    early_lookalike=False):
    """True candidates at ground-truth revisits, false ones at look-alike places (twins) and a
    fraction of random pairs; at most one candidate per query keyframe, the earliest match (as
    loop_fusion's detectLoop picks the oldest good match). Returns a list of Candidate.
    rows, early_lookalike: see select_candidates."""
    n = len(truth)
    P = np.array([T[:3, 3] for T in truth])
    pools = candidate_pools(truth, twins, rng, min_gap, radius, yaw_tol, min_false_distance)
    n_random = int(round(n_false * random_fraction))
    chosen, _, got, used = select_candidates(*pools, rng, n_true, n_false - n_random, rows, early_lookalike)
    # Random pairs: any two places far apart, with a small relative pose. They fill up to
    # n_false; with rows, only the random share (a scene short of look-alike rows says so in
    # its candidate counts rather than hiding it behind easy random pairs).
    target = got + n_random if rows > 1 or early_lookalike else n_false
    tries = 0
    while got < target and tries < 100 * n_false:
        tries += 1
        q = int(rng.integers(min_gap + 1, n))
        m = int(rng.integers(0, q - min_gap))
        if q in used or np.linalg.norm(P[q] - P[m]) < 5.0:
            continue
        used.add(q)
        chosen.append(Candidate(q, m, small_pose(rng), 0, 40, "random"))
        got += 1
    return sorted(chosen, key=lambda c: c.query)


def make_scene(name, sigma=0.05, seed=0, n_true=100, n_false=100, six_dof=False, rows=1, early_lookalike=False,
               random_fraction=0.2, min_false_distance=1.0, yaw_bias=0.0, scale_error=0.0, **scene_args):
    """A Scenario for one simulated scene at odometry noise `sigma` (hard-case options: see
    select_candidates; random_fraction: share of the false candidates that are random far
    pairs instead of look-alikes; min_false_distance: how far from the query a look-alike's
    match must be, below 1 m for twins 1 m away; yaw_bias, scale_error: steady drift, add_drift)."""
    rng = np.random.default_rng(seed)
    path = SCENES[name](rng, **scene_args)
    vio = add_drift(path.truth, sigma, rng, six_dof, yaw_bias, scale_error)
    cands = make_candidates(path.truth, path.twins, rng, n_true, n_false, min_gap=path.min_gap,
                            radius=path.revisit_radius, random_fraction=random_fraction,
                            min_false_distance=min_false_distance, rows=rows, early_lookalike=early_lookalike)
    kfs = [Keyframe(i, 1000.0 + i * path.dt, 1, T) for i, T in enumerate(vio)]
    meta = {"scene": name, "sigma": sigma, "seed": seed, "mode": "6dof" if six_dof else "4dof",
            "true_candidates": sum(c.label == 1 for c in cands),
            "false_candidates": sum(c.label == 0 for c in cands)}
    if yaw_bias or scale_error:
        meta.update(yaw_bias_deg_per_m=yaw_bias, scale_error=scale_error)
    return Scenario(f"{name}_s{sigma:g}_seed{seed}", kfs, cands, path.truth, meta)


def tilted_loop():
    """Two laps of a 3 m circle (sequence 1, VIO = truth) by a body pitched 60 deg and rolled
    30 deg, as EuRoC's IMU is tilted, and one exact loop between headings 18 deg apart: its
    relative rotation's yaw is 8.8 deg, loop_fusion's relative yaw (the difference of world
    yaws) 18 deg. Returns (scenario, candidate)."""
    tilt = g.rot_x(np.radians(30.0)) @ g.rot_y(np.radians(-60.0))
    n, r = 40, 3.0
    T = [g.pose(g.rot_z(2 * np.pi * k / n + np.pi / 2) @ tilt,
                [r * np.cos(2 * np.pi * k / n), r * np.sin(2 * np.pi * k / n), 0.0]) for k in range(2 * n)]
    q, m = n + 20, 18
    c = Candidate(q, m, g.relative(T[m], T[q]), 1, 40)
    keyframes = [Keyframe(k, 100.0 + 0.5 * k, 1, T[k]) for k in range(len(T))]
    return Scenario("tilted_loop", keyframes, [c], list(T)), c
