#!/usr/bin/env python3
"""Writes the throttle scenario sets: fixtures/sets/throttle_tuning/ and throttle_heldout/.

Deterministic (fixed seeds): running it again rewrites the same files (`--check` compares
and writes nothing). The two sets differ in
everything a new vehicle would change (fixtures/sets/README.md says how):

- tuning: seeds 1000+, excitation pulse_train / chirp / pedal_ramps, wattmeter noise 0.05 to
  0.4 W, TPS noise 4-10 mV, TPS gain/offset within 1.5 % / 15 mV, wattmeter gain within 4 %,
  lags, Table I error up to 1 %, restitution 0.2, fault sizes as the committed fixtures',
  process noise x0.5 to x2 and a block of quiet plates (x0.05 to x0.3);
- held-out: seeds 33000+ (version 15), excitation steady_holds / idle_blips / mixed, wattmeter noise 0.05 to
  0.5 W, Table I error up to 1.5 %, stops and restitution, TPS and wattmeter gain and offset
  errors and lags, process noise x0.08 to x2, fault sizes 0.75 to 1.5 times the fixtures',
  long fault-free driving (>= 10 h in all).

Nothing in the monitors may be chosen by looking at results on the held-out set.

Usage: python3 tools/make_sets_throttle.py   (from the repository root)
"""

import os
import random
import shutil
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SETS = os.path.join(ROOT, "fixtures", "sets")

# Fault sizes of the committed fixtures (fixtures/scenarios/throttle_*.toml).
FIXTURE = {
    "tps_bias": {"bias_deg": 8.0},
    "tps_drift": {"drift_deg_per_s": 2.0},
    "tps_noise": {"noise_std_v": 0.2},
    "tps_intermittent": {"dropout_rate_hz": 5.0},
    "wattmeter": {"gain": 1.0, "offset_w": 0.3},
}
KINDS = [
    "tps_stuck",
    "tps_bias",
    "tps_drift",
    "tps_open",
    "tps_short",
    "tps_intermittent",
    "tps_noise",
    "wattmeter",
    "plate_stuck",
]


def fmt(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int,)):
        return str(v)
    if isinstance(v, float):
        return repr(round(v, 6))
    if isinstance(v, str):
        return '"%s"' % v
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(fmt(x) for x in v) + "]"
    raise TypeError(v)


def table(name, d):
    lines = ["[%s]" % name]
    for k, v in d.items():
        lines.append("%s = %s" % (k, fmt(v)))
    return "\n".join(lines) + "\n"


def fault_table(rng, kind, start_s, scale, end_s=None):
    f = {"kind": kind, "start_s": start_s}
    if end_s is not None:
        f["end_s"] = end_s
    for k, v in FIXTURE.get(kind, {}).items():
        if kind == "wattmeter" and k == "gain":
            # A shunt/gain error of the same relative size as the offset's.
            f[k] = 1.0 + (0.15 * scale if rng.random() < 0.5 else 0.0)
        else:
            sign = -1.0 if (kind in ("tps_bias", "tps_drift") and rng.random() < 0.5) else 1.0
            f[k] = sign * v * scale
    return f


def scenario(name, seed, duration_s, excitation, sensors, plant, fault, second=None, comment=""):
    text = "# %s\n" % comment if comment else ""
    text += 'name = "%s"\nmonitor = "throttle"\nduration_s = %s\nseed = %d\n\n' % (
        name,
        fmt(float(duration_s)),
        seed,
    )
    text += table("excitation", excitation) + "\n"
    text += table("sensors", sensors) + "\n"
    if plant:
        text += table("plant", plant) + "\n"
    text += table("fault", fault)
    if second:
        text += "\n" + table("second_fault", second)
    return text


def check_set(dirname, items):
    """Number of files of the set that differ from what would be written (or are extra)."""
    d = os.path.join(SETS, dirname)
    want = {name + ".toml": text for name, text in items}
    bad = 0
    have = set(os.listdir(d)) if os.path.isdir(d) else set()
    for f in sorted(have - set(want)):
        if f.endswith(".toml"):
            print("extra: %s" % os.path.join(dirname, f))
            bad += 1
    for f, text in sorted(want.items()):
        try:
            with open(os.path.join(d, f), encoding="utf-8") as fh:
                same = fh.read() == text
        except OSError:
            same = False
        if not same:
            print("differs: %s" % os.path.join(dirname, f))
            bad += 1
    return bad


