#!/usr/bin/env python3
"""Write the intake monitor's scenario sets: fixtures/sets/intake_tuning/ and
fixtures/sets/intake_heldout/ (Python 3 standard library only, deterministic).

    python3 tools/make_sets_intake.py [--check]

Each set is a directory of intake scenario files (fixtures/src/intake_sim.rs documents the
format), named after their `name` key. `fdd evaluate fixtures/sets/intake_tuning/` simulates
and scores them. `--check` writes nothing and exits 1 if a committed file differs from what the
script would write.

How the sets differ (also in fixtures/sets/README.md):

- **seeds**: the tuning set's scenario seeds are 10000 + i, the held-out set's 90000 + i, and
  every random choice below is drawn from a generator of its own per set (seed 1, and 9 for
  the tuning set's small-faults block; 13 for the held-out set); the held-out set is version 8
  (seeds 100000 + i): version 1 (seeds 20000 + i, generator seed 2), version 2 (30000 + i,
  seed 3), version 3 (40000 + i, seed 4), version 4 (50000 + i, seed 5), version 5
  (70000 + i, seed 10), version 6 (80000 + i, seed 11) and version 7 (90000 + i, seed 12)
  were each evaluated once and are retired;
- **drive styles**: tuning drives `mixed`, `tip_in_out` (EGR 0.2..0.4 in the tip-outs),
  `steady_holds` and `idle`; held-out drives `pedal_ramps`, `idle_blips` and `speed_sweep`,
  which the tuning set never sees;
- **plants**: every log draws its own plant and sensor calibration from the same stated ranges
  (PLANT below), from the set's own generator, so no held-out plant is a tuning plant;
- **fault sizes**: each fault's size is its reference size (REFERENCE below: the committed
  fixtures' sizes where a fixture has the fault) times a factor drawn from [0.75, 1.5];
- **lengths**: tuning logs last 4..6 min with the fault in the second half; held-out logs last
  10..12 min with the fault in the last 1.5..3 min, plus fully nominal logs of 15 min, so that
  the held-out set holds more than 10 h of fault-free driving.

Both sets hold every fault kind of the simulator, faults at idle or near idle, faults that end
(`end_s`), and logs with two faults at once.
"""

import argparse
import math
import os
import random
import sys

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
SETS = os.path.join(ROOT, "fixtures", "sets")

# Reference fault sizes. From the committed fixtures (fixtures/scenarios/intake_*.toml):
# map_bias 5 kPa, maf_gain 1.10, egr_stuck_open at 0.3, leak 3 mm. The other kinds have no
# fixture; their references are the sizes of tests/intake_fixtures.rs (map_gain 1.08,
# maf_bias 2 g/s) or chosen here: a drift that reaches the fixture's MAP bias (5 kPa) or a
# 2 g/s MAF error in 2 s, extra noise of about four times the sensor's own, a sluggish valve
# with the simulator's default 2 s time constant.
REFERENCE = {
    "map_bias": ("bias_pa", 5000.0),
    "map_gain": ("gain", 0.08),  # gain - 1
    "map_drift": ("rate_pa_per_s", 2500.0),
    "map_noise": ("std_pa", 3000.0),
    "maf_bias": ("bias_kg_s", 0.002),
    "maf_gain": ("gain", 0.10),  # gain - 1
    "maf_drift": ("rate_kg_s_per_s", 0.001),
    "maf_noise": ("std_rel", 0.06),
    "egr_stuck_open": ("position", 0.3),
    "egr_sluggish": ("time_constant_s", 2.0),
    "leak": ("diameter_m", 0.003),
}
SIZE_FACTOR = (0.75, 1.5)

