#!/usr/bin/env python3
"""Regenerates the bags shipped with the package (fixed seeds; a few hundred kB in total):

  data/corridor/      the demo (launch/demo.launch): a 20 m x 10 m corridor loop driven three
                      times, odometry noise sigma 0.05, 40 true + 40 false candidates (look-alike
                      doors 3 m along the corridor, random pairs)
  data/warehouse/     the paper's Warehouse scene (aisles 3 m apart), sigma 0.05, 40 + 40
  data/euroc_mh05/    EuRoC MH_05 stereo VIO estimate (real drift) from ../shared/data, 40 + 40
                      candidates from its ground truth; without groundtruth.csv (we do not
                      ship copies of the data set's ground truth: regenerate it for ATE)
  test/data/malformed/ malformed.bag + expected.csv: every kind of bad input (test/ros/malformed.test)

Each data/ directory is a scenario directory (keyframes.csv, candidates.csv with the labels,
groundtruth.csv) plus scenario.bag, as `scripts/simulate.py ... --bag` writes it.

  /usr/bin/python3 scripts/make_shipped_data.py [--out ROOT]   (after sourcing devel/setup.bash)

--out writes under another root (the test that checks the shipped files are reproducible)."""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))

import simulate  # noqa: E402
from roverlib import bag  # noqa: E402

ROOT = os.path.dirname(HERE)
SHIPPED = {  # directory -> simulate.py arguments
    "data/corridor": ["--scene", "corridor", "--sigma", "0.05", "--seed", "0", "--true", "40", "--false", "40"],
    "data/warehouse": ["--scene", "warehouse", "--sigma", "0.05", "--seed", "0", "--true", "40", "--false", "40"],
    "data/euroc_mh05": ["--real", "euroc_mh05", "--seed", "0", "--true", "40", "--false", "40"],
}
NO_TRUTH = {"data/euroc_mh05"}
MALFORMED = "test/data/malformed"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=ROOT, help="root directory (default: this repository)")
    ap.add_argument("--only", nargs="*", help="only these directories")
    a = ap.parse_args(argv)
    for d, args in SHIPPED.items():
        if a.only and d not in a.only:
            continue
        simulate.main(args + ["--out", os.path.join(a.out, d), "--bag"])
        if d in NO_TRUTH:
            os.remove(os.path.join(a.out, d, "groundtruth.csv"))
    if not a.only or MALFORMED in a.only:
        msgs, expect = bag.write_malformed(os.path.join(a.out, MALFORMED))
        print(f"{os.path.join(a.out, MALFORMED)}: {len(msgs)} messages, {len(expect)} candidates")
    return 0


if __name__ == "__main__":
    sys.exit(main())