def write_set(dirname, items):
    d = os.path.join(SETS, dirname)
    if os.path.isdir(d):
        shutil.rmtree(d)
    os.makedirs(d)
    for name, text in items:
        with open(os.path.join(d, name + ".toml"), "w") as f:
            f.write(text)


def wide_draw(r, table1_errors, process_noise):
    """Sensors and plant over the whole documented range, drawn from `r` in a fixed order (the
    healing and quiet-plate blocks of the tuning set): Table I error and process noise scale
    from the lists given."""
    sensors = {
        "wattmeter_noise_std_w": r.choice([0.05, 0.1, 0.2, 0.3, 0.4, 0.5]),
        "tps_noise_std_v": r.choice([0.003, 0.005, 0.008, 0.01]),
        "tps_gain": round(1.0 + r.uniform(-0.02, 0.02), 6),
        "tps_offset_v": round(r.uniform(-0.02, 0.02), 6),
        "wattmeter_gain": round(1.0 + r.uniform(-0.04, 0.04), 6),
    }
    if r.random() < 0.5:
        sensors["tps_lag_s"] = r.choice([0.001, 0.002])
    if r.random() < 0.5:
        sensors["wattmeter_lag_s"] = r.choice([0.001, 0.003])
    plant = {
        "table1_rel_error": r.choice(table1_errors),
        "table1_max_draws": 500,
        "stop_restitution": r.choice([0.0, 0.1, 0.3]),
        "process_noise_scale": r.choice(process_noise),
    }
    return sensors, plant


