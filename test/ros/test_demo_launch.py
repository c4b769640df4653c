#!/usr/bin/env python3
"""launch/demo.launch and launch/verifier.launch, loaded with roslaunch's XML loader (nothing
is started; the demo itself runs in bag_regression.test's way and in scripts/demo.sh): the two
verifier nodes with the shipped YAML, the replay node that ends the launch, rviz only on
request, the threshold override."""
import os
import unittest

import roslaunch.config
import roslaunch.xmlloader
import rospkg
import yaml

PKG = "rover_loop_fusion"
ROOT = rospkg.RosPack().get_path(PKG)


def load(name, *args):
    config = roslaunch.config.ROSLaunchConfig()
    roslaunch.xmlloader.XmlLoader().load(os.path.join(ROOT, "launch", name), config, argv=list(args), verbose=False)
    return {n: p.value for n, p in config.params.items()}, {n.name: n for n in config.nodes}


class DemoLaunch(unittest.TestCase):
    def test_headless_demo_replays_the_shipped_bag_into_rover_and_accept_all(self):
        params, nodes = load("demo.launch")
        self.assertEqual(sorted(nodes), ["accept_all_verifier", "rover_demo", "rover_verifier"])
        for name in ("rover_verifier", "accept_all_verifier"):
            self.assertEqual((nodes[name].package, nodes[name].type), (PKG, "rover_verifier_node"))
            self.assertTrue(nodes[name].required)
        self.assertEqual(params["/rover_verifier/verifier_type"], "rover")
        self.assertEqual(params["/accept_all_verifier/verifier_type"], "accept_all")
        indoor = {}
        for name in ("rover_template.yaml", "rover_indoor.yaml"):  # the template, then the override
            with open(os.path.join(ROOT, "config", name)) as f:
                indoor.update(yaml.safe_load(f) or {})
        for key, value in indoor.items():
            self.assertEqual(params["/rover_verifier/rover/" + key], value, key)
        demo = nodes["rover_demo"]
        self.assertEqual(demo.type, "replay_bag.py")
        self.assertTrue(demo.required, "the summary ends the launch")
        self.assertEqual(params["/rover_demo/bag"], os.path.join(ROOT, "data", "corridor", "scenario.bag"))
        self.assertTrue(os.path.exists(params["/rover_demo/bag"]))
        self.assertEqual(params["/rover_demo/verifier"], "/rover_verifier")
        self.assertEqual(params["/rover_demo/baseline"], "/accept_all_verifier")
        self.assertEqual(params["/rover_demo/rate"], 0.0)

    def test_replay_false_leaves_the_replay_to_demo_sh_with_its_parameters(self):
        params, nodes = load("demo.launch", "replay:=false", "verbose:=false")
        self.assertEqual(sorted(nodes), ["accept_all_verifier", "rover_verifier"])
        self.assertEqual(params["/rover_demo/bag"], os.path.join(ROOT, "data", "corridor", "scenario.bag"))
        self.assertEqual(params["/rover_demo/verifier"], "/rover_verifier")
        self.assertEqual(params["/rover_demo/baseline"], "/accept_all_verifier")
        self.assertIs(params["/rover_demo/verbose"], False)

    def test_rviz_and_threshold_args(self):
        params, nodes = load("demo.launch", "rviz:=true", "threshold:=0.5")
        rviz = nodes["rover_rviz"]
        self.assertEqual(rviz.args.split("-d", 1)[1].strip(), os.path.join(ROOT, "config", "rover_demo.rviz"))
        self.assertTrue(rviz.required)
        self.assertFalse(nodes["rover_demo"].required, "with rviz the launch ends when rviz is closed")
        self.assertEqual(params["/rover_demo/rate"], 5.0)
        self.assertEqual(params["/rover_verifier/rover/threshold"], 0.5)
        with open(os.path.join(ROOT, "config", "rover_demo.rviz")) as f:
            manager = yaml.safe_load(f)["Visualization Manager"]
        topics = {d.get("Topic", d.get("Marker Topic")) for d in manager["Displays"]}
        for t in ("/rover_verifier/pose_graph_path", "/accept_all_verifier/pose_graph_path",
                  "/rover_verifier/odometry_path", "/rover_verifier/loop_markers"):
            self.assertIn(t, topics)
        self.assertEqual(manager["Global Options"]["Fixed Frame"], "world")

    def test_verifier_launch_defaults(self):
        params, nodes = load("verifier.launch")
        node = nodes["rover_verifier"]
        self.assertEqual(node.type, "rover_verifier_node")
        self.assertEqual(params["/rover_verifier/keyframe_topic"], "/vins_estimator/keyframe_pose")
        self.assertEqual(params["/rover_verifier/candidate_topic"], "/loop_fusion/loop_candidates")
        self.assertEqual(params["/rover_verifier/rover/threshold"], 0.2)
        self.assertNotIn("/rover_verifier/threshold", params)
        self.assertEqual(params["/rover_verifier/relocalisation"], "confirm")
        # Respawned when it exits (the master watchdog exits after a master restart), unless
        # it is required (roslaunch refuses both).
        self.assertTrue(node.respawn)
        self.assertFalse(node.required)
        _, nodes = load("verifier.launch", "required:=true")
        self.assertTrue(nodes["rover_verifier"].required)
        self.assertFalse(nodes["rover_verifier"].respawn)
        params, _ = load("verifier.launch", "name:=b", "verifier:=accept_all",
                         "verifier_config:=" + os.path.join(ROOT, "config", "rover_outdoor.yaml"))
        self.assertEqual(params["/b/verifier_type"], "accept_all")
        self.assertEqual(params["/b/rover/threshold"], 1.0)
        # The global pass: not set (the core's default, off) unless the arg sets it.
        self.assertNotIn("/b/rover/global_check", params)
        params, _ = load("verifier.launch", "global_check:=true")
        self.assertIs(params["/rover_verifier/rover/global_check"], True)
        # ...and its budget per pass: not set (the core's 200 ms) unless the arg sets it.
        self.assertNotIn("/rover_verifier/rover/global_budget_ms", params)
        params, _ = load("verifier.launch", "global_budget_ms:=50")
        self.assertEqual(params["/rover_verifier/rover/global_budget_ms"], 50.0)


if __name__ == "__main__":
    import rostest
    rostest.rosrun(PKG, "demo_launch", DemoLaunch)
