//! fdd's configuration is TOML: the diagnostics' configuration types must read from it as
//! documented, and a wrong value must come back as an error that names its key.

use fdd_diagnostics::detectors::{
    ChiSquareConfig, ChiSquareWindow, Cusum, CusumConfig, Glr, GlrConfig, RangeRateCheck,
    RangeRateConfig,
};
use fdd_diagnostics::dtc::{EventMemory, EventMemoryConfig};
use fdd_diagnostics::isolation::{SignatureConfig, SignatureMatrix};

const GOOD: &str = r#"
[chi_square]
window = 20
false_alarm_probability = 1e-4

[cusum]
min_bias_sigma = 1.0
mean_steps_between_false_alarms = 100000.0

[glr]
window = 50
false_alarm_probability = 1e-4

[tps_range]
low_limit = 0.25
high_limit = 4.75
max_rate = 200.0

[isolation]
tests = ["r_position", "r_wattmeter", "r_both"]
faults = ["position_sensor", "wattmeter", "plate_stuck"]
rows = ["1 0 X", "0 1 1", "1 1 1"]

[memory]
capacity = 8

[[memory.events]]
name = "tps_a_high"
dtc = "P0123-1C"
priority = 2
freeze_frame = ["tps_a_v", "motor_v"]
debounce = { kind = "counter", increment_step = 8, failed_threshold = 64 }

[[memory.events]]
name = "tps_a_performance"
dtc = "P0121-92"
priority = 3
confirmation_threshold = 2
debounce = { kind = "time", failed_time_s = 0.3, passed_time_s = 1.0 }
"#;

fn table(text: &str) -> toml::Table {
    toml::from_str(text).expect("valid TOML")
}

fn section<T: serde::de::DeserializeOwned>(
    t: &toml::Table,
    key: &str,
) -> Result<T, toml::de::Error> {
    t[key].clone().try_into()
}

#[test]
fn documented_shapes_build_working_components() {
    let t = table(GOOD);
    let chi: ChiSquareConfig = section(&t, "chi_square").expect("chi_square");
    ChiSquareWindow::<64>::new(&chi).expect("chi-square builds");
    let cusum: CusumConfig = section(&t, "cusum").expect("cusum");
    Cusum::new(&cusum).expect("cusum builds");
    let glr: GlrConfig = section(&t, "glr").expect("glr");
    Glr::<64>::new(&glr).expect("glr builds");
    let rr: RangeRateConfig = section(&t, "tps_range").expect("range");
    RangeRateCheck::new(&rr).expect("range check builds");
    let iso: SignatureConfig = section(&t, "isolation").expect("isolation");
    SignatureMatrix::new(&iso).expect("matrix builds");
    let mem: EventMemoryConfig = section(&t, "memory").expect("memory");
    let memory = EventMemory::new(&mem).expect("memory builds");
    let id = memory.event_id("tps_a_high").expect("configured event");
    assert_eq!(memory.dtc(id).to_string(), "P0123-1C");
}

#[test]
fn wrong_values_name_their_key() {
    let bad = |from: &str, to: &str| table(&GOOD.replace(from, to));

    let t = bad("window = 20", "window = -3");
    let err = ChiSquareWindow::<64>::new(&section(&t, "chi_square").expect("parses")).unwrap_err();
    assert_eq!(err.field, "window", "{err}");

    let t = bad(
        "false_alarm_probability = 1e-4\n\n[cusum]",
        "false_alarm_probability = 1.5\n\n[cusum]",
    );
    let err = ChiSquareWindow::<64>::new(&section(&t, "chi_square").expect("parses")).unwrap_err();
    assert_eq!(err.field, "false_alarm_probability", "{err}");

    let t = bad("low_limit = 0.25", "low_limit = 4.9");
    let err = RangeRateCheck::new(&section(&t, "tps_range").expect("parses")).unwrap_err();
    assert!(err.field.contains("limit"), "{err}");

    let t = bad("failed_threshold = 64", "failed_threshold = -5");
    let err = EventMemory::new(&section(&t, "memory").expect("parses")).unwrap_err();
    assert_eq!(err.field, "events[0].debounce.failed_threshold", "{err}");

    let t = bad("P0121-92", "P5121-92");
    let err = EventMemory::new(&section(&t, "memory").expect("parses")).unwrap_err();
    assert_eq!(err.field, "events[1].dtc", "{err}");
    assert!(err.to_string().contains("0-3"), "{err}");

    // A misspelt key is refused by the parser, naming the key.
    let t = bad("min_bias_sigma", "min_bias_sigmaa");
    let err = section::<CusumConfig>(&t, "cusum").unwrap_err().to_string();
    assert!(err.contains("min_bias_sigmaa"), "{err}");
}
