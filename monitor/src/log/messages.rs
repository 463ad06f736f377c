//! The message types fdd reads and writes, one per topic, and the serde helpers that write a
//! non-finite `f64` as JSON `null` and read `null` back as NaN.
//!
//! Units are in the field names (`_v` volts, `_w` watts, `_a` amperes, `_deg` degrees, `_pa`
//! pascals, `_kg_s` kg/s, `_rpm` rev/min) and in the doc comments; the
//! [module documentation](super) has the table of the throttle and fdd topics. The intake
//! topics (`/intake/*`, `/truth/intake`: [`EngineSpeed`] .. [`IntakeTruth`]) are listed in
//! [`INTAKE_TOPICS`](super::schema::INTAKE_TOPICS).

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use fdd_diagnostics::event::DiagnosticEvent;

use super::schema::{self, TopicSchema};

/// A message type with a fixed topic and JSON schema, written with
/// [`LogWriter::write_message`](super::LogWriter::write_message) and read with
/// [`LogMessage::decode`](super::LogMessage::decode).
pub trait TopicMessage: Serialize + DeserializeOwned {
    /// The topic and schema of this type.
    const SCHEMA: &'static TopicSchema;
    /// The channel topic, e.g. `/throttle/tps`.
    const TOPIC: &'static str = Self::SCHEMA.topic;
}

/// `/throttle/motor_voltage`: the voltage applied to the throttle motor (the model input `u`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotorVoltage {
    /// Motor voltage, V. `null` in JSON when not finite.
    #[serde(with = "nan_as_null")]
    pub voltage_v: f64,
}

/// `/throttle/tps`: the throttle position sensor output.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TpsVoltage {
    /// Sensor output voltage, V (0..5 V for 0..90 deg with the default
    /// `[position_sensor]` configuration). `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub voltage_v: f64,
}

/// `/throttle/wattmeter`: the wattmeter on the throttle motor supply.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Wattmeter {
    /// Motor power `i^2` into 1 ohm, W (numerically the squared motor current in A^2), with
    /// the wattmeter's noise. `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub power_w: f64,
}

/// `/truth/throttle`: the simulated truth, written by fixtures only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ThrottleTruth {
    /// True plate angle, deg (0 closed .. 90 wide open).
    #[serde(with = "nan_as_null")]
    pub angle_deg: f64,
    /// True plate angular velocity `rho`, in the identified throttle model's own units (the
    /// second state of `fdd_estimators::models::throttle`).
    #[serde(with = "nan_as_null")]
    pub velocity: f64,
    /// True motor current, A.
    #[serde(with = "nan_as_null")]
    pub current_a: f64,
    /// The scenario's fault name, e.g. `"none"`, `"tps_stuck"`.
    pub fault: String,
    /// Whether the fault is active at this sample.
    pub fault_active: bool,
    /// Whether the active fault changes a reading at this sample by more than a healthy part
    /// could (simulated logs since the throttle simulator marks it; absent in older logs,
    /// read as `fault_active`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fault_observable: Option<bool>,
}

/// `/intake/engine_speed`: engine speed over one 180 deg crank segment (the intake model's
/// input `N`). The intake model is discretized per segment, so the speed is the one an ECU
/// computes from the segment time, not an instantaneous value.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EngineSpeed {
    /// Engine speed, rpm: `30 / T` for a segment of `T` seconds. `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub speed_rpm: f64,
}

/// `/intake/throttle`: throttle opening over one crank segment (the intake model's input
/// `theta`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ThrottleAngle {
    /// Throttle opening from the closed plate, deg. `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub angle_deg: f64,
}

/// `/intake/egr_command`: the commanded EGR valve position over one crank segment (the intake
/// model's input `e`). The command, not the valve: a stuck valve differs from it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EgrCommand {
    /// Commanded position, 0 closed .. 1 fully open (dimensionless). `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub position: f64,
}

/// `/intake/map`: the manifold absolute pressure sensor reading.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ManifoldPressure {
    /// Manifold absolute pressure, Pa. `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub pressure_pa: f64,
}

/// `/intake/maf`: the mass air flow sensor reading (metered air upstream of the throttle; a
/// manifold leak bypasses it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MassAirFlow {
    /// Air mass flow, kg/s. `null` when not finite.
    #[serde(with = "nan_as_null")]
    pub flow_kg_s: f64,
}