def tuning():
    rng = random.Random(1)
    styles = ["pulse_train", "chirp", "pedal_ramps"]
    items = []
    n = 0

    def common(i):
        # Every kind of perturbation the held-out set has, with other values and seeds.
        exc = {"kind": styles[i % len(styles)]}
        sensors = {
            "wattmeter_noise_std_w": rng.choice([0.05, 0.1, 0.2, 0.3, 0.4]),
            "tps_noise_std_v": rng.choice([0.004, 0.006, 0.01]),
            "tps_gain": 1.0 + rng.uniform(-0.015, 0.015),
            "tps_offset_v": rng.uniform(-0.015, 0.015),
            "wattmeter_gain": 1.0 + rng.uniform(-0.04, 0.04),
        }
        if rng.random() < 0.5:
            sensors["tps_lag_s"] = 0.0015
        if rng.random() < 0.5:
            sensors["wattmeter_lag_s"] = 0.002
        plant = {
            "table1_rel_error": rng.choice([0.0, 0.005, 0.01]),
            "table1_max_draws": 200,
            "stop_restitution": rng.choice([0.0, 0.2]),
            "process_noise_scale": rng.choice([0.7, 1.0, 1.5]),
        }
        return exc, sensors, plant

    # Nominal drives: 6 x 10 min.
    for i in range(6):
        exc, sensors, plant = common(i)
        name = "throttle_tuning_%02d_nominal" % n
        items.append((name, scenario(name, 1000 + n, 600, exc, sensors, plant, {"kind": "none"},
                                     comment="tuning: fault-free drive")))
        n += 1
    # Every fault type, 3 logs each, fixture sizes, onset after 60-120 s of fault-free driving.
    for kind in KINDS:
        for j in range(3):
            exc, sensors, plant = common(n)
            start = float(rng.randint(60, 120))
            f = fault_table(rng, kind, start, 1.0)
            name = "throttle_tuning_%02d_%s" % (n, kind)
            items.append((name, scenario(name, 1000 + n, start + 60, exc, sensors, plant, f,
                                         comment="tuning: %s from %g s" % (kind, start))))
            n += 1
    # Healing faults and two at once.
    for kind in ["tps_bias", "tps_open", "wattmeter", "plate_stuck"]:
        exc, sensors, plant = common(n)
        f = fault_table(rng, kind, 60.0, 1.0, end_s=90.0)
        name = "throttle_tuning_%02d_%s_heals" % (n, kind)
        items.append((name, scenario(name, 1000 + n, 150, exc, sensors, plant, f,
                                     comment="tuning: %s from 60 s to 90 s" % kind)))
        n += 1
    for first, second in [("wattmeter", "tps_bias"), ("wattmeter", "tps_open")]:
        exc, sensors, plant = common(n)
        f = fault_table(rng, first, 60.0, 1.0)
        g = fault_table(rng, second, 100.0, 1.0)
        name = "throttle_tuning_%02d_%s_then_%s" % (n, first, second)
        items.append((name, scenario(name, 1000 + n, 160, exc, sensors, plant, f, g,
                                     comment="tuning: %s from 60 s, then %s from 100 s" % (first, second))))
        n += 1
    # Long fault-free drives over the whole documented range of plants and sensors (added
    # after the held-out set version 2 showed rare false alarms that 1.8 h of tuning driving
    # did not have; their own generator, so the files above stay as they were).
    wide = random.Random(11)
    for i in range(8):
        exc = {"kind": styles[i % len(styles)]}
        sensors = {
            "wattmeter_noise_std_w": wide.choice([0.05, 0.1, 0.2, 0.3, 0.4, 0.5]),
            "tps_noise_std_v": wide.choice([0.003, 0.005, 0.008, 0.01]),
            "tps_gain": 1.0 + wide.uniform(-0.02, 0.02),
            "tps_offset_v": wide.uniform(-0.02, 0.02),
            "wattmeter_gain": 1.0 + wide.uniform(-0.04, 0.04),
        }
        if wide.random() < 0.5:
            sensors["tps_lag_s"] = wide.choice([0.001, 0.002])
        if wide.random() < 0.5:
            sensors["wattmeter_lag_s"] = wide.choice([0.001, 0.003])
        plant = {
            "table1_rel_error": wide.choice([0.005, 0.01, 0.015]),
            "table1_max_draws": 500,
            "stop_restitution": wide.choice([0.0, 0.1, 0.3]),
            "process_noise_scale": wide.choice([0.5, 1.0, 2.0]),
        }
        name = "throttle_tuning_%02d_nominal_long" % n
        items.append((name, scenario(name, 1000 + n, 1800, exc, sensors, plant, {"kind": "none"},
                                     comment="tuning: fault-free drive, 30 min, wide plant range")))
        n += 1
    # The corners of the documented range together (wattmeter noise 0.4-0.5 W and gain 4-5 %
    # off, Table I 1.5 % off): added after held-out version 8 had a false wattmeter DTC on
    # such a plant (0.45 W, +4.7 %) that the draws above never combined.
    corner = random.Random(13)
    for i in range(4):
        exc = {"kind": styles[i % len(styles)]}
        sensors = {
            "wattmeter_noise_std_w": round(corner.uniform(0.4, 0.5), 3),
            "tps_noise_std_v": corner.choice([0.003, 0.005, 0.008, 0.01]),
            "tps_gain": round(1.0 + corner.uniform(-0.02, 0.02), 6),
            "tps_offset_v": round(corner.uniform(-0.02, 0.02), 6),
            "wattmeter_gain": round(1.0 + corner.choice([-1, 1]) * corner.uniform(0.04, 0.05), 6),
        }
        if corner.random() < 0.5:
            sensors["tps_lag_s"] = corner.choice([0.001, 0.002])
        if corner.random() < 0.5:
            sensors["wattmeter_lag_s"] = corner.choice([0.001, 0.003])
        plant = {
            "table1_rel_error": 0.015,
            "table1_max_draws": 500,
            "stop_restitution": corner.choice([0.0, 0.1, 0.3]),
            "process_noise_scale": corner.choice([0.5, 1.0, 2.0]),
        }
        name = "throttle_tuning_%02d_nominal_corner" % n
        items.append((name, scenario(name, 1000 + n, 1800, exc, sensors, plant, {"kind": "none"},
                                     comment="tuning: fault-free drive, 30 min, range corners")))
        n += 1
    # Every fault type starting and ending, sizes 0.75-1.5x (added after held-out version 9,
    # whose healed drift kept its flag past the grace and whose plate stuck for 40 s went
    # unnamed: the block above healed only four types at fixture sizes; its own generator).
    heal = random.Random(15)
    for i, kind in enumerate(KINDS):
        exc = {"kind": styles[i % len(styles)]}
        sensors, plant = wide_draw(heal, [0.0, 0.005, 0.01, 0.015], [0.5, 1.0, 2.0])
        scale = heal.uniform(0.75, 1.5)
        f = fault_table(heal, kind, 120.0, scale, end_s=160.0)
        name = "throttle_tuning_%02d_%s_heals" % (n, kind)
        items.append((name, scenario(name, 1000 + n, 240, exc, sensors, plant, f,
                                     comment="tuning: %s from 120 s to 160 s, size x%.2f" % (kind, scale))))
        n += 1
    # Quiet plates (process noise x0.05 to x0.3): the truth's process noise stands for the
    # paper's model-vs-data error and makes the plate wander 10-20 deg about a hold at x1-x2,
    # which no real plate does. On quiet plates the static map's own error shows (a plant
    # 1.5 % off Table I rests up to 14 deg from the model's map): added after a stuck plate and
    # a TPS short were named on such healthy plates (their own generator).
    quiet = random.Random(17)
    for i in range(6 + len(KINDS)):
        exc = {"kind": styles[i % len(styles)]}
        sensors, plant = wide_draw(quiet, [0.005, 0.01, 0.015], [0.05, 0.1, 0.2, 0.3])
        if i < 6:
            name = "throttle_tuning_%02d_nominal_quiet" % n
            items.append((name, scenario(name, 1000 + n, 1200, exc, sensors, plant,
                                         {"kind": "none"},
                                         comment="tuning: fault-free drive, 20 min, quiet plate")))
        else:
            kind = KINDS[i - 6]
            scale = quiet.uniform(0.75, 1.5)
            f = fault_table(quiet, kind, 120.0, scale)
            name = "throttle_tuning_%02d_%s_quiet" % (n, kind)
            items.append((name, scenario(name, 1000 + n, 180, exc, sensors, plant, f,
                                         comment="tuning: %s from 120 s, size x%.2f, quiet plate"
                                         % (kind, scale))))
        n += 1
    return items


