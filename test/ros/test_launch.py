#!/usr/bin/env python3
"""launch/vins_rover.launch, loaded with roslaunch's own XML loader (nothing is started, so
VINS-Fusion is not needed): the nodes it starts, the parameters the loop_fusion adapter and
the verifier plugin get for each verifier:=A/B choice, and the rviz config it points at."""
import os
import tempfile
import unittest

import roslaunch.config
import roslaunch.core
import roslaunch.xmlloader
import rospkg
import yaml

PKG = "rover_loop_fusion"
ROOT = rospkg.RosPack().get_path(PKG)
LAUNCH = os.path.join(ROOT, "launch", "vins_rover.launch")
VINS_CONFIG = "/path/to/VINS-Fusion/config/euroc/euroc_stereo_imu_config.yaml"
PARAM_NAMES = [  # keys config/rover_template.yaml sets; test_config.cpp checks the YAMLs
    "mode", "alignment", "threshold", "threshold_per_metre", "max_innovation",
    "max_innovation_per_metre", "max_iterations", "time_budget_ms",
    "function_tolerance", "odometry_neighbours", "loop_huber", "robust_candidate", "window_margin",
    "max_relative_translation", "max_relative_yaw_deg", "quaternion_tolerance"]


def load(*args, launch=LAUNCH):
    config = roslaunch.config.ROSLaunchConfig()
    roslaunch.xmlloader.XmlLoader().load(launch, config, argv=["config_file:=" + VINS_CONFIG] + list(args),
                                         verbose=False)
    params = {name: p.value for name, p in config.params.items()}
    nodes = {n.name: n for n in config.nodes}
    return params, nodes


class VinsRoverLaunch(unittest.TestCase):
    def test_default_starts_vins_and_patched_loop_fusion_with_the_rover_verifier(self):
        params, nodes = load()
        est, lf = nodes["vins_estimator"], nodes["loop_fusion"]
        self.assertEqual((est.package, est.type, est.args), ("vins", "vins_node", VINS_CONFIG))
        self.assertEqual((lf.package, lf.type, lf.args), ("loop_fusion", "loop_fusion_node", VINS_CONFIG))
        self.assertTrue(lf.required)
        self.assertEqual(params["/loop_fusion/verifier_type"], "rover_loop_fusion/TrajectoryPriorVerifier")
        self.assertEqual(params["/loop_fusion/verifier_name"], "rover")
        self.assertIs(params["/loop_fusion/fallback_to_accept_all"], False)
        self.assertEqual(params["/loop_fusion/verdict_log"], "")
        self.assertIs(params["/loop_fusion/publish_markers"], True)
        self.assertEqual(params["/loop_fusion/marker_frame"], "world")
        self.assertEqual(params["/loop_fusion/relocalisation"], "confirm")  # held until confirmed
        self.assertEqual(params["/loop_fusion/rover/threshold"], 0.2)  # config/rover_template.yaml
        for name in PARAM_NAMES:
            self.assertIn("/loop_fusion/rover/" + name, params)

    def test_verifier_arg_selects_the_plugin(self):
        for arg, plugin in [("rover", "rover_loop_fusion/TrajectoryPriorVerifier"),
                            ("accept_all", "rover_loop_fusion/AcceptAllVerifier"),
                            ("my_pkg/MyVerifier", "my_pkg/MyVerifier")]:
            params, _ = load("verifier:=" + arg)
            self.assertEqual(params["/loop_fusion/verifier_type"], plugin, arg)

    def test_outdoor_config_and_other_args(self):
        params, nodes = load("verifier_config:=" + os.path.join(ROOT, "config", "rover_outdoor.yaml"),
                             "verdict_log:=/tmp/b.csv", "verifier_name:=outdoor", "rviz:=false",
                             "estimator:=false", "fallback_to_accept_all:=true",
                             "relocalisation:=accept_unverified")
        self.assertEqual(params["/loop_fusion/outdoor/threshold"], 1.0)
        self.assertNotIn("/loop_fusion/rover/threshold", params)
        self.assertEqual(params["/loop_fusion/verifier_name"], "outdoor")
        self.assertEqual(params["/loop_fusion/verdict_log"], "/tmp/b.csv")
        self.assertIs(params["/loop_fusion/fallback_to_accept_all"], True)
        self.assertEqual(params["/loop_fusion/relocalisation"], "accept_unverified")
        self.assertEqual(sorted(nodes), ["loop_fusion"])

    def test_template_then_override_in_one_namespace(self):
        # Every launch file loads config/rover_template.yaml, then verifier_config, into the
        # verifier's namespace: the override's keys win, the template's others stay.
        def read(name):
            with open(os.path.join(ROOT, "config", name)) as f:
                return yaml.safe_load(f) or {}
        for env in ("indoor", "outdoor", "paper"):
            want = dict(read("rover_template.yaml"), **read("rover_%s.yaml" % env))
            override = "verifier_config:=" + os.path.join(ROOT, "config", "rover_%s.yaml" % env)
            for launch, ns in ((LAUNCH, "/loop_fusion/rover/"),
                               (os.path.join(ROOT, "launch", "verifier.launch"), "/rover_verifier/rover/"),
                               (os.path.join(ROOT, "launch", "demo.launch"), "/rover_verifier/rover/")):
                params, _ = load(override, launch=launch)
                got = {k[len(ns):]: v for k, v in params.items() if k.startswith(ns)}
                self.assertEqual(got, want, (env, launch))

    def test_rviz_config_shows_paths_and_verdict_markers(self):
        _, nodes = load()
        rviz = nodes["rover_rviz"]
        self.assertEqual((rviz.package, rviz.type), ("rviz", "rviz"))
        path = rviz.args.split("-d", 1)[1].strip()
        self.assertEqual(path, os.path.join(ROOT, "config", "rover_vins.rviz"))
        with open(path) as f:
            rviz_config = yaml.safe_load(f)
        manager = rviz_config["Visualization Manager"]
        self.assertEqual(manager["Global Options"]["Fixed Frame"], "world")
        shown = {(d["Class"], d.get("Topic", d.get("Marker Topic"))) for d in manager["Displays"]
                 if d.get("Enabled")}
        self.assertIn(("rviz/MarkerArray", "/loop_fusion/loop_markers"), shown)
        self.assertIn(("rviz/Path", "/loop_fusion/pose_graph_path"), shown)
        self.assertIn(("rviz/Path", "/vins_estimator/path"), shown)

    def test_config_file_is_required(self):
        loader = roslaunch.xmlloader.XmlLoader()
        loader.ignore_unset_args = False  # (not set by every roslaunch version's constructor)
        with self.assertRaisesRegex(roslaunch.core.RLException, "config_file"):
            loader.load(LAUNCH, roslaunch.config.ROSLaunchConfig(), argv=[], verbose=False)

    def test_missing_or_broken_parameter_file_stops_the_launch_naming_it(self):
        # A verifier YAML that does not exist or does not parse stops roslaunch before any
        # node starts, with the file in the message (values of the wrong type or range are
        # the adapter's business: test_adapter.cpp, AdapterStop.*).
        missing = "/nonexistent/rover_params.yaml"
        with self.assertRaisesRegex(roslaunch.core.RLException, "rover_params.yaml"):
            load("verifier_config:=" + missing)
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            f.write("threshold: [0.15\nmode: auto\n")
        try:
            with self.assertRaisesRegex(roslaunch.core.RLException, os.path.basename(f.name)):
                load("verifier_config:=" + f.name)
        finally:
            os.unlink(f.name)


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "vins_rover_launch", VinsRoverLaunch)