KINDS = [
    "map_bias",
    "map_gain",
    "map_stuck",
    "map_open",
    "map_short",
    "map_drift",
    "map_noise",
    "maf_bias",
    "maf_gain",
    "maf_stuck",
    "maf_open",
    "maf_short",
    "maf_drift",
    "maf_noise",
    "egr_stuck_open",
    "egr_stuck_closed",
    "egr_sluggish",
    "leak",
]
# Kinds that show at idle with the EGR closed (an EGR valve stuck closed or sluggish does not).
IDLE_KINDS = {k for k in KINDS if k not in ("egr_stuck_closed", "egr_sluggish")}
# Kinds that need EGR commands to show.
EGR_KINDS = {"egr_stuck_closed", "egr_sluggish"}

# The plant and sensor perturbations every log draws from (uniform on each range; the same
# ranges for both sets): "a few percent" of model error, within which the default monitor
# config has to hold.
PLANT = {
    "param_rel_error": (0.0, 0.02),
    "ve_error_rel": (-0.01, 0.01),
    "ve_error_speed": (-0.01, 0.01),
    "ve_error_pressure": (-0.01, 0.01),
    "discharge_error_rel": (-0.02, 0.02),
    "discharge_error_angle": (-0.02, 0.02),
    "ambient_pressure_pa": (97000.0, 104000.0),
    "ambient_temperature_k": (283.0, 308.0),
}
SENSORS = {
    "map_noise_std_pa": (500.0, 1000.0),
    "maf_noise_rel": (0.01, 0.02),
    "map_gain": (0.995, 1.005),
    "map_offset_pa": (-300.0, 300.0),
    "map_time_constant_s": (0.005, 0.010),
    "maf_gain": (0.99, 1.01),
    "maf_time_constant_s": (0.010, 0.025),
}

TUNING_STYLES = ["mixed", "tip_in_out", "steady_holds"]
HELDOUT_STYLES = ["pedal_ramps", "speed_sweep"]


