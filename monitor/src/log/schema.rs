//! The JSON schemas (draft 2020-12, MCAP schema encoding `jsonschema`) of fdd's topics.
//!
//! They are written by hand, with each field's unit in its `description`, and kept in step with
//! the serde types in [`super::messages`] by the unit tests below (the properties and required
//! keys must be exactly the keys serde writes). A non-finite number is written as `null`, so
//! every `f64` field is `"type": ["number", "null"]`.

/// One topic fdd knows: its channel topic, schema name, JSON schema and a one-line description.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicSchema {
    /// The channel topic, e.g. `/throttle/tps`.
    pub topic: &'static str,
    /// The schema record's name, e.g. `fdd.TpsVoltage`.
    pub schema_name: &'static str,
    /// The JSON schema text (the schema record's data).
    pub schema: &'static str,
    /// What the topic carries.
    pub description: &'static str,
}

/// MCAP schema encoding of every fdd schema.
pub const SCHEMA_ENCODING: &str = "jsonschema";
/// MCAP message encoding of every fdd channel.
pub const MESSAGE_ENCODING: &str = "json";

/// `/throttle/motor_voltage`.
pub const MOTOR_VOLTAGE: TopicSchema = TopicSchema {
    topic: "/throttle/motor_voltage",
    schema_name: "fdd.MotorVoltage",
    description: "voltage applied to the throttle motor (model input u)",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.MotorVoltage",
  "description": "Voltage applied to the throttle motor (the throttle model's input u). Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "voltage_v": {"type": ["number", "null"], "description": "motor voltage, V; null when not finite"}
  },
  "required": ["voltage_v"],
  "additionalProperties": false
}
"#,
};

/// `/throttle/tps`.
pub const TPS_VOLTAGE: TopicSchema = TopicSchema {
    topic: "/throttle/tps",
    schema_name: "fdd.TpsVoltage",
    description: "throttle position sensor output voltage",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.TpsVoltage",
  "description": "Throttle position sensor output. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "voltage_v": {"type": ["number", "null"], "description": "sensor output voltage, V (0..5 V for 0..90 deg by default); null when not finite"}
  },
  "required": ["voltage_v"],
  "additionalProperties": false
}
"#,
};

/// `/throttle/wattmeter`.
pub const WATTMETER: TopicSchema = TopicSchema {
    topic: "/throttle/wattmeter",
    schema_name: "fdd.Wattmeter",
    description: "wattmeter on the throttle motor supply: power i^2 into 1 ohm",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.Wattmeter",
  "description": "Wattmeter on the throttle motor supply. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "power_w": {"type": ["number", "null"], "description": "motor power i^2 into 1 ohm, W (numerically the squared motor current, A^2), with measurement noise; null when not finite"}
  },
  "required": ["power_w"],
  "additionalProperties": false
}
"#,
};

/// `/truth/throttle`.
pub const THROTTLE_TRUTH: TopicSchema = TopicSchema {
    topic: "/truth/throttle",
    schema_name: "fdd.ThrottleTruth",
    description: "simulated truth (fixtures only): angle, velocity, current, active fault",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.ThrottleTruth",
  "description": "Simulated throttle truth, written by fixtures only. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "angle_deg": {"type": ["number", "null"], "description": "true plate angle, deg (0 closed .. 90 wide open)"},
    "velocity": {"type": ["number", "null"], "description": "true plate angular velocity rho, in the identified throttle model's own units"},
    "current_a": {"type": ["number", "null"], "description": "true motor current, A"},
    "fault": {"type": "string", "description": "scenario fault name, e.g. none, tps_stuck"},
    "fault_active": {"type": "boolean", "description": "whether the fault is active at this sample"},
    "fault_observable": {"type": "boolean", "description": "whether the active fault changes a reading at this sample by more than a healthy part could (TPS: 0.1 V; wattmeter: 0.05 W; stuck plate: 2 deg from where the voltage would hold it); absent: as fault_active"}
  },
  "required": ["angle_deg", "velocity", "current_a", "fault", "fault_active"],
  "additionalProperties": false
}
"#,
};

