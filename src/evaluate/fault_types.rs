//! What each fault of the ground truth counts as: the link between the simulator's fault names
//! (the `fault` field of `/truth/throttle` and `/truth/intake`, the scenario's fault kinds) and
//! a monitor's diagnosis classes and DTCs.
//!
//! Isolation is judged at the level a repair needs: a DTC is correct when it names the right
//! component's DTC family (any TPS DTC for any TPS fault: a bias reported as a range /
//! performance fault and a stuck sensor reported the same way send the mechanic to the same
//! part), and a fault's score is the sum of the monitor's scores of that component's classes.

/// One fault type of the ground truth as the evaluation counts it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaultType {
    /// Its name in the truth's `fault` field (a scenario fault kind, e.g. `tps_bias`).
    pub truth: &'static str,
    /// The monitor's diagnosis classes whose scores, summed (at most 1), are its score.
    pub scored_as: &'static [&'static str],
    /// The monitor's events (configured event names) whose DTCs are correct for it.
    pub dtcs: &'static [&'static str],
}

const TPS_CLASSES: &[&str] = &[
    "tps_open_circuit",
    "tps_short_circuit",
    "tps_intermittent",
    "tps_stuck",
    "tps_range_performance",
];
/// The TPS DTC family, with the switch of the position output to the wattmeter estimate (P2106
/// "forced limited power"), which is raised with every decided TPS fault and with nothing else.
const TPS_DTCS: &[&str] = &[
    "position_from_wattmeter",
    "tps_circuit_low",
    "tps_circuit_high",
    "tps_range_performance",
    "tps_intermittent",
];

const fn tps(truth: &'static str) -> FaultType {
    FaultType {
        truth,
        scored_as: TPS_CLASSES,
        dtcs: TPS_DTCS,
    }
}

/// The throttle faults of `fdd_fixtures::scenario::FaultKind`.
pub const THROTTLE: &[FaultType] = &[
    tps("tps_stuck"),
    tps("tps_bias"),
    tps("tps_drift"),
    tps("tps_open"),
    tps("tps_short"),
    tps("tps_intermittent"),
    tps("tps_noise"),
    FaultType {
        truth: "plate_stuck",
        scored_as: &["plate_stuck"],
        dtcs: &["throttle_plate_stuck"],
    },
    FaultType {
        truth: "wattmeter",
        scored_as: &["wattmeter"],
        dtcs: &["wattmeter_plausibility"],
    },
];

const MAP_DTCS: &[&str] = &[
    "map_range_performance",
    "map_circuit_low",
    "map_circuit_high",
];
const MAF_DTCS: &[&str] = &[
    "maf_range_performance",
    "maf_circuit_low",
    "maf_circuit_high",
];

const fn map(truth: &'static str) -> FaultType {
    FaultType {
        truth,
        scored_as: &["map_sensor"],
        dtcs: MAP_DTCS,
    }
}

const fn maf(truth: &'static str) -> FaultType {
    FaultType {
        truth,
        scored_as: &["maf_sensor"],
        dtcs: MAF_DTCS,
    }
}

/// The EGR valve's DTC family: a valve stuck at one position gives too much flow where the
/// command is below it and too little where it is above, so either DTC sends the mechanic to
/// the valve.
const EGR_DTCS: &[&str] = &[
    "egr_flow_insufficient",
    "egr_flow_excessive",
    "egr_slow_response",
];

const fn egr(truth: &'static str) -> FaultType {
    FaultType {
        truth,
        scored_as: &["egr_valve"],
        dtcs: EGR_DTCS,
    }
}

/// The intake faults of `fdd_fixtures::intake_sim`.
pub const INTAKE: &[FaultType] = &[
    map("map_bias"),
    map("map_gain"),
    map("map_stuck"),
    map("map_drift"),
    map("map_noise"),
    map("map_open"),
    map("map_short"),
    maf("maf_bias"),
    maf("maf_gain"),
    maf("maf_stuck"),
    maf("maf_drift"),
    maf("maf_noise"),
    maf("maf_open"),
    maf("maf_short"),
    egr("egr_stuck_open"),
    egr("egr_stuck_closed"),
    egr("egr_sluggish"),
    FaultType {
        truth: "leak",
        scored_as: &["manifold_leak"],
        dtcs: &["intake_leak"],
    },
];