def fmt(v):
    """A TOML float that reads back exactly enough (6 significant digits)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    s = "%.6g" % v
    if "e" not in s and "." not in s and "inf" not in s and "nan" not in s:
        s += ".0"
    return s


def profile(rng, style):
    """`[profile]` lines of a drive style."""
    lines = ['kind = "%s"' % style]
    if style == "tip_in_out":
        lines.append("egr_pos = %s" % fmt(round(rng.uniform(0.2, 0.4), 3)))
    elif style == "idle":
        lines.append("speed_rpm = %s" % fmt(round(rng.uniform(750.0, 900.0), 1)))
        lines.append("throttle_deg = %s" % fmt(round(rng.uniform(1.8, 2.4), 2)))
    elif style == "idle_blips":
        lines.append("speed_rpm = %s" % fmt(round(rng.uniform(750.0, 900.0), 1)))
        lines.append("throttle_deg = %s" % fmt(round(rng.uniform(1.8, 2.4), 2)))
        lines.append("blip_prob = %s" % fmt(round(rng.uniform(0.2, 0.5), 2)))
    elif style == "speed_sweep":
        lines.append("sweep_s = %s" % fmt(round(rng.uniform(15.0, 40.0), 1)))
        lines.append("throttle_deg = %s" % fmt(round(rng.uniform(8.0, 30.0), 1)))
    return lines


def plant(rng):
    p = ["%s = %s" % (k, fmt(round(rng.uniform(*r), 6))) for k, r in PLANT.items()]
    s = ["%s = %s" % (k, fmt(round(rng.uniform(*r), 6))) for k, r in SENSORS.items()]
    return p, s


def fault_lines(rng, kind, start_s, end_s=None, size_factor=SIZE_FACTOR):
    """The lines of a `[fault]` table of `kind` with a random size (the reference size times a
    factor drawn from `size_factor`)."""
    lines = ['kind = "%s"' % kind, "start_s = %s" % fmt(round(start_s, 2))]
    if end_s is not None:
        lines.append("end_s = %s" % fmt(round(end_s, 2)))
    if kind in REFERENCE:
        key, ref = REFERENCE[kind]
        f = rng.uniform(*size_factor)
        if kind in ("map_gain", "maf_gain"):
            sign = rng.choice([-1.0, 1.0])
            v = 1.0 + sign * ref * f
        elif kind in ("map_bias", "maf_bias", "map_drift", "maf_drift"):
            v = rng.choice([-1.0, 1.0]) * ref * f
        elif kind == "egr_stuck_open":
            v = min(1.0, ref * f)
        else:
            v = ref * f
        lines.append("%s = %s" % (key, fmt(round(v, 6) if abs(v) > 1e-3 else float("%.4g" % v))))
    return lines


def scenario(name, seed, duration_s, style_lines, plant_lines, sensor_lines, faults, comment):
    out = ["# " + line for line in comment]
    out += [
        'name = "%s"' % name,
        'monitor = "intake"',
        "duration_s = %s" % fmt(round(duration_s, 1)),
        "seed = %d" % seed,
        "",
        "[profile]",
    ]
    out += style_lines
    out += ["", "[plant]"] + plant_lines + ["", "[sensors]"] + sensor_lines
    for table, lines in zip(["fault", "second_fault"], faults):
        out += ["", "[%s]" % table] + lines
    return "\n".join(out) + "\n"


def make_set(label, rng, seed0, n_per_kind, styles, idle_style, duration, onset_from_end,
             nominal, doubles, plant_fn=plant):
    """The files of one set as {name: text}; `plant_fn(rng)` gives each log's plant lines."""
    files = {}
    i = 0

    def next_seed():
        nonlocal i
        i += 1
        return seed0 + i

    for kind in KINDS:
        for rep in range(n_per_kind):
            # The first log of each idle-capable kind (every third for the others) runs at idle.
            at_idle = kind in IDLE_KINDS and rep == 0 and kind in (
                "leak", "egr_stuck_open", "map_bias", "maf_gain", "map_noise", "maf_stuck",
                "map_open", "maf_drift", "map_gain")
            if at_idle:
                style = idle_style
            elif kind == "egr_stuck_open" or kind in EGR_KINDS:
                # Needs EGR commands that differ from a stuck position.
                style = rng.choice([s for s in styles if s != "speed_sweep"])
            else:
                style = styles[(rep + KINDS.index(kind)) % len(styles)]
            d = rng.uniform(*duration)
            onset = d - rng.uniform(*onset_from_end)
            # About a quarter of the faults heal after 20..90 s (none in the last 30 s).
            end = None
            if rng.random() < 0.3:
                end = min(onset + rng.uniform(20.0, 90.0), d - 30.0)
                if end <= onset + 10.0:
                    end = None
            seed = next_seed()
            name = "intake_%s_%02d_%s_%s" % (label, i, kind, style)
            p, s = plant_fn(rng)
            comment = [
                "%s set: %s at %.0f s%s, %s drive; generated by tools/make_sets_intake.py"
                % (label, kind, onset, "" if end is None else " until %.0f s" % end, style)
            ]
            files[name] = scenario(name, seed, d, profile(rng, style), p, s,
                                   [fault_lines(rng, kind, onset, end)], comment)
    for kinds, style, overlap in doubles:
        d = rng.uniform(*duration)
        onset = d - rng.uniform(*onset_from_end)
        second = onset + (rng.uniform(5.0, 20.0) if overlap else rng.uniform(40.0, 60.0))
        seed = next_seed()
        name = "intake_%s_%02d_%s_and_%s" % (label, i, kinds[0], kinds[1])
        p, s = plant_fn(rng)
        comment = [
            "%s set: two faults, %s at %.0f s and %s at %.0f s, %s drive; generated by "
            "tools/make_sets_intake.py" % (label, kinds[0], onset, kinds[1], second, style)
        ]
        files[name] = scenario(
            name, seed, d, profile(rng, style), p, s,
            [fault_lines(rng, kinds[0], onset), fault_lines(rng, kinds[1], second)], comment)
    for n_nom, style, dur in nominal:
        for _ in range(n_nom):
            seed = next_seed()
            name = "intake_%s_%02d_nominal_%s" % (label, i, style)
            p, s = plant_fn(rng)
            comment = ["%s set: no fault, %s drive; generated by tools/make_sets_intake.py"
                       % (label, style)]
            files[name] = scenario(name, seed, rng.uniform(*dur), profile(rng, style), p, s,
                                   [['kind = "none"']], comment)
    return files


