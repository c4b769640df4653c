"""Incremental loop-closure verifiers from the literature, written from their papers for the
evaluation (not part of the product), on a roverlib.problem.Problem: the same graph, the same
covariances and the same candidates in the same order as the ROVER verifier in that run.

PCM  pairwise consistency maximisation (Mangelson et al., ICRA 2018), as Kimera-RPGO runs it
     (outlier/Pcm.h): a loop enters the consistency graph if it agrees with the odometry
     between its two keyframes (squared Mahalanobis distance of the cycle odometry * loop^-1
     under the composed covariances below the chi2 quantile); two such loops are consistent if
     the cycle loop_a^-1 * odometry(match_a, match_b) * loop_b * odometry(query_b, query_a)
     passes the same test; the accepted set is the maximum clique of that graph, recomputed as
     every candidate arrives with the heuristic Kimera-RPGO runs by default (Pattabiraman et al.
     2015, MaxCliqueHeu: from every vertex whose degree could beat the best clique so far, grow a
     clique greedily by highest degree; the largest wins, ties go to the one found first).
     A loop accepted earlier can leave the set later. (Kimera-RPGO's `incremental` variant grows
     cliques only from the new vertex: measured here, it locks onto an early row of agreeing
     look-alikes and never lets the later, larger set of true loops in.)
     Odometry covariances between any two keyframes come from the chain in O(1): with C_i the
     covariance of keyframe i relative to keyframe 0 (propagated with the adjoint), the
     covariance of i -> j is C_j - Ad(D^-1) C_i Ad(D^-1)^T, D = P_i^-1 P_j (as Kimera-RPGO).
IPC  incremental pose consistency (Olivastri, Pretto et al., ICRA 2024): for a candidate (m, q)
     the span [m, q] is widened by every accepted loop that overlaps it (transitively); that
     subgraph (odometry, those accepted loops, the candidate) is solved from the current
     estimate with the vertex at the span's start fixed and everything outside left as it is;
     the candidate is accepted only if every edge's chi2 stays under the 0.95 quantile, and the
     solution then becomes the estimate of the span (later keyframes are appended by odometry).
     Accepted loops are never removed.

run() returns per-candidate decisions (PCM: the final clique; the selection after every
candidate is kept for the temporal ATE), why each was not accepted, and per-candidate
wall-clock time in ms. Deterministic: no random
numbers anywhere (ties go to the earliest candidate).
"""
import time

import numpy as np

from . import robust

PCM_CHI2_PROBABILITY = 0.99  # both of PCM's tests (Kimera-RPGO takes thresholds as parameters)
IPC_CHI2_PROBABILITY = 0.95  # IPC's per-edge test (the paper's)
IPC_LM_ITERATIONS = 50


def _chi2(p, dof):
    from scipy.stats import chi2
    return float(chi2.ppf(p, dof))


class _Chain:
    """Odometry poses and covariances relative to keyframe 0, appended as keyframes arrive."""

    def __init__(self, problem):
        self.dim = problem.dim
        self.cls = _pose_class(problem.dim)
        k = 3 if problem.dim == 2 else 6
        self.poses = [self.cls()]
        self.covs = [np.zeros((k, k))]
        self.odometry = problem.odometry

    def extend_to(self, i):
        while len(self.poses) <= i:
            e = self.odometry[len(self.poses) - 1]
            step = robust.to_gtsam_pose(e.T, self.dim)
            Ad = step.inverse().AdjointMap()
            self.covs.append(Ad @ self.covs[-1] @ Ad.T + e.cov)
            self.poses.append(self.poses[-1].compose(step))

    def between(self, i, j):
        """(pose of j in i's frame, its covariance) along the odometry, i <= j or i > j."""
        if i > j:
            return _inverse(self.between(j, i))
        self.extend_to(j)
        D = self.poses[i].between(self.poses[j])
        Ad = D.inverse().AdjointMap()
        C = self.covs[j] - Ad @ self.covs[i] @ Ad.T
        return D, 0.5 * (C + C.T)


def _pose_class(dim):
    import gtsam
    return gtsam.Pose2 if dim == 2 else gtsam.Pose3


def _inverse(pc):
    P, C = pc
    Ad = P.AdjointMap()
    return P.inverse(), Ad @ C @ Ad.T


def _compose(a, b):
    Ad = b[0].inverse().AdjointMap()
    return a[0].compose(b[0]), Ad @ a[1] @ Ad.T + b[1]


def _mahalanobis2(pc, cls):
    P, C = pc
    xi = cls.Logmap(P)
    return float(xi @ np.linalg.solve(C, xi))


