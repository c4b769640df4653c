#!/usr/bin/env python3
"""Makes a scenario directory (docs/scenario-format.md): keyframes with drift, labelled loop
candidates, ground truth; fixed seed.

  simulate.py --scene room|sports_ground|warehouse|parking_deck|corridor --sigma 0.05 --out DIR
  simulate.py --real euroc_mh01|euroc_mh03|euroc_mh05|euroc_mh04_mono{0,1,2}|kitti_09 --out DIR

Run with /usr/bin/python3. Real data is read from ../shared/data (ROVER_SHARED_DATA
overrides)."""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from roverlib import real_data, scenario, scenes  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--scene", choices=sorted(scenes.SCENES))
    src.add_argument("--real", choices=sorted(real_data.SEQUENCES))
    ap.add_argument("--sigma", type=float, default=0.05, help="odometry noise level (simulated scenes)")
    ap.add_argument("--six-dof", action="store_true", help="roll/pitch drift too (VO without IMU)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--true", dest="n_true", type=int, default=100)
    ap.add_argument("--false", dest="n_false", type=int, default=100)
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if a.scene:
        s = scenes.make_scene(a.scene, a.sigma, a.seed, a.n_true, a.n_false, a.six_dof)
    else:
        s = real_data.make_real(a.real, a.seed, a.n_true, a.n_false)
    scenario.write(s, a.out)
    print(f"{s.name}: {len(s.keyframes)} keyframes, {s.meta['true_candidates']} true and "
          f"{s.meta['false_candidates']} false candidates -> {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