def heldout():
    # Version 15 (seeds 33000+, random.Random(34)). Version 1 (seeds 5000+) was evaluated once,
    # with a tuning set that lacked sensor tolerances, lags and stop restitution; version 2
    # (seeds 7000+, random.Random(6)) once after the step test and the allowances; version 3
    # (seeds 9000+, random.Random(8)) once before the frozen-TPS test and the wattmeter-only
    # filter; version 4 (seeds 11000+, random.Random(12)) once before the rail check asked the
    # wattmeter-only filter after a healed TPS fault and before the wattmeter's gain allowance
    # was widened; version 5 (seeds 13000+, random.Random(14)) once before the drift rule's
    # disagreement persistence, the circuit heal's agreement and the plate test's rail-band fix;
    # version 6 (seeds 15000+, random.Random(16)) once before the combined filter started from
    # the wattmeter-only filter's state at a TPS fault and before a drift stopped healing on
    # rail readings; version 7 (seeds 17000+, random.Random(18)) once before the stuck-plate
    # test's counter debounced and its "away from the static map" clause left the end stops;
    # version 8 (seeds 19000+, random.Random(20)) once before the tuning set's range corners,
    # watt_confirm_alarms 5 and the drift rule's own count and sigma floor; version 9 (seeds
    # 21000+, random.Random(22)) once before the tuning set's healing block and the heal
    # rules it led to; version 10 (seeds 23000+, random.Random(24)) once before a frozen TPS
    # got its own, smaller drive (frozen_driven_range_deg); version 11 (seeds 25000+,
    # random.Random(26)) once before a TPS frozen for frozen_alone_samples was stuck without
    # a drive; version 12 (seeds 27000+, random.Random(28)) once before the quiet plates (the
    # plate test's map "since the TPS last moved", the rail check's map allowance), whose
    # process noise it did not draw; version 13 (seeds 29000+, random.Random(30)) once before
    # the wattmeter test's mode-boundary allowance and the wattmeter-fed filters' boundary-trap
    # and steady-hold re-seeds; version 14 (seeds 31000+, random.Random(32)) once before those
    # re-seeds kept to a static map between static_map_from_deg and the open stop's margin.
    # All fourteen are retired (README).
    rng = random.Random(34)
    base = 33000
    styles = ["steady_holds", "idle_blips", "mixed"]
    items = []
    n = 0

    def common(i):
        exc = {"kind": styles[i % len(styles)]}
        sensors = {
            "wattmeter_noise_std_w": rng.choice([0.05, 0.15, 0.25, 0.35, 0.45, 0.5]),
            "tps_noise_std_v": rng.choice([0.003, 0.005, 0.008]),
            "tps_gain": 1.0 + rng.uniform(-0.02, 0.02),
            "tps_offset_v": rng.uniform(-0.02, 0.02),
            "wattmeter_gain": 1.0 + rng.uniform(-0.05, 0.05),
        }
        if rng.random() < 0.5:
            sensors["tps_lag_s"] = rng.choice([0.001, 0.002])
        if rng.random() < 0.5:
            sensors["wattmeter_lag_s"] = rng.choice([0.001, 0.003])
        plant = {
            "table1_rel_error": rng.choice([0.0, 0.005, 0.01, 0.015]),
            "table1_max_draws": 500,
            "stop_restitution": rng.choice([0.0, 0.1, 0.3]),
            "process_noise_scale": rng.choice([0.08, 0.15, 0.25, 0.5, 1.0, 2.0]),
        }
        return exc, sensors, plant

    # Fault-free: 12 drives of 30 min (6 h).
    for i in range(12):
        exc, sensors, plant = common(i)
        name = "throttle_heldout_%02d_nominal" % n
        items.append((name, scenario(name, base + n, 1800, exc, sensors, plant, {"kind": "none"},
                                     comment="held-out: fault-free drive")))
        n += 1
    # Every fault type, 4 logs each (36), sizes 0.75-1.5x, onset after 7-9 min (>= 4.2 h).
    for kind in KINDS:
        for j in range(4):
            exc, sensors, plant = common(n)
            start = float(rng.randint(420, 540))
            scale = rng.uniform(0.75, 1.5)
            f = fault_table(rng, kind, start, scale)
            name = "throttle_heldout_%02d_%s" % (n, kind)
            items.append((name, scenario(name, base + n, start + 60, exc, sensors, plant, f,
                                         comment="held-out: %s from %g s, size x%.2f" % (kind, start, scale))))
            n += 1
    # Healing and two at once.
    for kind in ["tps_drift", "tps_short", "wattmeter", "plate_stuck"]:
        exc, sensors, plant = common(n)
        scale = rng.uniform(0.75, 1.5)
        f = fault_table(rng, kind, 300.0, scale, end_s=340.0)
        name = "throttle_heldout_%02d_%s_heals" % (n, kind)
        items.append((name, scenario(name, base + n, 400, exc, sensors, plant, f,
                                     comment="held-out: %s from 300 s to 340 s" % kind)))
        n += 1
    for first, second in [("wattmeter", "tps_stuck"), ("wattmeter", "tps_drift")]:
        exc, sensors, plant = common(n)
        f = fault_table(rng, first, 300.0, rng.uniform(0.75, 1.5))
        g = fault_table(rng, second, 340.0, rng.uniform(0.75, 1.5))
        name = "throttle_heldout_%02d_%s_then_%s" % (n, first, second)
        items.append((name, scenario(name, base + n, 400, exc, sensors, plant, f, g,
                                     comment="held-out: %s from 300 s, then %s from 340 s" % (first, second))))
        n += 1
    return items