/// `/truth/intake`: the simulated intake-manifold truth, written by fixtures only.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntakeTruth {
    /// True manifold pressure, Pa.
    #[serde(with = "nan_as_null")]
    pub p_m_pa: f64,
    /// True throttle (metered) air flow, kg/s.
    #[serde(with = "nan_as_null")]
    pub w_thr_kg_s: f64,
    /// True EGR flow at the actual valve position, kg/s.
    #[serde(with = "nan_as_null")]
    pub w_egr_kg_s: f64,
    /// True intake-valve (engine) flow, kg/s.
    #[serde(with = "nan_as_null")]
    pub w_inv_kg_s: f64,
    /// True unmetered leak flow into the manifold, kg/s (0 without a leak).
    #[serde(with = "nan_as_null")]
    pub w_leak_kg_s: f64,
    /// Actual EGR valve position, 0..1 (differs from the command under an EGR fault).
    #[serde(with = "nan_as_null")]
    pub egr_actual: f64,
    /// The fault present at this sample: the scenario's fault name (e.g. `"map_bias"`,
    /// `"leak"`) once active, `"none"` before (as in [`ThrottleTruth`]).
    pub fault: String,
    /// Whether the fault is active at this sample.
    pub fault_active: bool,
    /// Whether the fault is active and has an effect at this sample: a detector can only be
    /// expected to see it then (an EGR valve stuck where it is commanded has no effect).
    pub fault_observable: bool,
}

/// `/fdd/throttle/position`: fdd's throttle position output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PositionEstimate {
    /// Estimated plate angle, deg. `null` (NaN) when no estimate is available.
    #[serde(with = "nan_as_null")]
    pub angle_deg: f64,
    /// Lower end of the 95% interval, deg.
    #[serde(with = "nan_as_null")]
    pub lower_deg: f64,
    /// Upper end of the 95% interval, deg.
    #[serde(with = "nan_as_null")]
    pub upper_deg: f64,
    /// Where the estimate comes from: `"tps"` (the position sensor) or `"wattmeter_estimate"`
    /// (the wattmeter UKF, when the sensor is diagnosed faulty).
    pub source: String,
}

/// `/fdd/throttle/innovation`: one filter's innovation after an update.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InnovationMsg {
    /// The filter's name, as configured (e.g. `"ukf_ahsm"`).
    pub filter: String,
    /// Innovation `y - h(x)` per measurement component, in that measurement's units (V for the
    /// position sensor, W for the wattmeter). `null` entries are non-finite values.
    #[serde(with = "vec_nan_as_null")]
    pub residual: Vec<f64>,
    /// Innovation variance per component (the diagonal of `S`), in the squared measurement
    /// units (V^2, W^2).
    #[serde(with = "vec_nan_as_null")]
    pub variance: Vec<f64>,
    /// Normalized innovation squared `r' S^-1 r`, dimensionless.
    #[serde(with = "nan_as_null")]
    pub nis: f64,
    /// Degrees of freedom of `nis` (the number of measurement components used).
    pub dof: u32,
}

/// `/fdd/tests`: one step of one statistical test (OBD service $06 convention: passed when
/// `min <= value <= max`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TestStatistic {
    /// The test's name, as configured.
    pub test: String,
    /// The test statistic, in the test's units (dimensionless for NIS-based tests; V for a
    /// range check on a voltage). `null` when the test did not run.
    #[serde(with = "nan_as_null")]
    pub value: f64,
    /// Lower limit, same units.
    #[serde(with = "nan_as_null")]
    pub min: f64,
    /// Upper limit (the threshold), same units.
    #[serde(with = "nan_as_null")]
    pub max: f64,
    /// `"PASSED"`, `"FAILED"`, `"PRE_PASSED"`, `"PRE_FAILED"` or `"NOT_TESTED"`
    /// (`fdd_diagnostics::verdict::Verdict`).
    pub verdict: String,
}

/// `/fdd/dtc_status`: a DTC's ISO 14229-1 status byte, written when it changes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct DtcStatusMsg {
    /// The UDS DTC as J2012 code and failure type byte, e.g. `"P0123-1C"`.
    pub dtc: String,
    /// The status byte, 0-255 (bit 0 testFailed ... bit 7 warningIndicatorRequested).
    pub status: u8,
}

impl TopicMessage for MotorVoltage {
    const SCHEMA: &'static TopicSchema = &schema::MOTOR_VOLTAGE;
}
impl TopicMessage for TpsVoltage {
    const SCHEMA: &'static TopicSchema = &schema::TPS_VOLTAGE;
}
impl TopicMessage for Wattmeter {
    const SCHEMA: &'static TopicSchema = &schema::WATTMETER;
}
impl TopicMessage for ThrottleTruth {
    const SCHEMA: &'static TopicSchema = &schema::THROTTLE_TRUTH;
}
impl TopicMessage for EngineSpeed {
    const SCHEMA: &'static TopicSchema = &schema::ENGINE_SPEED;
}
impl TopicMessage for ThrottleAngle {
    const SCHEMA: &'static TopicSchema = &schema::THROTTLE_ANGLE;
}
impl TopicMessage for EgrCommand {
    const SCHEMA: &'static TopicSchema = &schema::EGR_COMMAND;
}
impl TopicMessage for ManifoldPressure {
    const SCHEMA: &'static TopicSchema = &schema::MANIFOLD_PRESSURE;
}
impl TopicMessage for MassAirFlow {
    const SCHEMA: &'static TopicSchema = &schema::MASS_AIR_FLOW;
}
impl TopicMessage for IntakeTruth {
    const SCHEMA: &'static TopicSchema = &schema::INTAKE_TRUTH;
}
impl TopicMessage for PositionEstimate {
    const SCHEMA: &'static TopicSchema = &schema::POSITION_ESTIMATE;
}
impl TopicMessage for InnovationMsg {
    const SCHEMA: &'static TopicSchema = &schema::INNOVATION;
}
impl TopicMessage for TestStatistic {
    const SCHEMA: &'static TopicSchema = &schema::TEST_STATISTIC;
}
impl TopicMessage for DtcStatusMsg {
    const SCHEMA: &'static TopicSchema = &schema::DTC_STATUS;
}
/// `/fdd/events`: the JSON shape documented in `fdd_diagnostics::event`.
impl TopicMessage for DiagnosticEvent {
    const SCHEMA: &'static TopicSchema = &schema::DIAGNOSTIC_EVENT;
}

