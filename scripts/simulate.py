#!/usr/bin/env python3
"""Makes a scenario directory (docs/scenario-format.md): keyframes with drift, labelled loop
candidates, ground truth; fixed seed. With --bag also DIR/scenario.bag for rover_verifier_node
(keyframe poses + loop candidates; the labels stay in DIR).

  simulate.py --scene room|sports_ground|warehouse|parking_deck|corridor|city|kitti_route --sigma 0.05 --out DIR
  simulate.py --real euroc_mh01|euroc_mh03|euroc_mh05|euroc_mh04_mono{0,1,2}|kitti_09 --out DIR
  simulate.py --estimate EST.tum --groundtruth GT.tum --out DIR      (your own trajectory)

How hard the false candidates are: --lookalike-distance M (scenes: the aisle spacing, floor
height, door spacing or facade spacing a look-alike sits at; real runs: look-alikes M metres
sideways/vertically/along instead of far-apart places), --false-distance LO,HI (real runs:
far-apart places LO..HI metres apart, default 3,15; 10,60 outdoors), --rows N (look-alikes in
rows of N agreeing ones), --early-lookalike (a row before the first true loop).

Your own trajectory: a VIO/VO estimate and its ground truth as TUM files (stamp x y z qx qy qz
qw; stamps associated within 10 ms); keyframes are taken from the estimate, true candidates
at ground-truth revisits, false ones between places 3-15 m apart (10-60 m with --outdoor).

Run with /usr/bin/python3 (--bag: after sourcing the workspace's devel/setup.bash). Real data
is read from ../shared/data (ROVER_SHARED_DATA overrides)."""
import argparse
import os
import sys


from roverlib import real_data, scenario, scenes

BAG_NAME = "scenario.bag"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--scene", choices=sorted(scenes.SCENES))
    src.add_argument("--real", choices=sorted(real_data.SEQUENCES))
    src.add_argument("--estimate", metavar="EST.tum", help="your own VIO/VO estimate (TUM format)")
    ap.add_argument("--groundtruth", metavar="GT.tum", help="ground truth of --estimate (TUM format)")
    ap.add_argument("--outdoor", action="store_true", help="--estimate: outdoor distances (keyframes 1 m apart, ...)")
    ap.add_argument("--sigma", type=float, default=0.05, help="odometry noise level (simulated scenes)")
    ap.add_argument("--six-dof", action="store_true", help="roll/pitch drift too (VO without IMU)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--lookalike-distance", type=float, metavar="M",
                    help="distance of the look-alikes (scenes: " + ", ".join(f"{k}: {v}" for k, v in
                                                                     sorted(scenes.LOOKALIKE_DISTANCE.items())) + ")")
    ap.add_argument("--false-distance", metavar="LO,HI", help="real runs: far-apart false candidates LO..HI m apart")
    ap.add_argument("--rows", type=int, default=1, help="look-alikes in rows of N consecutive query keyframes")
    ap.add_argument("--early-lookalike", action="store_true", help="a row of look-alikes before the first true loop")
    ap.add_argument("--laps", type=int, help="laps of the room, sports ground, corridor, city")
    ap.add_argument("--true", dest="n_true", type=int, default=100)
    ap.add_argument("--false", dest="n_false", type=int, default=100)
    ap.add_argument("--out", required=True)
    ap.add_argument("--bag", action="store_true", help=f"also write OUT/{BAG_NAME} for rover_verifier_node")
    a = ap.parse_args(argv)
    if a.estimate and not a.groundtruth:
        ap.error("--estimate needs --groundtruth")
    if a.scene:
        extra = {}
        if a.lookalike_distance is not None:
            if a.scene not in scenes.LOOKALIKE_DISTANCE:
                ap.error(f"--lookalike-distance: the {a.scene}'s look-alikes mirror it (set by its size)")
            extra[scenes.LOOKALIKE_DISTANCE[a.scene]] = a.lookalike_distance
        if a.laps:
            extra["laps"] = a.laps
        if a.rows > 1 or a.early_lookalike:
            extra.update(rows=a.rows, early_lookalike=a.early_lookalike)
        s = scenes.make_scene(a.scene, a.sigma, a.seed, a.n_true, a.n_false, a.six_dof, **extra)
    else:
        name = a.real
        if a.estimate:
            name = "tum_" + os.path.splitext(os.path.basename(a.estimate))[0]
            real_data.SEQUENCES[name] = (os.path.abspath(a.estimate), os.path.abspath(a.groundtruth),
                                         "6dof" if a.six_dof else "4dof", "se3", "outdoor" if a.outdoor else "indoor")
        extra = {}
        if a.false_distance:
            extra["false_distance"] = tuple(float(x) for x in a.false_distance.split(","))
        if a.lookalike_distance is not None:
            extra["lookalike"] = dict(offset=a.lookalike_distance, rows=a.rows, early=a.early_lookalike)
        s = real_data.make_real(name, a.seed, a.n_true, a.n_false, **extra)
    scenario.write(s, a.out)
    print(f"{s.name}: {len(s.keyframes)} keyframes, {s.meta['true_candidates']} true and "
          f"{s.meta['false_candidates']} false candidates -> {a.out}")
    if a.bag:
        from roverlib import bag  # needs ROS (source devel/setup.bash)
        path = os.path.join(a.out, BAG_NAME)
        # From the files just written: the bag holds exactly the numbers the labels refer to.
        n_kf, n_c = bag.write_bag(scenario.read(a.out), path)
        print(f"{path}: {n_kf} keyframe poses on {bag.KEYFRAME_TOPIC}, {n_c} candidates on {bag.CANDIDATE_TOPIC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