/// `/intake/engine_speed`.
pub const ENGINE_SPEED: TopicSchema = TopicSchema {
    topic: "/intake/engine_speed",
    schema_name: "fdd.EngineSpeed",
    description: "engine speed from the 180 deg crank segment time",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.EngineSpeed",
  "description": "Engine speed over one 180 deg crank segment (30 / segment time), the intake model's input N. Log time = end of the segment, ns.",
  "type": "object",
  "properties": {
    "speed_rpm": {"type": ["number", "null"], "description": "engine speed, rpm (30 / segment time in s); null when not finite"}
  },
  "required": ["speed_rpm"],
  "additionalProperties": false
}
"#,
};

/// `/intake/throttle`.
pub const THROTTLE_ANGLE: TopicSchema = TopicSchema {
    topic: "/intake/throttle",
    schema_name: "fdd.ThrottleAngle",
    description: "throttle opening over the crank segment (intake model input)",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.ThrottleAngle",
  "description": "Throttle opening over one crank segment, the intake model's input theta. Log time = end of the segment, ns.",
  "type": "object",
  "properties": {
    "angle_deg": {"type": ["number", "null"], "description": "throttle opening from the closed plate, deg; null when not finite"}
  },
  "required": ["angle_deg"],
  "additionalProperties": false
}
"#,
};

/// `/intake/egr_command`.
pub const EGR_COMMAND: TopicSchema = TopicSchema {
    topic: "/intake/egr_command",
    schema_name: "fdd.EgrCommand",
    description: "commanded EGR valve position over the crank segment (intake model input)",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.EgrCommand",
  "description": "Commanded EGR valve position over one crank segment, the intake model's input e. Log time = end of the segment, ns.",
  "type": "object",
  "properties": {
    "position": {"type": ["number", "null"], "description": "commanded EGR valve position, 0 closed .. 1 fully open (dimensionless); null when not finite"}
  },
  "required": ["position"],
  "additionalProperties": false
}
"#,
};

/// `/intake/map`.
pub const MANIFOLD_PRESSURE: TopicSchema = TopicSchema {
    topic: "/intake/map",
    schema_name: "fdd.ManifoldPressure",
    description: "manifold absolute pressure (MAP) sensor reading",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.ManifoldPressure",
  "description": "Manifold absolute pressure sensor reading, sampled at the end of a crank segment. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "pressure_pa": {"type": ["number", "null"], "description": "manifold absolute pressure, Pa; null when not finite"}
  },
  "required": ["pressure_pa"],
  "additionalProperties": false
}
"#,
};

/// `/intake/maf`.
pub const MASS_AIR_FLOW: TopicSchema = TopicSchema {
    topic: "/intake/maf",
    schema_name: "fdd.MassAirFlow",
    description: "mass air flow (MAF) sensor reading: metered air through the throttle",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.MassAirFlow",
  "description": "Mass air flow sensor reading (metered air upstream of the throttle), sampled at the end of a crank segment. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "flow_kg_s": {"type": ["number", "null"], "description": "air mass flow, kg/s; null when not finite"}
  },
  "required": ["flow_kg_s"],
  "additionalProperties": false
}
"#,
};