/// The turbo air-path monitor's diagnosis classes and events (DTCs) that each fault of
/// `fdd_fixtures::turbo_faults` counts as: P0106 (`turbo_p_im_range_performance`), P0236
/// (`turbo_p_ic_range_performance`), P0101 (`turbo_maf_range_performance`), P0096
/// (`turbo_t_ic_range_performance`), P2279 (`turbo_intake_leak`, both leaks), the P0243 family
/// with P0299 / P0234 (`turbo_wastegate`, `turbo_underboost`, `turbo_overboost`: a stuck
/// wastegate shows as under- or overboost) and the throttle actuator (`turbo_throttle_actuator`).
/// The simulator's truth names carry the size (`pim_gain_1.10`, `leak_ic_5mm`, as the imported
/// LiU-ICE faults' `pim_gain_1.15`); every name it can write is listed, on its size grid.
const TURBO_P_IM_DTCS: &[&str] = &["turbo_p_im_range_performance"];
const TURBO_P_IC_DTCS: &[&str] = &["turbo_p_ic_range_performance"];
const TURBO_MAF_DTCS: &[&str] = &["turbo_maf_range_performance"];
const TURBO_T_IC_DTCS: &[&str] = &["turbo_t_ic_range_performance"];
const TURBO_LEAK_DTCS: &[&str] = &["turbo_intake_leak"];
const TURBO_WASTEGATE_DTCS: &[&str] = &["turbo_wastegate", "turbo_underboost", "turbo_overboost"];
const TURBO_THROTTLE_DTCS: &[&str] = &["turbo_throttle_actuator"];

const fn turbo(
    truth: &'static str,
    class: &'static [&'static str],
    dtcs: &'static [&'static str],
) -> FaultType {
    FaultType {
        truth,
        scored_as: class,
        dtcs,
    }
}

/// The table of sized names: `prefix, class, dtcs; [sizes]` per family, then the unsized ones.
macro_rules! turbo_table {
    ($( $prefix:literal, $class:literal, $dtcs:expr; [$($size:literal),*] );* ; fixed: $( $name:literal, $fclass:literal, $fdtcs:expr );* $(;)?) => {
        &[
            $( $( turbo(concat!($prefix, $size), &[$class], $dtcs), )* )*
            $( turbo($name, &[$fclass], $fdtcs), )*
        ]
    };
}

/// The turbo faults of `fdd_fixtures::turbo_faults` (every truth name on the size grid, and the
/// imported LiU-ICE faults' names, which are on it: `pim_gain_1.15`, `pic_gain_0.85`,
/// `waf_gain_1.05`, ...).
pub const TURBO: &[FaultType] = turbo_table!(
    "pim_gain_", "turbo_p_im_sensor", TURBO_P_IM_DTCS; ["0.80", "0.81", "0.82", "0.83", "0.84", "0.85", "0.86", "0.87", "0.88", "0.89", "0.90", "0.91", "0.92", "0.93", "0.94", "0.95", "1.05", "1.06", "1.07", "1.08", "1.09", "1.10", "1.11", "1.12", "1.13", "1.14", "1.15", "1.16", "1.17", "1.18", "1.19", "1.20"];
    "pic_gain_", "turbo_p_ic_sensor", TURBO_P_IC_DTCS; ["0.80", "0.81", "0.82", "0.83", "0.84", "0.85", "0.86", "0.87", "0.88", "0.89", "0.90", "0.91", "0.92", "0.93", "0.94", "0.95", "1.05", "1.06", "1.07", "1.08", "1.09", "1.10", "1.11", "1.12", "1.13", "1.14", "1.15", "1.16", "1.17", "1.18", "1.19", "1.20"];
    "waf_gain_", "turbo_maf_sensor", TURBO_MAF_DTCS; ["0.80", "0.81", "0.82", "0.83", "0.84", "0.85", "0.86", "0.87", "0.88", "0.89", "0.90", "0.91", "0.92", "0.93", "0.94", "0.95", "1.05", "1.06", "1.07", "1.08", "1.09", "1.10", "1.11", "1.12", "1.13", "1.14", "1.15", "1.16", "1.17", "1.18", "1.19", "1.20"];
    "tic_bias_", "turbo_t_ic_sensor", TURBO_T_IC_DTCS; ["-20K", "-19K", "-18K", "-17K", "-16K", "-15K", "-14K", "-13K", "-12K", "-11K", "-10K", "-9K", "-8K", "-7K", "-6K", "-5K", "-4K", "-3K", "-2K", "2K", "3K", "4K", "5K", "6K", "7K", "8K", "9K", "10K", "11K", "12K", "13K", "14K", "15K", "16K", "17K", "18K", "19K", "20K"];
    "leak_ic_", "turbo_leak_before_throttle", TURBO_LEAK_DTCS; ["1mm", "2mm", "3mm", "4mm", "5mm", "6mm", "7mm", "8mm", "9mm", "10mm", "11mm", "12mm"];
    "leak_im_", "turbo_leak_after_throttle", TURBO_LEAK_DTCS; ["1mm", "2mm", "3mm", "4mm", "5mm", "6mm", "7mm", "8mm", "9mm", "10mm", "11mm", "12mm"];
    fixed:
    "wg_stuck", "turbo_wastegate", TURBO_WASTEGATE_DTCS;
    "wg_stuck_closed", "turbo_wastegate", TURBO_WASTEGATE_DTCS;
    "wg_stuck_open", "turbo_wastegate", TURBO_WASTEGATE_DTCS;
    "throttle_stuck", "turbo_throttle_actuator", TURBO_THROTTLE_DTCS;
    "throttle_sluggish", "turbo_throttle_actuator", TURBO_THROTTLE_DTCS;
);