# The calibration plant (Table I 20 % off, wattmeter 0.6 W, a restitution at the stops, sensor
# tolerances): every log of the calibration sets and of the calibration development set.
CAL_SENSORS = {
    "wattmeter_noise_std_w": 0.6,
    "tps_noise_std_v": 0.008,
    "tps_gain": 1.01,
    "tps_offset_v": 0.01,
    "wattmeter_gain": 1.02,
    "tps_lag_s": 0.0015,
    "wattmeter_lag_s": 0.002,
}
CAL_PLANT = {
    "table1_rel_error": 0.2,
    "table1_max_draws": 1000,
    "stop_restitution": 0.2,
    "process_noise_scale": 1.0,
    "seed": 424242,
}


def calibration():
    """One plant beyond the default configuration's range (Table I 20 % off, against the 1.5 %
    of the tuning set; wattmeter noise 0.6 W; a restitution at the stops, sensor tolerances): a
    30-minute fault-free log to calibrate on (`throttle_calibrate_train/`) and logs of the same
    plant (`plant.seed`) with other seeds, excitation styles and fault sizes 0.75-1.5x to judge
    the calibrated and the default configuration on (`throttle_calibrate_heldout/`)."""
    rng = random.Random(29)
    sensors, plant = CAL_SENSORS, CAL_PLANT
    train = []
    name = "throttle_calibrate_train_00_nominal"
    train.append((name, scenario(name, 3000, 1800, {"kind": "mixed"}, sensors, plant,
                                 {"kind": "none"},
                                 comment="calibration: 30 min fault-free of the plant")))
    held = []
    styles = ["pulse_train", "chirp", "pedal_ramps", "steady_holds", "idle_blips"]
    n = 0
    # Version 7 (seeds 3700+, random.Random(29); the plant of the example: Table I
    # 20 % off, wattmeter 0.6 W): 20 fault-free drives of 30 min (10 h) and 9 fault kinds x 3.
    # Version 6 (seeds 3600+, random.Random(27), the same plant), version 5 (seeds 3500+,
    # random.Random(25)), version 4 (seeds 3400+, random.Random(24), the same plant), version 3 (seeds 3300+, random.Random(23), the same plant), version 2 (seeds 3200+,
    # random.Random(22), Table I 2 %, wattmeter 0.9 W) and version 1 (seeds 3100+, 2 drives and
    # 9 x 2, random.Random(21)) were evaluated once and are retired.
    for i in range(20):
        name = "throttle_calibrate_heldout_%02d_nominal" % n
        held.append((name, scenario(name, 3700 + n, 1800, {"kind": styles[n % len(styles)]},
                                    sensors, plant, {"kind": "none"},
                                    comment="calibration held-out: 30 min fault-free")))
        n += 1
    for kind in KINDS:
        for j in range(3):
            start = float(rng.randint(120, 240))
            scale = rng.uniform(0.75, 1.5)
            f = fault_table(rng, kind, start, scale)
            name = "throttle_calibrate_heldout_%02d_%s" % (n, kind)
            held.append((name, scenario(name, 3700 + n, start + 60,
                                        {"kind": styles[n % len(styles)]}, sensors, plant, f,
                                        comment="calibration held-out: %s from %g s, size x%.2f"
                                        % (kind, start, scale))))
            n += 1
    return train, held


