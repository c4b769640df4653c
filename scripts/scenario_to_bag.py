#!/usr/bin/env python3
"""Writes DIR/scenario.bag from an existing scenario directory (docs/scenario-format.md):
keyframe poses on /vins_estimator/keyframe_pose, loop candidates on
/loop_fusion/loop_candidates; the labels stay in DIR. Same as scripts/simulate.py --bag.

  scenario_to_bag.py DIR [--out FILE]

Run with /usr/bin/python3 after sourcing the workspace's devel/setup.bash."""
import argparse
import os
import sys


from roverlib import bag, scenario  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenario", metavar="DIR")
    ap.add_argument("--out", help="bag file (default DIR/scenario.bag)")
    a = ap.parse_args(argv)
    s = scenario.read(a.scenario)
    path = a.out or os.path.join(a.scenario, bag.BAG_NAME)
    n_kf, n_c = bag.write_bag(s, path)
    print(f"{path}: {n_kf} keyframe poses on {bag.KEYFRAME_TOPIC}, {n_c} candidates on {bag.CANDIDATE_TOPIC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
