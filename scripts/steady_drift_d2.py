#!/usr/bin/env python3
"""How far a simulated case's loop candidates sit from the odometry, in units of the drift model:
each candidate's squared Mahalanobis distance d2 (x, y, z, yaw of the query in the match's frame)
against its odometry chain alone (no accepted loop: what the first revisit of a run sees), under
the shipped YAML's random-walk drift model and with a steady-drift term added (a yaw rate with
std --yaw-rate-sigma deg/m and a scale error with std --scale-sigma, common to the whole chain:
rank-one terms J J^T sigma^2). Prints per case the ROC AUC of d2 (true loops below false ones),
the true loops' median d2 and the share of true and false candidates within the chi-square gate
(4 dof).

A diagnostic of the trajectory prior, not of the verifier: the verifier's own covariance also
runs through accepted loops (docs/results.md, "Steady drift").

    scripts/steady_drift_d2.py [--split tuning|test] [--yaw-rate-sigma 0.2] [--scale-sigma 0.02]
                               [--gate 0.999] [cases ...]      (default: every simulated case)
"""
import argparse

import numpy as np

from roverlib import drift_model, scenes, splits
from roverlib import geometry as g

CHI2_4 = {0.99: 13.277, 0.999: 18.467, 0.9999: 23.513}


def pose4(T):
    return np.array([T[0, 3], T[1, 3], T[2, 3], g.yaw_of(T[:3, :3])])


def chain(poses, yaw_rate=0.0, scale=0.0):
    """The last pose relative to the first with a steady yaw rate [rad/m] and scale error on
    the steps between them (scenes.add_drift without noise)."""
    drifted = scenes.add_drift(poses, 0.0, np.random.default_rng(0), yaw_bias=np.degrees(yaw_rate), scale_error=scale)
    return g.relative(drifted[0], drifted[-1])


def covariances(track, model, yaw_rate_sigma, scale_sigma):
    """(random walk, random walk + steady term) covariance of the pose of track[-1] relative to
    track[0] (odometry poses), 4x4, loop noise in."""
    poses = [g.relative(track[0], T) for T in track]
    end = poses[-1][:3, 3]
    C = np.diag([model.loop_sigma_t ** 2] * 3 + [model.loop_sigma_yaw ** 2])
    for k in range(len(poses) - 1):
        length = max(np.linalg.norm(poses[k + 1][:3, 3] - poses[k][:3, 3]), model.min_step)
        J = np.zeros((4, 3))
        J[:3, :3] = poses[k][:3, :3]  # a translation error of step k moves the end with it
        C += J @ np.diag([model.sigma_xy ** 2, model.sigma_xy ** 2, model.sigma_z ** 2]) @ J.T * length
        d = end - poses[k + 1][:3, 3]  # a yaw error of step k turns the rest of the chain
        jy = np.array([-d[1], d[0], 0.0, 1.0])
        C += np.outer(jy, jy) * model.sigma_yaw ** 2 * length
    eps = 1e-6
    base = pose4(chain(track))
    jb = (pose4(chain(track, eps)) - base) / eps
    js = (pose4(chain(track, 0.0, eps)) - base) / eps
    steady = C + np.outer(jb, jb) * np.radians(yaw_rate_sigma) ** 2 + np.outer(js, js) * scale_sigma ** 2
    return C, steady


def case_d2(scenario, model, yaw_rate_sigma, scale_sigma):
    """[(label, d2 random walk, d2 with the steady term)] per candidate."""
    P = [k.T for k in scenario.keyframes]
    out = []
    for c in scenario.candidates:
        nu = pose4(c.T_rel) - pose4(g.relative(P[c.match], P[c.query]))
        nu[3] = (nu[3] + np.pi) % (2 * np.pi) - np.pi
        rw, steady = covariances(P[c.match:c.query + 1], model, yaw_rate_sigma, scale_sigma)
        out.append((c.label, nu @ np.linalg.solve(rw, nu), nu @ np.linalg.solve(steady, nu)))
    return out


def auc(rows, col):
    t = np.array([r[col] for r in rows if r[0] == 1])
    f = np.array([r[col] for r in rows if r[0] == 0])
    if not len(t) or not len(f):
        return float("nan")
    return float(np.mean([(x < f).mean() + 0.5 * (x == f).mean() for x in t]))


def summary(rows, gate):
    def within(label, col):
        v = [r[col] <= gate for r in rows if r[0] == label]
        return float(np.mean(v)) if v else float("nan")
    def median(label, col):
        v = [r[col] for r in rows if r[0] == label]
        return float(np.median(v)) if v else float("nan")
    return {"auc_rw": auc(rows, 1), "auc_steady": auc(rows, 2),
            "true_median_rw": median(1, 1), "true_median_steady": median(1, 2),
            "true_in_rw": within(1, 1), "true_in_steady": within(1, 2),
            "false_in_rw": within(0, 1), "false_in_steady": within(0, 2)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", choices=("tuning", "test"), default="tuning")
    ap.add_argument("--yaw-rate-sigma", type=float, default=0.2, help="deg per metre")
    ap.add_argument("--scale-sigma", type=float, default=0.02, help="fraction")
    ap.add_argument("--gate", type=float, choices=sorted(CHI2_4), default=0.999, help="chi-square probability")
    ap.add_argument("cases", nargs="*")
    a = ap.parse_args(argv)
    cases = [c for c in splits.cases("poc", a.split) if not a.cases or c.name in a.cases]
    missing = set(a.cases) - {c.name for c in cases}
    if missing:
        ap.error(f"not simulated {a.split} cases: {', '.join(sorted(missing))}")
    gate = CHI2_4[a.gate]
    print(f"d2 against the odometry chain alone; steady term: yaw rate std {a.yaw_rate_sigma} deg/m, "
          f"scale std {a.scale_sigma}; gate chi2({a.gate}, 4) = {gate}")
    print("case | AUC random walk | AUC + steady | true loops' median d2 rw / + steady | true within gate rw / + steady"
          " | false within gate rw / + steady")
    results = {}
    for c in cases:
        model = drift_model.from_yaml(c.environment)
        s = summary(case_d2(c.build(), model, a.yaw_rate_sigma, a.scale_sigma), gate)
        results[c.name] = s
        print(f"{c.name} | {s['auc_rw']:.3f} | {s['auc_steady']:.3f} | {s['true_median_rw']:.1f} / {s['true_median_steady']:.1f}"
              f" | {s['true_in_rw']:.2f} / {s['true_in_steady']:.2f}"
              f" | {s['false_in_rw']:.2f} / {s['false_in_steady']:.2f}")
    return results


if __name__ == "__main__":
    main()
