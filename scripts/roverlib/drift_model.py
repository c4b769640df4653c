"""The one drift model of the evaluation: how uncertain odometry is, for every method that needs
covariances where the data has none (simulated scenes and real VIO/VO runs; the g2o pose graphs
carry their own information matrices, which every method gets instead).

Odometry drifts by independent increments whose variance grows with the distance travelled:
a keyframe step of length l (at least `min_step`: turning in place still drifts) gets

    translation  sigma_xy^2 * l  per horizontal axis, sigma_z^2 * l vertically   [m^2]
    yaw          sigma_yaw^2 * l                                                [rad^2]
    roll, pitch  sigma_roll_pitch^2 * l  (6-DoF VO only; with an IMU gravity is observed and
                 loop_fusion's 4-DoF graph keeps the VIO's roll and pitch)

A loop measurement (PnP on the matched keyframe) has its own, distance-independent noise
`loop_sigma_t` per axis and `loop_sigma_yaw` (`loop_sigma_roll_pitch` in 6-DoF).

These numbers are meant to be given to the C++ verifier too (issue 12): `as_params()` names
them as parameters, so one set of numbers configures every method of a benchmark run.
The values below were chosen on the tuning split only (roverlib/splits.py), from
`python -m roverlib.drift_model` (robust per-metre drift over 5-20 m segments of the tuning
runs: EuRoC MH_01 and MH_03 and two simulated scenes for indoor; the tuning city scenes for
outdoor), the largest of each, rounded up.
"""
from dataclasses import dataclass

import numpy as np

from . import geometry as g

# rx, ry: roll and pitch of a 4-DoF graph are not estimated (VIO keeps them); the Pose3 edges the
# Python back ends use for 4-DoF still need a (tiny) variance there. Their residuals are zero by
# construction (every pose and measurement is a pure-yaw rotation); kept tiny because through
# the lever arm of a long chain it would add vertical uncertainty (1e-5 rad per edge: < 0.1 m
# over 3000 keyframes and 1 km).
FOUR_DOF_ROLL_PITCH_SIGMA = 1e-5  # rad


@dataclass(frozen=True)
class DriftModel:
    name: str
    sigma_xy: float  # m / sqrt(m), each horizontal axis
    sigma_z: float  # m / sqrt(m)
    sigma_yaw: float  # rad / sqrt(m)
    sigma_roll_pitch: float  # rad / sqrt(m), 6-DoF only
    loop_sigma_t: float  # m, each axis
    loop_sigma_yaw: float  # rad
    loop_sigma_roll_pitch: float  # rad, 6-DoF only
    min_step: float = 0.1  # m

    def step_covariance(self, length, dof):
        """6x6 covariance of one odometry step of `length` metres in gtsam's Pose3 tangent order
        (rx, ry, rz, tx, ty, tz), body frame. dof 4: roll/pitch fixed (FOUR_DOF_ROLL_PITCH_SIGMA)."""
        l = max(float(length), self.min_step)
        rp = self.sigma_roll_pitch ** 2 * l if dof == 6 else FOUR_DOF_ROLL_PITCH_SIGMA ** 2
        return np.diag([rp, rp, self.sigma_yaw ** 2 * l,
                        self.sigma_xy ** 2 * l, self.sigma_xy ** 2 * l, self.sigma_z ** 2 * l])

    def loop_covariance(self, dof):
        """6x6 covariance of a loop measurement, same order as step_covariance."""
        rp = self.loop_sigma_roll_pitch ** 2 if dof == 6 else FOUR_DOF_ROLL_PITCH_SIGMA ** 2
        return np.diag([rp, rp, self.loop_sigma_yaw ** 2] + [self.loop_sigma_t ** 2] * 3)

    def as_params(self):
        """The model as verifier parameters (names for the YAML of the C++ drift model)."""
        return {"drift_sigma_xy_per_sqrt_m": self.sigma_xy, "drift_sigma_z_per_sqrt_m": self.sigma_z,
                "drift_sigma_yaw_per_sqrt_m": self.sigma_yaw,
                "drift_sigma_roll_pitch_per_sqrt_m": self.sigma_roll_pitch,
                "drift_min_step": self.min_step, "loop_sigma_t": self.loop_sigma_t,
                "loop_sigma_yaw": self.loop_sigma_yaw, "loop_sigma_roll_pitch": self.loop_sigma_roll_pitch}


