"""The tuning and test sets of every benchmark family, in one place.

Defaults (thresholds, gates, drift model, peers' settings) may be chosen on the TUNING cases
only; the docs report the TEST cases. The two never share a simulated (scene, seed) pair, and
never a real sequence, in any family (KITTI 00 is a pose graph, a route for simulated drift and
a real run alike: it is on one side only). test_splits.py checks it.

  poc        simulated scenes (roverlib/scenes.py): the paper's PoC grid and the hard cases
  real       real VIO/VO runs (roverlib/real_data.py): far-apart and near look-alike candidates
  posegraph  g2o pose graphs with injected outliers (roverlib/g2o.py)

Tuning keeps what the shipped defaults were chosen on before this split existed (seed 0 of
the five scenes at sigma 0.05/0.1/0.175, EuRoC MH_01 and MH_03, manhattan3500); the old sweep
also used MH_05 and MH_04 trial 0, now test: the docs say so for the "before" figures.
Hard cases are on both sides: look-alikes 1-3 m away laterally, vertically and along the track,
rows of agreeing look-alikes, a look-alike row before the first true loop, odometry noise up to
sigma 0.35, long laps (city scale) with the first loop after a long stretch, matches many laps
old, and a scene without true loops (named so).
"""
from dataclasses import dataclass

FAMILIES = ("poc", "real", "posegraph")
SPLITS = ("tuning", "test")


@dataclass(frozen=True)
class Case:
    family: str
    split: str
    name: str
    environment: str  # indoor | outdoor: which shipped YAML decides, which drift model
    args: tuple  # builder keyword arguments as sorted (key, value) pairs
    quick: bool = False  # part of the family's --quick run (CI)
    notes: str = ""  # what makes it hard, in words for the tables
    true_loops: bool = True  # False: the scene has none (its name says so too)

    @property
    def kwargs(self):
        return dict(self.args)

    @property
    def seed(self):
        return self.kwargs.get("seed", 0)

    @property
    def sequence(self):
        """The real sequence the case is made from (None for purely simulated scenes)."""
        k = self.kwargs
        if self.family == "poc":
            return f"kitti_{k['sequence']}" if k["name"] == "kitti_route" else None
        if self.family == "real":
            n = k["name"]
            return "euroc_mh04" if n.startswith("euroc_mh04") else n
        return k["graph"]

    @property
    def scene_seed(self):
        """(scene, seed) of a simulated case, None otherwise."""
        return (self.kwargs["name"], self.seed) if self.family == "poc" else None

    def build(self):
        """The Scenario (poc, real); pose-graph cases are built by scripts/bench/posegraph.py."""
        if self.family == "poc":
            from . import scenes
            return scenes.make_scene(**self.kwargs)
        if self.family == "real":
            from . import real_data
            k = self.kwargs
            if "lookalike" in k:
                k["lookalike"] = dict(k["lookalike"])
            return real_data.make_real(**k)
        raise ValueError("pose-graph cases are built from their graph (bench/posegraph.py)")


def _case(family, split, case_name, environment, quick=False, notes="", true_loops=True, **args):
    return Case(family, split, case_name, environment, tuple(sorted(args.items())), quick, notes, true_loops)