# The tuning set's second block: every kind once more at the small end of the held-out sizes
# (0.75..0.9 of the reference), where detection is slowest, on the tuning drive styles and at
# idle, from a generator of its own (seed 9) so that the first block stays as it was. Chosen
# after held-out version 3 had shown small faults to be the slow ones; it holds no held-out
# drive style.
SMALL_SIZE_FACTOR = (0.75, 0.9)


def small_faults_block(first_index):
    rng = random.Random(9)
    files = {}
    i = first_index
    for k, kind in enumerate(KINDS):
        i += 1
        if kind in EGR_KINDS or kind == "egr_stuck_open":
            style = rng.choice(["mixed", "tip_in_out", "steady_holds"])
        elif k % 2 == 0:
            style = "idle"
        else:
            style = TUNING_STYLES[(k // 2) % len(TUNING_STYLES)]
        d = rng.uniform(240.0, 300.0)
        onset = d - rng.uniform(60.0, 120.0)
        seed = 10000 + i
        name = "intake_tune_%02d_%s_%s_small" % (i, kind, style)
        p, sens = plant(rng)
        comment = ["tune set, small faults: %s at %.0f s, %s drive; generated by "
                   "tools/make_sets_intake.py" % (kind, onset, style)]
        files[name] = scenario(name, seed, d, profile(rng, style), p, sens,
                               [fault_lines(rng, kind, onset, None, SMALL_SIZE_FACTOR)], comment)
    return files


def all_sets():
    tuning = make_set(
        "tune", random.Random(1), 10000, 2, TUNING_STYLES, "idle", (240.0, 360.0),
        (60.0, 150.0),
        nominal=[(1, "mixed", (600.0, 600.0)), (1, "idle", (300.0, 300.0))],
        doubles=[
            (("map_stuck", "maf_open"), "mixed", True),
            (("leak", "egr_stuck_open"), "idle", True),
            (("maf_gain", "leak"), "tip_in_out", False),
        ],
    )
    tuning.update(small_faults_block(len(tuning)))
    heldout = make_set(
        "held", random.Random(13), 100000, 3, HELDOUT_STYLES, "idle_blips", (600.0, 720.0),
        (90.0, 180.0),
        nominal=[(4, "pedal_ramps", (900.0, 900.0)), (2, "idle_blips", (900.0, 900.0)),
                 (2, "speed_sweep", (900.0, 900.0))],
        doubles=[
            (("maf_stuck", "map_short"), "pedal_ramps", True),
            (("egr_stuck_open", "leak"), "idle_blips", True),
            (("map_bias", "egr_stuck_closed"), "pedal_ramps", False),
        ],
    )
    train, cal_heldout = calibration()
    return {"intake_tuning": tuning, "intake_heldout": heldout,
            "intake_calibrate_train": train, "intake_calibrate_heldout": cal_heldout}


# One plant beyond the range the embedded default configuration is meant to hold within
# (PLANT, SENSORS: parameters 0..2 % off, MAP noise 500..1000 Pa, MAF noise 1..2 %): every
# physical parameter up to 6 % off (one draw, `seed`), volumetric efficiency and throttle
# discharge 2..4 % off, MAP noise 2 kPa, MAF noise 4 %. Every log of the calibration sets is of
# this plant: `fdd calibrate` fits a configuration to the training log, and the held-out logs
# judge it (and the default configuration, for comparison).
CAL_PLANT = [
    ("param_rel_error", 0.06),
    ("ve_error_rel", 0.03),
    ("ve_error_speed", -0.02),
    ("ve_error_pressure", 0.02),
    ("discharge_error_rel", 0.04),
    ("discharge_error_angle", -0.03),
    ("ambient_pressure_pa", 99000.0),
    ("ambient_temperature_k", 300.0),
    ("seed", 515151),
]
CAL_SENSORS = [
    ("map_noise_std_pa", 2000.0),
    ("maf_noise_rel", 0.04),
    ("map_gain", 1.004),
    ("map_offset_pa", 400.0),
    ("map_time_constant_s", 0.012),
    ("maf_gain", 1.015),
    ("maf_time_constant_s", 0.03),
]


def cal_plant(_rng):
    return (["%s = %s" % (k, fmt(v)) for k, v in CAL_PLANT],
            ["%s = %s" % (k, fmt(v)) for k, v in CAL_SENSORS])


def calibration():
    """`intake_calibrate_train/`: one 30-minute fault-free `mixed` drive (a tuning style) of the
    calibration plant; `intake_calibrate_heldout/`: the held-out styles on that plant, version 3
    (seeds 62000 + i, generator seed 14; version 1, seeds 60000 + i and generator seed 7, and
    version 2, seeds 61000 + i and generator seed 8, were evaluated once and are retired):
    every fault kind three times and eight fault-free 30-minute drives."""
    train = {}
    name = "intake_calibrate_train_00_nominal_mixed"
    p, s = cal_plant(None)
    train[name] = scenario(
        name, 59000, 1800.0, profile(random.Random(6), "mixed"), p, s, [['kind = "none"']],
        ["calibration training log: no fault, mixed drive, the calibration plant; generated by "
         "tools/make_sets_intake.py"])
    heldout = make_set(
        "calibrate_heldout", random.Random(14), 62000, 3, HELDOUT_STYLES, "idle_blips",
        (600.0, 720.0), (90.0, 180.0),
        nominal=[(4, "pedal_ramps", (1800.0, 1800.0)), (2, "idle_blips", (1800.0, 1800.0)),
                 (2, "speed_sweep", (1800.0, 1800.0))],
        doubles=[],
        plant_fn=cal_plant,
    )
    return train, heldout


def dev_set():
    """A development set, not committed: the held-out recipe (styles, plants, sizes) with other
    seeds (300000 + i, generator seed 99), to try a change on before a held-out version is
    spent. Session 2026-12-06 chose the isolation margin on it and on the tuning set."""
    return make_set(
        "idev", random.Random(99), 300000, 3, HELDOUT_STYLES, "idle_blips", (600.0, 720.0),
        (90.0, 180.0),
        nominal=[],
        doubles=[
            (("map_bias", "egr_stuck_closed"), "speed_sweep", False),
            (("leak", "map_drift"), "pedal_ramps", True),
        ],
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="compare, write nothing")
    ap.add_argument("--dev", metavar="DIR",
                    help="write the development set (not committed) into DIR, nothing else")
    args = ap.parse_args()
    if args.dev:
        os.makedirs(args.dev, exist_ok=True)
        files = dev_set()
        for name, text in sorted(files.items()):
            with open(os.path.join(args.dev, name + ".toml"), "w", encoding="utf-8") as f:
                f.write(text)
        print("dev set: %d files in %s" % (len(files), args.dev))
        return 0
    bad = 0
    for set_name, files in all_sets().items():
        d = os.path.join(SETS, set_name)
        if not args.check:
            os.makedirs(d, exist_ok=True)
            for f in os.listdir(d):
                if f.endswith(".toml") and f[:-5] not in files:
                    os.remove(os.path.join(d, f))
        for name, text in sorted(files.items()):
            path = os.path.join(d, name + ".toml")
            if args.check:
                try:
                    with open(path, encoding="utf-8") as f:
                        same = f.read() == text
                except OSError:
                    same = False
                if not same:
                    print("differs: %s" % os.path.relpath(path, ROOT))
                    bad += 1
            else:
                with open(path, "w", encoding="utf-8") as f:
                    f.write(text)
        print("%s: %d files" % (set_name, len(files)))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