# Indoor (VIO, 4-DoF), from `python -m roverlib.drift_model`: EuRoC MH_01/MH_03 stereo VIO
# sigma_xy 0.018/0.026, sigma_z 0.015/0.011, sigma_yaw 0.0080/0.0060; the simulated warehouse and
# corridor at the tuning noise sigma 0.1 (0.5 m steps) 0.075/0.070, 0.037/0.036, 0.0042/0.0041.
# One model for all: the largest of each, rounded up (a model that underrates drift rejects true
# loops after long stretches; one that overrates it lets near look-alikes through).
INDOOR = DriftModel("indoor", sigma_xy=0.08, sigma_z=0.04, sigma_yaw=0.008, sigma_roll_pitch=0.004,
                    loop_sigma_t=0.1, loop_sigma_yaw=float(np.radians(1.0)),
                    loop_sigma_roll_pitch=float(np.radians(0.5)))
# Outdoor (car-scale VIO/VO), same command: the tuning city block and KITTI 05 route (simulated
# drift sigma 0.03, 2 m steps) 0.040/0.049, 0.021/0.022, 0.0024/0.0023. No real outdoor VO run is
# on the tuning side (KITTI 09 is test), so these numbers know nothing about real VO.
OUTDOOR = DriftModel("outdoor", sigma_xy=0.05, sigma_z=0.025, sigma_yaw=0.0025, sigma_roll_pitch=0.0025,
                     loop_sigma_t=0.2, loop_sigma_yaw=float(np.radians(1.0)),
                     loop_sigma_roll_pitch=float(np.radians(0.5)))
MODELS = {"indoor": INDOOR, "outdoor": OUTDOOR}


def segment_drift(vio, truth, min_length=5.0, max_length=20.0, stride=5):
    """Per-metre drift of a run: for segments i -> j whose true path length is in
    [min_length, max_length], the error of the VIO's relative pose against the truth's, in the
    yaw-only frame of i. Returns per-metre squared errors (N x 4: x, y, z, yaw), each e^2 / L."""
    P = np.array([T[:3, 3] for T in truth])
    steps = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))]
    out = []
    for i in range(0, len(truth), stride):
        j = int(np.searchsorted(steps, steps[i] + min_length))
        while j < len(truth) and steps[j] - steps[i] <= max_length:
            L = steps[j] - steps[i]
            rv, rt = g.relative(g.yaw_only(vio[i]), g.yaw_only(vio[j])), g.relative(g.yaw_only(truth[i]), g.yaw_only(truth[j]))
            e = np.r_[rv[:3, 3] - rt[:3, 3], g.wrap(g.yaw_of(rv[:3, :3]) - g.yaw_of(rt[:3, :3]))]
            out.append(e ** 2 / L)
            j += stride
    return np.array(out).reshape(-1, 4)


def calibrate(runs):
    """sigma_xy, sigma_z, sigma_yaw [per sqrt(m)] from [(vio poses, truth poses), ...]: the
    median of e^2/L over every segment, divided by the median of chi^2_1 (0.455), square root
    (robust to the odd bad stretch)."""
    e = np.vstack([segment_drift(v, t) for v, t in runs])
    med = np.median(e, axis=0) / 0.4549
    return {"sigma_xy": float(np.sqrt(0.5 * (med[0] + med[1]))), "sigma_z": float(np.sqrt(med[2])),
            "sigma_yaw": float(np.sqrt(med[3])), "segments": int(len(e))}


def main():
    """Prints the calibration of every tuning run (what INDOOR/OUTDOOR were chosen from)."""
    from . import splits
    for env in ("indoor", "outdoor"):
        for case in splits.drift_calibration_cases(env):
            s = case.build()
            c = calibrate([([k.T for k in s.keyframes], s.truth)])
            print(f"{env:8s} {case.name:40s} sigma_xy {c['sigma_xy']:.4f}  sigma_z {c['sigma_z']:.4f}  "
                  f"sigma_yaw {c['sigma_yaw']:.5f}  ({c['segments']} segments)")
        print(f"{env:8s} chosen: {MODELS[env]}")


if __name__ == "__main__":
    main()