def _poc():
    out = []
    # tuning: what the shipped defaults were chosen on (seed 0), plus hard cases of their own
    for scene in ("room", "sports_ground", "warehouse", "corridor", "parking_deck"):
        for sigma in (0.05, 0.1, 0.175):
            nt = scene != "parking_deck"
            name = f"{scene}_s{sigma:g}" + ("" if nt else "_no_true_loops")
            out.append(_case("poc", "tuning", name, "indoor", true_loops=nt, notes="" if nt else "no true loops: every accepted loop is false", name=scene, sigma=sigma,
                             seed=0))
    hard_tuning = [
        ("warehouse_aisles2m_rows", "indoor", "aisles 2 m apart, rows of 5, a row before the first true loop",
         dict(name="warehouse", sigma=0.1, seed=1, spacing=2.0, rows=5, early_lookalike=True, random_fraction=0.0)),
        ("parking_deck_floors2m_two_ascents", "indoor", "floors 2 m apart, rows of 5",
         dict(name="parking_deck", sigma=0.05, seed=2, floor_height=2.0, ascents=2, rows=5, random_fraction=0.0)),
        ("corridor_doors1.5m_10laps", "indoor", "doors 1.5 m apart, 10 laps (matches laps old), rows, early row",
         dict(name="corridor", sigma=0.05, seed=3, door_spacing=1.5, laps=10, rows=5, early_lookalike=True,
              random_fraction=0.0)),
        ("room_s0.35", "indoor", "odometry noise sigma 0.35", dict(name="room", sigma=0.35, seed=4)),
        ("corridor_s0.25_doors2m", "indoor", "sigma 0.25, doors 2 m apart, rows",
         dict(name="corridor", sigma=0.25, seed=5, door_spacing=2.0, laps=4, rows=5, random_fraction=0.0)),
        ("city_600m_laps", "outdoor", "600 m laps in two lanes: first true loop after 1200 m; lane/facade twins",
         dict(name="city", sigma=0.03, seed=6, rows=5, early_lookalike=True, random_fraction=0.0)),
        ("kitti_05_route", "outdoor", "KITTI 05 streets, simulated drift; lane/facade twins, rows",
         dict(name="kitti_route", sequence="05", sigma=0.03, seed=7, rows=5, random_fraction=0.0)),
        # steady drift (a gyro bias, a scale error) on top of the random walk: scenes.add_drift
        ("corridor_yaw0.2_scale2pct", "indoor", "steady drift: 0.2 deg/m of yaw, 2 % scale, 3 laps",
         dict(name="corridor", sigma=0.05, seed=8, yaw_bias=0.2, scale_error=0.02)),
        ("warehouse_yaw0.15", "indoor", "steady drift: 0.15 deg/m of yaw",
         dict(name="warehouse", sigma=0.05, seed=9, yaw_bias=0.15)),
        ("room_yaw0.3", "indoor", "steady drift: 0.3 deg/m of yaw", dict(name="room", sigma=0.05, seed=10, yaw_bias=0.3)),
    ]
    for name, env, notes, args in hard_tuning:
        out.append(_case("poc", "tuning", name, env, notes=notes, **args))
    # test: the paper's PoC grid on new seeds and new scene sizes
    grid = (("room", dict(width=9.0, depth=7.0)), ("sports_ground", dict(straight=40.0, radius=12.0)),
            ("warehouse", dict(aisles=7)))
    seed = 100
    for scene, params in grid:
        for sigma in (0.01, 0.05, 0.1, 0.15, 0.175):
            out.append(_case("poc", "test", f"{scene}_s{sigma:g}", "indoor", quick=(scene, sigma) == ("room", 0.05),
                             name=scene, sigma=sigma, seed=seed, **params))
            seed += 1
    hard_test = [
        ("warehouse_aisles1.5m_rows", "indoor", "aisles 1.5 m apart, rows of 5, a row before the first true loop",
         dict(name="warehouse", sigma=0.05, seed=120, spacing=1.5, rows=5, early_lookalike=True, random_fraction=0.0),
         True),
        ("warehouse_aisles2.5m_s0.1", "indoor", "aisles 2.5 m apart, rows of 5",
         dict(name="warehouse", sigma=0.1, seed=121, spacing=2.5, rows=5, random_fraction=0.0), False),
        ("parking_deck_floors1.5m_two_ascents", "indoor", "floors 1.5 m apart, rows of 5, a row before the first true loop",
         dict(name="parking_deck", sigma=0.05, seed=122, floor_height=1.5, ascents=2, rows=5, early_lookalike=True,
              random_fraction=0.0), False),
        ("parking_deck_floors3m_spiral_no_true_loops", "indoor", "no true loops: every accepted loop is false",
         dict(name="parking_deck", sigma=0.1, seed=123, floor_height=3.0), False),
        ("corridor_doors1m_12laps", "indoor", "doors 1 m apart, 12 laps (matches 11 laps old), rows, early row",
         dict(name="corridor", sigma=0.05, seed=124, door_spacing=1.0, laps=12, rows=5, early_lookalike=True,
              random_fraction=0.0, min_false_distance=0.75), False),
        ("corridor_s0.25_doors2m", "indoor", "sigma 0.25, doors 2 m apart, rows",
         dict(name="corridor", sigma=0.25, seed=125, door_spacing=2.0, laps=4, rows=5, random_fraction=0.0), False),
        ("room_s0.25", "indoor", "odometry noise sigma 0.25", dict(name="room", sigma=0.25, seed=126), False),
        ("warehouse_s0.35", "indoor", "odometry noise sigma 0.35", dict(name="warehouse", sigma=0.35, seed=127), False),
        ("city_900m_laps", "outdoor", "900 m laps in two lanes: first true loop after 1800 m; lane/facade twins",
         dict(name="city", sigma=0.03, seed=128, block=(300.0, 150.0), rows=5, early_lookalike=True,
              random_fraction=0.0), False),
        ("kitti_00_route", "outdoor", "KITTI 00 streets, simulated drift; lane/facade twins, rows",
         dict(name="kitti_route", sequence="00", sigma=0.03, seed=129, rows=5, random_fraction=0.0), False),
        ("corridor_yaw0.25_scale2pct", "indoor", "steady drift: 0.25 deg/m of yaw, 2 % scale, 4 laps",
         dict(name="corridor", sigma=0.05, seed=130, laps=4, yaw_bias=0.25, scale_error=0.02), False),
        ("warehouse_yaw0.2_aisles2.5m", "indoor", "steady drift: 0.2 deg/m of yaw; aisles 2.5 m apart, rows of 5",
         dict(name="warehouse", sigma=0.05, seed=131, spacing=2.5, rows=5, random_fraction=0.0, yaw_bias=0.2), False),
        ("sports_ground_yaw0.1_scale-1pct", "indoor", "steady drift: 0.1 deg/m of yaw, -1 % scale",
         dict(name="sports_ground", sigma=0.05, seed=132, yaw_bias=0.1, scale_error=-0.01), False),
        ("room_yaw0.4", "indoor", "steady drift: 0.4 deg/m of yaw", dict(name="room", sigma=0.05, seed=133, yaw_bias=0.4),
         False),
    ]
    for name, env, notes, args, quick in hard_test:
        out.append(_case("poc", "test", name, env, quick=quick, notes=notes,
                         true_loops=not name.endswith("no_true_loops"), **args))
    return out