class PCM:
    def __init__(self, problem, probability=PCM_CHI2_PROBABILITY):
        self.problem = problem
        self.cls = _pose_class(problem.dim)
        self.chain = _Chain(problem)
        self.threshold = _chi2(probability, problem.dof)
        self.loops = []  # (index into problem.loops, (pose, cov) of the measurement)
        self.adj = np.zeros((0, 0), dtype=bool)
        self.clique = []  # indices into self.loops
        self.reasons = {}  # problem.loops index -> why not accepted (at the end: see run())

    def _measurement(self, e):
        return robust.to_gtsam_pose(e.T, self.problem.dim), e.cov

    def odometry_consistent(self, e):
        cycle = _compose(self.chain.between(e.a, e.b), _inverse(self._measurement(e)))
        return _mahalanobis2(cycle, self.cls) < self.threshold

    def pairwise_consistent(self, ea, za, eb, zb):
        # loop_a^-1 * odo(m_a, m_b) * loop_b * odo(q_b, q_a) = identity for consistent loops
        cycle = _compose(_compose(_compose(_inverse(za), self.chain.between(ea.a, eb.a)), zb),
                         self.chain.between(eb.b, ea.b))
        return _mahalanobis2(cycle, self.cls) < self.threshold

    def add(self, k):
        """Candidate k of problem.loops arrives; returns the accepted set (problem.loops indices)."""
        e = self.problem.loops[k]
        self.reasons[k] = "odometry_inconsistent"
        if self.odometry_consistent(e):
            self.reasons[k] = "outside_max_clique"
            z = self._measurement(e)
            row = np.array([self.pairwise_consistent(self.problem.loops[j], zj, e, z) for j, zj in self.loops],
                           dtype=bool)
            n = len(self.loops)
            adj = np.zeros((n + 1, n + 1), dtype=bool)
            adj[:n, :n] = self.adj
            adj[n, :n] = adj[:n, n] = row
            self.adj = adj
            self.loops.append((k, z))
            self.clique = self._max_clique_heuristic()
        return [self.loops[i][0] for i in self.clique]

    def _max_clique_heuristic(self):
        """MaxCliqueHeu over the whole consistency graph (starting from the current clique,
        which stays a clique when vertices are added)."""
        degree = self.adj.sum(axis=1)
        best = list(self.clique)
        for v in range(len(degree)):
            if degree[v] < len(best):  # v's cliques have at most degree + 1 vertices
                continue
            clique = [v]
            cand = self.adj[v] & (degree >= len(best))
            while cand.any():
                idx = np.flatnonzero(cand)
                u = int(idx[np.argmax(degree[idx])])
                clique.append(u)
                cand &= self.adj[u]
                cand[u] = False
            if len(clique) > len(best):
                best = sorted(clique)
        return best


class IPC:
    def __init__(self, problem, probability=IPC_CHI2_PROBABILITY, max_iterations=IPC_LM_ITERATIONS):
        self.problem = problem
        self.threshold = _chi2(probability, problem.dof)
        self.max_iterations = max_iterations
        self.estimate = [np.eye(4)]  # 4x4 per keyframe that has arrived
        self.accepted = []  # indices into problem.loops
        self.reasons = {}

    def _extend_to(self, i):
        while len(self.estimate) <= i:
            self.estimate.append(self.estimate[-1] @ self.problem.odometry[len(self.estimate) - 1].T)

    def span(self, e):
        """[lo, hi] of the subgraph and the accepted loops inside it (transitive overlap)."""
        lo, hi = e.a, e.b
        inside = []
        changed = True
        left = list(self.accepted)
        while changed:
            changed = False
            for k in list(left):
                f = self.problem.loops[k]
                if min(hi, f.b) - max(lo, f.a) > 0:
                    lo, hi = min(lo, f.a), max(hi, f.b)
                    inside.append(k)
                    left.remove(k)
                    changed = True
        return lo, hi, inside

    def add(self, k):
        """Candidate k arrives; returns True if accepted."""
        import gtsam
        e = self.problem.loops[k]
        dim = self.problem.dim
        self._extend_to(e.b)
        lo, hi, inside = self.span(e)
        fg = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        for i in range(lo, hi + 1):
            values.insert(i, robust.to_gtsam_pose(self.estimate[i], dim))
        Prior = gtsam.PriorFactorPose2 if dim == 2 else gtsam.PriorFactorPose3
        fg.add(Prior(lo, robust.to_gtsam_pose(self.estimate[lo], dim),
                     gtsam.noiseModel.Isotropic.Sigma(3 if dim == 2 else 6, 1e-6)))
        first_edge = fg.size()
        for i in range(lo, hi):
            fg.add(robust.between(self.problem.odometry[i], dim))
        for j in inside + [k]:
            fg.add(robust.between(self.problem.loops[j], dim))
        params = robust.lm_params(self.max_iterations)
        result = gtsam.LevenbergMarquardtOptimizer(fg, values, params).optimize()
        ok = all(2.0 * fg.at(i).error(result) < self.threshold for i in range(first_edge, fg.size()))
        self.reasons[k] = "accepted" if ok else "chi2_above_quantile"
        if ok:
            self.accepted.append(k)
            self.estimate[lo:hi + 1] = robust.from_values(result, hi - lo + 1, dim, first=lo)
        return ok


def run(method, problem, deadline_s=None):
    """Runs PCM or IPC over problem.loops in order. Returns dict(accepted: bool per loop (PCM:
    the final clique), sets: the accepted indices after each candidate, ms: per-candidate time,
    time_limit_hit: the candidates after the deadline were not looked at (rejected))."""
    v = PCM(problem) if method == "pcm" else IPC(problem)
    start = time.perf_counter()
    current, sets, ms = [], [], []
    hit = False
    for k in range(len(problem.loops)):
        t0 = time.perf_counter()
        if deadline_s is not None and t0 - start > deadline_s:
            hit = True
            sets.append(list(current))
            ms.append(float("nan"))
            continue
        if method == "pcm":
            current = v.add(k)
        elif v.add(k):
            current = current + [k]
        sets.append(list(current))
        ms.append(1000.0 * (time.perf_counter() - t0))
    accepted = np.zeros(len(problem.loops), dtype=bool)
    accepted[current] = True
    reasons = ["accepted" if accepted[k] else v.reasons.get(k, "time_limit") for k in range(len(problem.loops))]
    return {"accepted": accepted, "sets": sets, "ms": np.array(ms), "time_limit_hit": hit, "reasons": reasons}
