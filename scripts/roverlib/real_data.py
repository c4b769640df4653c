"""Scenarios from real trajectories in ../shared/data (roverlib/datasets.py): keyframes from a
VIO/VO estimate (real drift), candidates from the ground truth.

True candidates pair keyframes that are at the same place in truth (and face the same way)
with their ground-truth relative pose; false ones pair keyframes that are far apart in truth
with a plausible small relative pose (what PnP on a look-alike place returns).
"""
import numpy as np

from . import datasets
from . import geometry as g
from .scenario import Candidate, Keyframe, Scenario
from .scenes import candidate_pools, perturb, select_candidates, small_pose

# name -> (estimate file, ground-truth file, mode, alignment, environment)
SEQUENCES = {
    "euroc_mh01": ("euroc/MH_01_vio_stereo.txt", "euroc/MH_01_groundtruth.txt", "4dof", "se3", "indoor"),
    "euroc_mh03": ("euroc/MH_03_vio_stereo.txt", "euroc/MH_03_groundtruth.txt", "4dof", "se3", "indoor"),
    "euroc_mh05": ("euroc/MH_05_vio_stereo.txt", "euroc/MH_05_groundtruth.txt", "4dof", "se3", "indoor"),
    "euroc_mh04_mono0": ("euroc/MH_04_vio_mono_trial0.txt", "euroc/MH_04_groundtruth.txt", "4dof", "se3", "indoor"),
    "euroc_mh04_mono1": ("euroc/MH_04_vio_mono_trial1.txt", "euroc/MH_04_groundtruth.txt", "4dof", "se3", "indoor"),
    "euroc_mh04_mono2": ("euroc/MH_04_vio_mono_trial2.txt", "euroc/MH_04_groundtruth.txt", "4dof", "se3", "indoor"),
    "kitti_09": ("kitti/09_vo_estimate.txt", "kitti/09_groundtruth.txt", "6dof", "se3", "outdoor"),
}

def associate(t_est, t_gt, tol):
    """Index into t_gt of the nearest stamp for each t_est, -1 where none is within tol."""
    j = np.clip(np.searchsorted(t_gt, t_est), 1, len(t_gt) - 1)
    left = np.abs(t_gt[j - 1] - t_est) < np.abs(t_gt[j] - t_est)
    j = np.where(left, j - 1, j)
    return np.where(np.abs(t_gt[j] - t_est) <= tol, j, -1)


LOOKALIKE_DIRECTIONS = ("lateral", "vertical", "along")


def lookalike_twins(offset, first="lateral"):
    """Twins of a real place for hard false candidates: the query's pose moved `offset` metres
    sideways (a parallel aisle), vertically (the floor below or above) or along its heading (the
    next identical bay); the first direction that has a keyframe there wins, starting at `first`."""
    k = LOOKALIKE_DIRECTIONS.index(first)
    order = LOOKALIKE_DIRECTIONS[k:] + LOOKALIKE_DIRECTIONS[:k]
    shifts = {"lateral": [(0.0, offset, 0.0), (0.0, -offset, 0.0)], "vertical": [(0.0, 0.0, -offset), (0.0, 0.0, offset)],
              "along": [(offset, 0.0, 0.0), (-offset, 0.0, 0.0)]}

    def twins(T):
        out = []
        for d in order:
            for dx, dy, dz in shifts[d]:
                Q = T.copy()
                Q[:3, 3] += g.rot_z(g.yaw_of(T[:3, :3])) @ np.array([dx, dy, 0.0]) + np.array([0.0, 0.0, dz])
                out.append(Q)
        return out
    return twins


