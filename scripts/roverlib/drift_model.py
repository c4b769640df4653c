"""The one drift model of the evaluation: how uncertain odometry is, for every method that needs
covariances where the data has none (simulated scenes and real VIO/VO runs; the g2o pose graphs
carry their own information matrices, which every method gets instead, ROVER through the
scenario's odometry.csv).

Odometry drifts by independent increments whose variance grows with the distance travelled:
a keyframe step of length l (at least `min_step`: turning in place still drifts) gets

    translation  sigma_xy^2 * l  per horizontal axis, sigma_z^2 * l vertically   [m^2]
    yaw          sigma_yaw^2 * l                                                [rad^2]
    roll, pitch  sigma_roll_pitch^2 * l  (6-DoF VO only; with an IMU gravity is observed and
                 loop_fusion's 4-DoF graph keeps the VIO's roll and pitch)

A loop measurement (PnP on the matched keyframe) has its own, distance-independent noise
`loop_sigma_t` per axis and `loop_sigma_yaw` (`loop_sigma_roll_pitch` in 6-DoF).

One source: the shipped verifier YAMLs. INDOOR and OUTDOOR are read from
config/rover_template.yaml with config/rover_indoor.yaml and rover_outdoor.yaml (drift_xy, drift_z, drift_yaw_deg,
drift_min_step, loop_sigma, loop_sigma_yaw_deg: the C++ verifier's drift model, core/drift.h),
so the peers (PCM, IPC, GNC, DCS) and the LM back end get the same model as ROVER. The YAMLs
have no roll/pitch terms (the core's drift model is 4-DoF: x, y, z, yaw); those stay the
constants ROLL_PITCH and LOOP_ROLL_PITCH below (6-DoF cases only: KITTI 09, parking-garage).
`as_params()` gives the model back under the YAML's keys.

`python -m roverlib.drift_model` prints the calibration of the tuning runs (robust per-metre
drift over 5-20 m segments: EuRoC MH_01 and MH_03 and two simulated scenes for indoor; the
tuning city scenes for outdoor) beside the model in use.
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
        """The model as verifier parameters, under the YAML's keys (YAML_KEYS; roll/pitch has
        none: the C++ drift model is 4-DoF)."""
        return {"drift_xy": self.sigma_xy, "drift_z": self.sigma_z, "drift_yaw_deg": float(np.degrees(self.sigma_yaw)),
                "drift_min_step": self.min_step, "loop_sigma": self.loop_sigma_t,
                "loop_sigma_yaw_deg": float(np.degrees(self.loop_sigma_yaw))}

    def __str__(self):
        return (f"{self.name}: xy {self.sigma_xy:g} m/sqrt(m), z {self.sigma_z:g} m/sqrt(m), yaw "
                f"{np.degrees(self.sigma_yaw):g} deg/sqrt(m), roll/pitch {self.sigma_roll_pitch:g} rad/sqrt(m) (6-DoF), "
                f"min step {self.min_step:g} m, loop {self.loop_sigma_t:g} m / {np.degrees(self.loop_sigma_yaw):g} deg")


# Roll and pitch drift [rad/sqrt(m)] (6-DoF only), which the YAMLs lack (the C++ drift model is
# 4-DoF): the values the evaluation used before the YAMLs became the source (indoor: half the
# yaw rate chosen then; outdoor: the outdoor yaw rate chosen then).
ROLL_PITCH = {"indoor": 0.004, "outdoor": 0.0025}
LOOP_ROLL_PITCH = float(np.radians(0.5))  # rad: a loop's roll/pitch noise (6-DoF only)
# The YAML keys of the model (config/rover_template.yaml, "drift model" block; drift_z named there).
YAML_KEYS = ("drift_xy", "drift_z", "drift_yaw_deg", "drift_min_step", "loop_sigma", "loop_sigma_yaw_deg")


def from_yaml(environment, path=None):
    """The drift model `environment` ships with (config/rover_template.yaml, then
    config/rover_<environment>.yaml: roverlib/config.py), or of the file `path` read in their
    place (a key it lacks: the template's named default): every number from the YAMLs except
    roll/pitch (ROLL_PITCH, LOOP_ROLL_PITCH). A missing key is an error."""
    from . import config
    if path is None:
        c = config.effective(environment)
    else:
        c = dict(config.defaults(), **config.load(path))
    missing = [k for k in YAML_KEYS if k not in c]
    if missing:
        raise ValueError(f"{path or environment}: no {', '.join(missing)}: the drift model is read from there")
    return DriftModel(environment, sigma_xy=float(c["drift_xy"]), sigma_z=float(c["drift_z"]),
                      sigma_yaw=float(np.radians(float(c["drift_yaw_deg"]))),
                      sigma_roll_pitch=ROLL_PITCH[environment], loop_sigma_t=float(c["loop_sigma"]),
                      loop_sigma_yaw=float(np.radians(float(c["loop_sigma_yaw_deg"]))),
                      loop_sigma_roll_pitch=LOOP_ROLL_PITCH, min_step=float(c["drift_min_step"]))


# What the indoor and outdoor configurations say (read when roverlib is imported).
INDOOR = from_yaml("indoor")
OUTDOOR = from_yaml("outdoor")
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
    """Prints the calibration of every tuning run beside the model in use (the YAML's)."""
    from . import splits
    for env in ("indoor", "outdoor"):
        for case in splits.drift_calibration_cases(env):
            s = case.build()
            c = calibrate([([k.T for k in s.keyframes], s.truth)])
            print(f"{env:8s} {case.name:40s} sigma_xy {c['sigma_xy']:.4f}  sigma_z {c['sigma_z']:.4f}  "
                  f"sigma_yaw {c['sigma_yaw']:.5f} rad ({c['segments']} segments)")
        m = MODELS[env]
        print(f"{env:8s} {'in use (rover_template.yaml + rover_' + env + '.yaml)':40s} sigma_xy {m.sigma_xy:.4f}  "
              f"sigma_z {m.sigma_z:.4f}  sigma_yaw {m.sigma_yaw:.5f} rad; loop {m.loop_sigma_t:g} m, "
              f"{np.degrees(m.loop_sigma_yaw):g} deg; min step {m.min_step:g} m; roll/pitch {m.sigma_roll_pitch:g} rad "
              "(constant, 6-DoF)")


if __name__ == "__main__":
    main()
