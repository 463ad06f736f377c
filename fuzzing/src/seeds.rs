//! Small seed inputs for the MCAP and replay targets: committed fixtures are 0.2-2 MB, far too
//! large for a fuzzer to mutate usefully, so the seeds are short scenarios simulated here with
//! the same simulators and writer, in each chunk layout fdd reads (uncompressed and zstd,
//! with and without message indexes, one chunk and several).

use std::io::Cursor;

use fdd_fixtures::scenario_file::AnyScenario;
use fdd_monitor::log::{ChunkCompression, LogWriter, WriteOptions};

/// Short scenarios: (name, TOML text). Throttle at 1 kHz for 60 ms with a TPS open circuit at
/// 30 ms; intake for 0.5 s with a leak at 0.25 s. A few kilobytes each: libFuzzer mutates
/// small inputs far faster, and a replay of either still runs every monitor step.
const SCENARIOS: &[(&str, &str)] = &[
    (
        "throttle_seed",
        r#"name = "throttle_seed"
monitor = "throttle"
duration_s = 0.06
seed = 2
sample_period_s = 0.001
[excitation]
kind = "pulse_train"
amplitude_v = [0.0, 1.2]
pulse_s = [0.01, 0.03]
block_s = [0.02, 0.06]
cutoff_hz = [0.5, 20.0]
[sensors]
tps_noise_std_v = 0.005
adc_bits = 10
wattmeter_noise_std_w = 0.1
[fault]
kind = "tps_open"
start_s = 0.03
"#,
    ),
    (
        "intake_seed",
        r#"name = "intake_seed"
monitor = "intake"
duration_s = 0.5
seed = 106
[profile]
kind = "tip_in_out"
[fault]
kind = "leak"
start_s = 0.25
diameter_m = 0.003
"#,
    ),
];

/// The chunk layouts: (suffix, options).
const LAYOUTS: &[(&str, WriteOptions)] = &[
    (
        "plain_indexed",
        WriteOptions {
            chunk_size: 2048,
            compression: ChunkCompression::None,
            message_indexes: true,
        },
    ),
    (
        "zstd_one_chunk",
        WriteOptions {
            chunk_size: 1 << 20,
            compression: ChunkCompression::Zstd { level: 1 },
            message_indexes: false,
        },
    ),
];

/// The seed scenarios' texts, for the `scenario` target's corpus.
pub fn scenario_texts() -> impl Iterator<Item = (&'static str, &'static str)> {
    SCENARIOS.iter().copied()
}

/// Every seed log: (file name, bytes). Deterministic: the same build gives the same bytes.
pub fn small_logs() -> Result<Vec<(String, Vec<u8>)>, String> {
    let mut out = Vec::new();
    for (name, text) in SCENARIOS {
        let s = AnyScenario::parse(text, name).map_err(|e| e.to_string())?;
        for (suffix, options) in LAYOUTS {
            let file = format!("{name}_{suffix}.mcap");
            let w = LogWriter::with_options(Cursor::new(Vec::new()), &file, *options)
                .map_err(|e| e.to_string())?;
            let (cursor, _) = s.write_log(w).map_err(|e| e.to_string())?;
            out.push((file, cursor.into_inner()));
        }
    }
    Ok(out)
}