def make_real(name, seed=0, n_true=100, n_false=100, keyframe_distance=None, min_gap_s=None,
              revisit_radius=None, false_distance=None, lookalike=None):
    """A Scenario from a real VIO/VO run. False candidates: by default pairs of places
    `false_distance` apart in truth with a small relative pose; with lookalike = dict(offset=M,
    first="lateral"|"vertical"|"along", rows=N, early=bool) look-alikes `offset` metres from the
    query instead (roverlib.scenes: in rows of N agreeing ones, a row before the first true loop)."""
    est_rel, gt_rel, mode, alignment, env = SEQUENCES[name]
    rng = np.random.default_rng(seed)
    outdoor = env == "outdoor"
    keyframe_distance = keyframe_distance or (1.0 if outdoor else 0.2)
    min_gap_s = min_gap_s or (30.0 if outdoor else 10.0)
    revisit_radius = revisit_radius or (4.0 if outdoor else 0.5)
    false_distance = false_distance or ((10.0, 60.0) if outdoor else (3.0, 15.0))
    if name.startswith("kitti"):
        t_est, est = datasets.load_kitti(datasets.data_path(est_rel))
        t_gt, gt = datasets.load_kitti(datasets.data_path(gt_rel))
        match = np.arange(len(est))  # one pose per frame in both
    else:
        t_est, est = datasets.load_tum(datasets.data_path(est_rel))
        t_gt, gt = datasets.load_tum(datasets.data_path(gt_rel))
        match = associate(t_est, t_gt, 0.01)
        # Before initialisation the VIO reports identity poses: skip them.
        moving = np.array([np.linalg.norm(T[:3, 3]) > 1e-9 or abs(T[0, 0] - 1) > 1e-12 for T in est])
        match = np.where(moving, match, -1)
    valid = np.flatnonzero(match >= 0)
    est_v = [est[i] for i in valid]
    keep = [valid[k] for k in g.keyframes_by_distance(est_v, keyframe_distance)]
    kfs = [Keyframe(k, float(t_est[i]), 1, est[i]) for k, i in enumerate(keep)]
    truth = [gt[match[i]] for i in keep]
    stamps = np.array([k.stamp for k in kfs])
    meta = {"source": f"{est_rel} + {gt_rel}", "mode": mode, "alignment": alignment,
            "environment": env, "seed": seed, "keyframe_distance": keyframe_distance}
    if lookalike:
        lk = dict(offset=1.5, first="lateral", rows=5, early=True)
        lk.update(lookalike)
        pools = candidate_pools(truth, lookalike_twins(lk["offset"], lk["first"]), rng, min_gap=1,
                                radius=revisit_radius, yaw_tol=np.radians(30.0),
                                min_false_distance=0.5 * lk["offset"],
                                older=lambda q: np.flatnonzero(stamps < stamps[q] - min_gap_s))
        chosen = select_candidates(*pools, rng, n_true, n_false, lk["rows"], lk["early"])[0]
        meta.update(lookalike_offset=lk["offset"], lookalike_first=lk["first"], rows=lk["rows"])
    else:
        chosen = _far_apart_candidates(truth, stamps, rng, n_true, n_false, min_gap_s, revisit_radius,
                                       false_distance)
    meta.update(true_candidates=sum(c.label == 1 for c in chosen), false_candidates=sum(c.label == 0 for c in chosen))
    return Scenario(name, kfs, sorted(chosen, key=lambda c: c.query), truth, meta)


def _far_apart_candidates(truth, stamps, rng, n_true, n_false, min_gap_s, revisit_radius, false_distance):
    P = np.array([T[:3, 3] for T in truth])
    Y = np.array([g.yaw_of(T[:3, :3]) for T in truth])
    true_pool, false_pool = [], []
    for q in range(len(truth)):
        older = np.flatnonzero(stamps < stamps[q] - min_gap_s)
        if older.size == 0:
            continue
        d = np.linalg.norm(P[older] - P[q], axis=1)
        same_way = np.abs(g.wrap(Y[older] - Y[q])) < np.radians(30.0)
        near = older[(d < revisit_radius) & same_way]
        if near.size:
            m = int(near[0])
            true_pool.append(Candidate(q, m, perturb(g.relative(truth[m], truth[q]), rng), 1, 40, "revisit"))
        far = older[(d > false_distance[0]) & (d < false_distance[1]) & same_way]
        if far.size:
            m = int(rng.choice(far))
            false_pool.append(Candidate(q, m, small_pose(rng), 0, 40, "far_apart"))

    chosen, used = [], set()
    for pool, k in ((true_pool, n_true), (false_pool, n_false)):
        got = 0
        for i in rng.permutation(len(pool)):
            if got >= k:
                break
            if pool[i].query not in used:
                used.add(pool[i].query)
                chosen.append(pool[i])
                got += 1
    return chosen