/// Serde helpers for an `f64` field: a non-finite value (NaN, +-inf) is written as `null` (JSON
/// has no NaN) and `null` is read back as NaN. Use with `#[serde(with = "nan_as_null")]`.
pub mod nan_as_null {
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes `v`, or `null` when it is not finite.
    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        if v.is_finite() {
            s.serialize_f64(*v)
        } else {
            s.serialize_none()
        }
    }

    /// Reads a number, or `null` as NaN.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
    }
}

/// [`nan_as_null`] for each element of a `Vec<f64>`. Use with
/// `#[serde(with = "vec_nan_as_null")]`.
pub mod vec_nan_as_null {
    use serde::ser::SerializeSeq;
    use serde::{Deserialize, Deserializer, Serializer};

    /// Writes the elements, non-finite ones as `null`.
    pub fn serialize<S: Serializer>(v: &[f64], s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(v.len()))?;
        for x in v {
            if x.is_finite() {
                seq.serialize_element(x)?;
            } else {
                seq.serialize_element(&Option::<f64>::None)?;
            }
        }
        seq.end()
    }

    /// Reads an array of numbers and `null`s (as NaN).
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
        let v = Vec::<Option<f64>>::deserialize(d)?;
        Ok(v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_is_null_and_reads_back_as_nan() {
        let m = InnovationMsg {
            filter: "f".into(),
            residual: vec![1.5, f64::NAN, f64::INFINITY],
            variance: vec![f64::NEG_INFINITY, 2.0, 3.0],
            nis: f64::NAN,
            dof: 3,
        };
        let s = serde_json::to_string(&m).unwrap();
        assert_eq!(
            s,
            r#"{"filter":"f","residual":[1.5,null,null],"variance":[null,2.0,3.0],"nis":null,"dof":3}"#
        );
        let back: InnovationMsg = serde_json::from_str(&s).unwrap();
        assert_eq!(back.residual[0], 1.5);
        assert!(back.residual[1].is_nan() && back.residual[2].is_nan());
        assert!(back.variance[0].is_nan());
        assert!(back.nis.is_nan());
        let t: MotorVoltage = serde_json::from_str(r#"{"voltage_v":null}"#).unwrap();
        assert!(t.voltage_v.is_nan());
        assert_eq!(
            serde_json::to_string(&MotorVoltage {
                voltage_v: f64::INFINITY
            })
            .unwrap(),
            r#"{"voltage_v":null}"#
        );
    }

    #[test]
    fn topics_follow_the_schema_table() {
        assert_eq!(MotorVoltage::TOPIC, "/throttle/motor_voltage");
        assert_eq!(TpsVoltage::TOPIC, "/throttle/tps");
        assert_eq!(Wattmeter::TOPIC, "/throttle/wattmeter");
        assert_eq!(ThrottleTruth::TOPIC, "/truth/throttle");
        assert_eq!(PositionEstimate::TOPIC, "/fdd/throttle/position");
        assert_eq!(InnovationMsg::TOPIC, "/fdd/throttle/innovation");
        assert_eq!(TestStatistic::TOPIC, "/fdd/tests");
        assert_eq!(DtcStatusMsg::TOPIC, "/fdd/dtc_status");
        assert_eq!(DiagnosticEvent::TOPIC, "/fdd/events");
        assert_eq!(EngineSpeed::TOPIC, "/intake/engine_speed");
        assert_eq!(ThrottleAngle::TOPIC, "/intake/throttle");
        assert_eq!(EgrCommand::TOPIC, "/intake/egr_command");
        assert_eq!(ManifoldPressure::TOPIC, "/intake/map");
        assert_eq!(MassAirFlow::TOPIC, "/intake/maf");
        assert_eq!(IntakeTruth::TOPIC, "/truth/intake");
    }
}