def calibration_dev():
    """A development set of the calibration plant, not committed (`--dev DIR`): 8 wattmeter
    faults and 6 TPS drifts (seeds 9100+, `random.Random(97)`, the six excitation styles) and 6
    fault-free drives of 30 min (seeds 9200+), to try a calibration or monitor change on before
    a held-out version is spent (session 2026-12-06: the wattmeter dead band and naming)."""
    rng = random.Random(97)
    sensors, plant = CAL_SENSORS, CAL_PLANT
    styles = ["pulse_train", "chirp", "pedal_ramps", "steady_holds", "idle_blips", "mixed"]
    items = []
    for n, kind in enumerate(["wattmeter"] * 8 + ["tps_drift"] * 6):
        start = float(rng.randint(120, 240))
        scale = rng.uniform(0.75, 1.5)
        f = fault_table(rng, kind, start, scale)
        name = "throttle_cdev_%02d_%s" % (n, kind)
        items.append((name, scenario(name, 9100 + n, start + 60,
                                     {"kind": styles[n % len(styles)]}, sensors, plant, f,
                                     comment="dev")))
    for i in range(6):
        name = "throttle_cdevnom_%02d_nominal" % i
        items.append((name, scenario(name, 9200 + i, 1800, {"kind": styles[i % len(styles)]},
                                     sensors, plant, {"kind": "none"}, comment="dev nominal")))
    return items


if __name__ == "__main__":
    if sys.argv[1:2] == ["--dev"] and len(sys.argv) == 3:
        os.makedirs(sys.argv[2], exist_ok=True)
        dev = calibration_dev()
        for name, text in dev:
            with open(os.path.join(sys.argv[2], name + ".toml"), "w") as f:
                f.write(text)
        print("wrote %d development scenarios into %s" % (len(dev), sys.argv[2]))
        sys.exit(0)
    t = tuning()
    h = heldout()
    ct, ch = calibration()
    if sys.argv[1:] == ["--check"]:
        # Compare only: exit 1 if a committed file differs from what would be written.
        bad = sum(check_set(d, items) for d, items in [
            ("throttle_tuning", t), ("throttle_heldout", h),
            ("throttle_calibrate_train", ct), ("throttle_calibrate_heldout", ch)])
        print("%d throttle scenario files differ" % bad)
        sys.exit(1 if bad else 0)
    write_set("throttle_tuning", t)
    write_set("throttle_heldout", h)
    write_set("throttle_calibrate_train", ct)
    write_set("throttle_calibrate_heldout", ch)
    print("wrote %d tuning, %d held-out and %d + %d calibration throttle scenarios"
          % (len(t), len(h), len(ct), len(ch)))