REAL_TUNING = ("euroc_mh01", "euroc_mh03")
REAL_TEST = ("euroc_mh05", "euroc_mh04_mono0", "euroc_mh04_mono1", "euroc_mh04_mono2", "kitti_09")


def _real():
    out = []
    for split, names, seed in (("tuning", REAL_TUNING, 0), ("test", REAL_TEST, 100)):
        for i, name in enumerate(names):
            outdoor = name.startswith("kitti")
            env = "outdoor" if outdoor else "indoor"
            far = "10-60 m" if outdoor else "3-15 m"
            out.append(_case("real", split, f"{name}_far", env, quick=split == "test" and i == 0,
                             notes=f"false: places {far} apart", name=name, seed=seed))
            first = ("lateral", "vertical", "along")[i % 3]
            offset = 3.0 if outdoor else 1.5
            # KITTI 09 revisits one place, at its end, where its look-alikes are too: rows there
            # (or a row before it) would take the queries of every true loop
            rows = 1 if outdoor else 3
            out.append(_case("real", split, f"{name}_near_{first}", env,
                             notes=f"false: look-alikes {offset:g} m away ({first} first)" +
                             ("" if outdoor else ", rows of 3, a row before the first true loop"),
                             name=name, seed=seed + 1,
                             lookalike=(("early", not outdoor), ("first", first), ("offset", offset), ("rows", rows))))
    return out


POSEGRAPH_TUNING = ("manhattan3500", "ring")
POSEGRAPH_TEST = ("ringCity", "kitti_00", "parking-garage")
POSEGRAPH_KINDS = ("random", "local", "grouped", "repetitive", "near")


def _posegraph():
    out = []
    for split, graphs, fractions, seed in (("tuning", POSEGRAPH_TUNING, (0.1, 0.2, 0.5), 0),
                                           ("test", POSEGRAPH_TEST, (0.2, 0.5), 100)):
        for graph in graphs:
            for kind in POSEGRAPH_KINDS:
                for fraction in fractions:
                    quick = split == "test" and graph == "ringCity" and fraction == 0.2 and kind == "near"
                    out.append(_case("posegraph", split, f"{graph}_{kind}_{int(round(fraction * 100))}",
                                     "outdoor", quick=quick, graph=graph, kind=kind, fraction=fraction, seed=seed))
    return out


def cases(family=None, split=None, quick=False):
    """The cases of a family and split (None: all), in table order; quick: only the CI subset."""
    every = _poc() + _real() + _posegraph()
    return [c for c in every if (family is None or c.family == family) and (split is None or c.split == split)
            and (not quick or c.quick)]


def drift_calibration_cases(environment):
    """The tuning runs drift_model.INDOOR/OUTDOOR were calibrated on."""
    if environment == "indoor":
        return [c for c in cases("real", "tuning") if c.name.endswith("_far")] + \
            [c for c in cases("poc", "tuning") if c.name in ("warehouse_s0.1", "corridor_s0.1")]
    return [c for c in cases("poc", "tuning") if c.environment == "outdoor"]


def overlaps():
    """What the tuning and test sets share: (scene, seed) pairs and real sequences. Empty."""
    tun, tst = cases(split="tuning"), cases(split="test")
    pairs = {c.scene_seed for c in tun if c.scene_seed} & {c.scene_seed for c in tst if c.scene_seed}
    seqs = {c.sequence for c in tun if c.sequence} & {c.sequence for c in tst if c.sequence}
    return sorted(pairs), sorted(seqs)