/// The intake monitor's group events: detected, not isolated (their isolation candidates name
/// the fault classes still possible).
pub const INTAKE_GROUP_EVENTS: &[&str] = &["intake_air_path_group"];

/// The air-path monitor's group event: detected, not isolated (its candidates name the fault
/// classes still possible).
pub const TURBO_GROUP_EVENTS: &[&str] = &["turbo_air_path_group"];

/// The group events of the monitor `name` (a DTC of one of them is a group DTC, judged by its
/// candidates; every other DTC is specific).
pub fn group_events(monitor: &str) -> &'static [&'static str] {
    match monitor {
        "intake" => INTAKE_GROUP_EVENTS,
        "turbo" => TURBO_GROUP_EVENTS,
        _ => &[],
    }
}

/// The fault types evaluated for the monitor `name` (empty for a monitor without ground truth).
pub fn fault_types(monitor: &str) -> &'static [FaultType] {
    match monitor {
        "throttle" => THROTTLE,
        "intake" => INTAKE,
        "turbo" => TURBO,
        _ => &[],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The turbo table lists exactly the names the turbo simulator can write (and so the
    /// imported LiU-ICE faults' names, which are on its grid).
    #[test]
    fn the_turbo_table_lists_every_simulated_fault_name() {
        let names: Vec<String> = fdd_fixtures::turbo_faults::all_fault_names()
            .into_iter()
            .filter(|n| n != "none")
            .collect();
        let table: Vec<&str> = TURBO.iter().map(|t| t.truth).collect();
        assert_eq!(names.len(), table.len());
        for n in &names {
            assert!(table.contains(&n.as_str()), "{n} missing from TURBO");
        }
        for real in [
            "pim_gain_1.15",
            "pic_gain_0.85",
            "waf_gain_0.90",
            "pim_gain_1.05",
        ] {
            assert!(table.contains(&real), "{real}");
        }
    }

    /// Every class and DTC the table names is one the monitors have, so that a renamed event
    /// cannot silently make every DTC "wrong".
    #[test]
    fn the_table_names_only_classes_and_events_the_monitors_have() {
        use fdd_monitor::intake::{EVENT_NAMES as INTAKE_EVENTS, FAULT_CLASSES as INTAKE_CLASSES};
        use fdd_monitor::throttle::{
            EVENT_NAMES as THROTTLE_EVENTS, FAULT_CLASSES as THROTTLE_CLASSES,
        };
        for (monitor, types, classes, events) in [
            (
                "throttle",
                THROTTLE,
                &THROTTLE_CLASSES[..],
                &THROTTLE_EVENTS[..],
            ),
            ("intake", INTAKE, &INTAKE_CLASSES[..], &INTAKE_EVENTS[..]),
        ] {
            for g in group_events(monitor) {
                assert!(events.contains(g), "group event {g}");
            }
            for t in types {
                for c in t.scored_as {
                    assert!(classes.contains(c), "{}: class {c}", t.truth);
                }
                for d in t.dtcs {
                    assert!(events.contains(d), "{}: event {d}", t.truth);
                }
            }
        }
    }
}
