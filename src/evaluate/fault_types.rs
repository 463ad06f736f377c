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

/// The intake monitor's group events: detected, not isolated (their isolation candidates name
/// the fault classes still possible).
pub const INTAKE_GROUP_EVENTS: &[&str] = &["intake_air_path_group"];

/// The group events of the monitor `name` (a DTC of one of them is a group DTC, judged by its
/// candidates; every other DTC is specific).
pub fn group_events(monitor: &str) -> &'static [&'static str] {
    match monitor {
        "intake" => INTAKE_GROUP_EVENTS,
        _ => &[],
    }
}

/// The fault types evaluated for the monitor `name` (empty for a monitor without ground truth).
pub fn fault_types(monitor: &str) -> &'static [FaultType] {
    match monitor {
        "throttle" => THROTTLE,
        "intake" => INTAKE,
        _ => &[],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