/// `/truth/intake`.
pub const INTAKE_TRUTH: TopicSchema = TopicSchema {
    topic: "/truth/intake",
    schema_name: "fdd.IntakeTruth",
    description: "simulated intake truth (fixtures only): pressure, flows, EGR position, fault",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.IntakeTruth",
  "description": "Simulated intake-manifold truth at the end of a crank segment, written by fixtures only. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "p_m_pa": {"type": ["number", "null"], "description": "true manifold pressure, Pa"},
    "w_thr_kg_s": {"type": ["number", "null"], "description": "true throttle (metered) air flow, kg/s"},
    "w_egr_kg_s": {"type": ["number", "null"], "description": "true EGR flow at the actual valve position, kg/s"},
    "w_inv_kg_s": {"type": ["number", "null"], "description": "true intake-valve (engine) flow, kg/s"},
    "w_leak_kg_s": {"type": ["number", "null"], "description": "true unmetered leak flow into the manifold, kg/s (0 without a leak)"},
    "egr_actual": {"type": ["number", "null"], "description": "actual EGR valve position, 0..1 (differs from the command under an EGR fault)"},
    "fault": {"type": "string", "description": "the fault present at this sample: the scenario fault name (e.g. map_bias, leak) once active, none before"},
    "fault_active": {"type": "boolean", "description": "whether the fault is active at this sample"},
    "fault_observable": {"type": "boolean", "description": "whether the fault is active and has an effect at this sample (an EGR valve stuck where it is commanded has none)"}
  },
  "required": ["p_m_pa", "w_thr_kg_s", "w_egr_kg_s", "w_inv_kg_s", "w_leak_kg_s", "egr_actual", "fault", "fault_active", "fault_observable"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/throttle/position`.
pub const POSITION_ESTIMATE: TopicSchema = TopicSchema {
    topic: "/fdd/throttle/position",
    schema_name: "fdd.PositionEstimate",
    description: "throttle position output with its 95% interval and source",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.PositionEstimate",
  "description": "fdd's throttle position output. Log time = time of the sample it is computed from, ns.",
  "type": "object",
  "properties": {
    "angle_deg": {"type": ["number", "null"], "description": "estimated plate angle, deg; null when no estimate is available"},
    "lower_deg": {"type": ["number", "null"], "description": "lower end of the 95% interval, deg"},
    "upper_deg": {"type": ["number", "null"], "description": "upper end of the 95% interval, deg"},
    "source": {"type": "string", "description": "tps (position sensor) or wattmeter_estimate (wattmeter UKF, sensor diagnosed faulty)"}
  },
  "required": ["angle_deg", "lower_deg", "upper_deg", "source"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/throttle/innovation`.
pub const INNOVATION: TopicSchema = TopicSchema {
    topic: "/fdd/throttle/innovation",
    schema_name: "fdd.Innovation",
    description: "per-filter innovation, its variance and NIS",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.Innovation",
  "description": "One filter's innovation after an update. Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "filter": {"type": "string", "description": "filter name, as configured"},
    "residual": {"type": "array", "items": {"type": ["number", "null"]}, "description": "innovation y - h(x) per measurement component, in its units (V position sensor, W wattmeter)"},
    "variance": {"type": "array", "items": {"type": ["number", "null"]}, "description": "innovation variance per component (diagonal of S), squared measurement units (V^2, W^2)"},
    "nis": {"type": ["number", "null"], "description": "normalized innovation squared r' S^-1 r, dimensionless"},
    "dof": {"type": "integer", "minimum": 0, "maximum": 4294967295, "description": "degrees of freedom of nis (measurement components used)"}
  },
  "required": ["filter", "residual", "variance", "nis", "dof"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/tests`.
pub const TEST_STATISTIC: TopicSchema = TopicSchema {
    topic: "/fdd/tests",
    schema_name: "fdd.TestStatistic",
    description: "one step of one statistical test: statistic, limits, verdict",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.TestStatistic",
  "description": "One step of one test (OBD $06 convention: passed when min <= value <= max). Log time = sample time, ns.",
  "type": "object",
  "properties": {
    "test": {"type": "string", "description": "test name, as configured"},
    "value": {"type": ["number", "null"], "description": "test statistic, in the test's units (dimensionless for NIS tests, V for a voltage range check); null when the test did not run"},
    "min": {"type": ["number", "null"], "description": "lower limit, same units"},
    "max": {"type": ["number", "null"], "description": "upper limit (threshold), same units"},
    "verdict": {"type": "string", "enum": ["NOT_TESTED", "PASSED", "FAILED", "PRE_PASSED", "PRE_FAILED"], "description": "the step's verdict"}
  },
  "required": ["test", "value", "min", "max", "verdict"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/dtc_status`.
pub const DTC_STATUS: TopicSchema = TopicSchema {
    topic: "/fdd/dtc_status",
    schema_name: "fdd.DtcStatus",
    description: "a DTC's ISO 14229-1 status byte, on change",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.DtcStatus",
  "description": "A DTC's ISO 14229-1 status byte, written when it changes. Log time = time of the change, ns.",
  "type": "object",
  "properties": {
    "dtc": {"type": "string", "pattern": "^[PCBU][0-3][0-9A-F]{3}-[0-9A-F]{2}$", "description": "UDS DTC as J2012 code and failure type byte, e.g. P0123-1C"},
    "status": {"type": "integer", "minimum": 0, "maximum": 255, "description": "status byte: bit 0 testFailed, 1 testFailedThisOperationCycle, 2 pendingDTC, 3 confirmedDTC, 4 testNotCompletedSinceLastClear, 5 testFailedSinceLastClear, 6 testNotCompletedThisOperationCycle, 7 warningIndicatorRequested"}
  },
  "required": ["dtc", "status"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/events`: `fdd_diagnostics::event::DiagnosticEvent`, as documented there.
pub const DIAGNOSTIC_EVENT: TopicSchema = TopicSchema {
    topic: "/fdd/events",
    schema_name: "fdd.DiagnosticEvent",
    description: "diagnostic events: one per DTC status change (fdd_diagnostics::event)",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.DiagnosticEvent",
  "description": "One DTC status change (fdd_diagnostics::event::DiagnosticEvent). Log time = time_s in ns.",
  "type": "object",
  "properties": {
    "time_s": {"type": "number", "description": "time of the report or operation-cycle call that caused the change, s"},
    "event": {"type": "string", "description": "configured event name"},
    "dtc": {"type": "string", "pattern": "^[PCBU][0-3][0-9A-F]{3}-[0-9A-F]{2}$", "description": "UDS DTC as J2012 code and failure type byte, e.g. P0123-1C"},
    "dtc_uds": {"type": "integer", "minimum": 0, "maximum": 16777215, "description": "the same DTC as the 3-byte UDS value"},
    "trigger": {"type": "string", "enum": ["test_result", "operation_cycle_start", "operation_cycle_end", "clear_dtc", "displacement"], "description": "what caused the change"},
    "status_before": {"type": "integer", "minimum": 0, "maximum": 255, "description": "ISO 14229-1 status byte before"},
    "status_after": {"type": "integer", "minimum": 0, "maximum": 255, "description": "ISO 14229-1 status byte after"},
    "changed": {
      "type": "array",
      "items": {"type": "string", "enum": ["testFailed", "testFailedThisOperationCycle", "pendingDTC", "confirmedDTC", "testNotCompletedSinceLastClear", "testFailedSinceLastClear", "testNotCompletedThisOperationCycle", "warningIndicatorRequested"]},
      "description": "names of the status bits that differ, bit 0 first"
    },
    "fdc": {"type": "integer", "minimum": -128, "maximum": 127, "description": "fault detection counter after the change"},
    "occurrence_counter": {"type": "integer", "minimum": 0, "maximum": 255, "description": "qualified failures since the last clear or aging"},
    "aging_counter": {"type": "integer", "minimum": 0, "maximum": 255, "description": "aging cycles counted so far"},
    "memory": {"type": "string", "enum": ["unchanged", "stored", "not_stored", "displaced", "aged", "cleared"], "description": "what happened to the event memory entry"},
    "displaced": {"type": ["string", "null"], "pattern": "^[PCBU][0-3][0-9A-F]{3}-[0-9A-F]{2}$", "description": "with memory = stored: the DTC whose entry this one displaced"},
    "freeze_frame": {
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "signal": {"type": "string", "description": "signal name, as configured"},
          "value": {"type": ["number", "null"], "description": "value at capture, in the signal's units; null when it had no finite value"}
        },
        "required": ["signal", "value"],
        "additionalProperties": false
      },
      "description": "the entry's freeze frame"
    },
    "test_result": {
      "type": ["object", "null"],
      "properties": {
        "value": {"type": ["number", "null"], "description": "test statistic, in the test's units"},
        "min": {"type": ["number", "null"], "description": "lower limit"},
        "max": {"type": ["number", "null"], "description": "upper limit"},
        "verdict": {"type": "string", "enum": ["NOT_TESTED", "PASSED", "FAILED", "PRE_PASSED", "PRE_FAILED"]}
      },
      "required": ["value", "min", "max", "verdict"],
      "additionalProperties": false,
      "description": "the test result that caused the change; null for operation-cycle, clear and displacement changes"
    },
    "candidates": {
      "type": "array",
      "items": {
        "type": "object",
        "properties": {
          "fault": {"type": "string", "description": "fault name"},
          "score": {"type": "number", "description": "isolation score (higher is more likely)"}
        },
        "required": ["fault", "score"],
        "additionalProperties": false
      },
      "description": "isolation candidates passed with the report, in its order"
    }
  },
  "required": ["time_s", "event", "dtc", "dtc_uds", "trigger", "status_before", "status_after", "changed", "fdc", "occurrence_counter", "aging_counter", "memory", "displaced", "freeze_frame", "test_result", "candidates"],
  "additionalProperties": false
}
"#,
};

/// Every built-in topic, inputs first.
pub const TOPICS: [&TopicSchema; 9] = [
    &MOTOR_VOLTAGE,
    &TPS_VOLTAGE,
    &WATTMETER,
    &THROTTLE_TRUTH,
    &POSITION_ESTIMATE,
    &INNOVATION,
    &TEST_STATISTIC,
    &DTC_STATUS,
    &DIAGNOSTIC_EVENT,
];

/// The intake-manifold topics, inputs first and truth last: built in like [`TOPICS`] (the
/// writer needs no registration for them), kept in their own list so that code iterating
/// [`TOPICS`] (the throttle and fdd output topics) sees the same list as before.
pub const INTAKE_TOPICS: [&TopicSchema; 6] = [
    &ENGINE_SPEED,
    &THROTTLE_ANGLE,
    &EGR_COMMAND,
    &MANIFOLD_PRESSURE,
    &MASS_AIR_FLOW,
    &INTAKE_TRUTH,
];

/// `/fdd/intake/estimate`.
pub const INTAKE_ESTIMATE: TopicSchema = TopicSchema {
    topic: "/fdd/intake/estimate",
    schema_name: "fdd.IntakeEstimate",
    description: "intake monitor outputs (manifold pressure, intake-valve flow) with 95% intervals",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.IntakeEstimate",
  "description": "One estimate of the intake monitor's primary filter, per crank segment. Log time = segment end, ns.",
  "type": "object",
  "properties": {
    "name": {"type": "string", "description": "manifold_pressure (Pa) or intake_valve_flow (kg/s)"},
    "value": {"type": ["number", "null"], "description": "the estimate, in the unit of its name"},
    "lower": {"type": ["number", "null"], "description": "lower end of the 95% interval"},
    "upper": {"type": ["number", "null"], "description": "upper end of the 95% interval"},
    "source": {"type": "string", "description": "the filter: centralized_ekf, decentralized_ekf or federated_ekf; maf_local_ekf or map_local_ekf after a sensor, EGR or leak fault; throttle_model (the model's steady state) with both sensors failed"}
  },
  "required": ["name", "value", "lower", "upper", "source"],
  "additionalProperties": false
}
"#,
};

/// `/fdd/intake/innovation`.
pub const INTAKE_INNOVATION: TopicSchema = TopicSchema {
    topic: "/fdd/intake/innovation",
    schema_name: "fdd.IntakeInnovation",
    description: "per-filter innovation of the intake filters, its variance and NIS",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.IntakeInnovation",
  "description": "One intake filter's innovation after a segment's update. Log time = segment end, ns.",
  "type": "object",
  "properties": {
    "filter": {"type": "string", "description": "intake_centralized, intake_local_map, intake_local_maf or intake_federated"},
    "residual": {"type": "array", "items": {"type": ["number", "null"]}, "description": "innovation per measurement component: MAP in Pa, MAF in kg/s"},
    "variance": {"type": "array", "items": {"type": ["number", "null"]}, "description": "innovation variance per component, Pa^2 or kg^2/s^2"},
    "nis": {"type": ["number", "null"], "description": "normalized innovation squared, dimensionless"},
    "dof": {"type": "integer", "minimum": 0, "maximum": 4294967295, "description": "degrees of freedom of nis"}
  },
  "required": ["filter", "residual", "variance", "nis", "dof"],
  "additionalProperties": false
}
"#,
};

/// The intake monitor's output topics (written by `fdd replay --out`).
pub const INTAKE_OUTPUT_TOPICS: [&TopicSchema; 2] = [&INTAKE_ESTIMATE, &INTAKE_INNOVATION];

/// `/fdd/diagnosis`.
pub const DIAGNOSIS: TopicSchema = TopicSchema {
    topic: "/fdd/diagnosis",
    schema_name: "fdd.Diagnosis",
    description: "each monitor step's detection flag and score per fault class",
    schema: r#"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "fdd.Diagnosis",
  "description": "One monitor step's diagnosis: whether it flags its subsystem as faulty and how strongly it names each fault class (the per-sample output TDR, FAR and FIA are computed from). Log time = step time, ns.",
  "type": "object",
  "properties": {
    "monitor": {"type": "string", "description": "the monitor (throttle, intake, turbo)"},
    "flagged": {"type": "boolean", "description": "a test fails, a fault is being isolated, or a decided fault is present"},
    "classes": {"type": "array", "items": {"type": "string"}, "description": "the monitor's fault classes, in the order of scores"},
    "scores": {"type": "array", "items": {"type": "number", "minimum": 0, "maximum": 1}, "description": "score per class, 0..1 (all 0 when not flagged)"}
  },
  "required": ["monitor", "flagged", "classes", "scores"],
  "additionalProperties": false
}
"#,
};

/// Output topics of every monitor (written by `fdd replay --out`).
pub const MONITOR_OUTPUT_TOPICS: [&TopicSchema; 1] = [&DIAGNOSIS];

/// The built-in topic named `topic` ([`TOPICS`], [`INTAKE_TOPICS`], [`INTAKE_OUTPUT_TOPICS`]
/// or [`MONITOR_OUTPUT_TOPICS`]), if any.
pub fn builtin_topic(topic: &str) -> Option<&'static TopicSchema> {
    TOPICS
        .iter()
        .chain(INTAKE_TOPICS.iter())
        .chain(INTAKE_OUTPUT_TOPICS.iter())
        .chain(MONITOR_OUTPUT_TOPICS.iter())
        .copied()
        .find(|t| t.topic == topic)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::log::messages::*;
    use fdd_diagnostics::event::DiagnosticEvent;
    use serde_json::Value;

    fn keys_of(v: &Value) -> Vec<String> {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    }

    /// The schema's properties and required list are exactly the keys serde writes.
    fn check<T: TopicMessage>(example: &T) {
        check_optional(example, &[]);
    }

    /// As [`check`], with `optional` properties that the example writes but that are not
    /// required (absent in older logs).
    fn check_optional<T: TopicMessage>(example: &T, optional: &[&str]) {
        let schema: Value = serde_json::from_str(T::SCHEMA.schema)
            .unwrap_or_else(|e| panic!("{}: schema is not JSON: {e}", T::SCHEMA.schema_name));
        assert_eq!(schema["title"], T::SCHEMA.schema_name);
        assert_eq!(schema["additionalProperties"], false);
        let written = serde_json::to_value(example).unwrap();
        let props = keys_of(&schema["properties"]);
        assert_eq!(props, keys_of(&written), "{}", T::SCHEMA.schema_name);
        let mut required: Vec<String> = schema["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect();
        required.sort();
        let expect: Vec<String> = props
            .iter()
            .filter(|p| !optional.contains(&p.as_str()))
            .cloned()
            .collect();
        assert_eq!(required, expect, "{}", T::SCHEMA.schema_name);
        for (name, p) in schema["properties"].as_object().unwrap() {
            assert!(
                p.get("description").is_some() || p.get("enum").is_some(),
                "{}.{name} has no description",
                T::SCHEMA.schema_name
            );
        }
    }

    #[test]
    fn schemas_match_the_serde_types() {
        check(&MotorVoltage { voltage_v: 1.0 });
        check(&TpsVoltage { voltage_v: 1.0 });
        check(&Wattmeter { power_w: 1.0 });
        check_optional(
            &ThrottleTruth {
                angle_deg: 1.0,
                velocity: 0.0,
                current_a: 0.1,
                fault: "none".into(),
                fault_active: false,
                fault_observable: Some(false),
            },
            &["fault_observable"],
        );
        check(&EngineSpeed { speed_rpm: 800.0 });
        check(&ThrottleAngle { angle_deg: 3.0 });
        check(&EgrCommand { position: 0.3 });
        check(&ManifoldPressure {
            pressure_pa: 35_000.0,
        });
        check(&MassAirFlow { flow_kg_s: 0.004 });
        check(&IntakeTruth {
            p_m_pa: 35_000.0,
            w_thr_kg_s: 0.004,
            w_egr_kg_s: 0.0,
            w_inv_kg_s: 0.004,
            w_leak_kg_s: 0.0,
            egr_actual: 0.0,
            fault: "none".into(),
            fault_active: false,
            fault_observable: false,
        });
        check(&PositionEstimate {
            angle_deg: 1.0,
            lower_deg: 0.5,
            upper_deg: 1.5,
            source: "tps".into(),
        });
        check(&InnovationMsg {
            filter: "f".into(),
            residual: vec![0.1],
            variance: vec![1.0],
            nis: 0.01,
            dof: 1,
        });
        check(&TestStatistic {
            test: "t".into(),
            value: 1.0,
            min: 0.0,
            max: 2.0,
            verdict: "PASSED".into(),
        });
        check(&DtcStatusMsg {
            dtc: "P0123-1C".into(),
            status: 0x27,
        });
        let event: DiagnosticEvent = serde_json::from_str(
            r#"{"time_s": 12.5, "event": "tps_a_high", "dtc": "P0123-1C", "dtc_uds": 74524,
                "trigger": "test_result", "status_before": 80, "status_after": 39,
                "changed": ["testFailed"], "fdc": 127, "occurrence_counter": 1,
                "aging_counter": 0, "memory": "stored", "displaced": null,
                "freeze_frame": [{"signal": "tps_a_v", "value": 4.93}],
                "test_result": {"value": 4.93, "min": 0.25, "max": 4.75, "verdict": "FAILED"},
                "candidates": [{"fault": "tps_a_bias", "score": 0.09}]}"#,
        )
        .unwrap();
        check(&event);
    }

    #[test]
    fn topics_are_unique_and_found() {
        let all: Vec<&TopicSchema> = TOPICS
            .iter()
            .chain(INTAKE_TOPICS.iter())
            .chain(INTAKE_OUTPUT_TOPICS.iter())
            .copied()
            .collect();
        for (i, a) in all.iter().enumerate() {
            assert_eq!(builtin_topic(a.topic), Some(*a));
            for b in &all[i + 1..] {
                assert_ne!(a.topic, b.topic);
                assert_ne!(a.schema_name, b.schema_name);
            }
        }
        assert_eq!(builtin_topic("/nope"), None);
    }
}
