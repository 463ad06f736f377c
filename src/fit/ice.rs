//! `fdd fit turbo-ice`: calibrates the turbocharged air-path model to a fault-free driving log
//! of the LiU-ICE engine (an MCAP log converted by `fdd import` with
//! `config/import/liu_ice.toml`), judges it on other fault-free logs, and writes a complete,
//! commented parameter file with a `[measurement_noise]` table.
//!
//! The math is `fdd_estimators::models::turbo::fit::ice`; this module reads the logs (every
//! error names the file and, for a missing signal, the topic and field), and renders the file.
//! The output is deterministic, as `fdd fit turbo`'s.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use fdd_estimators::models::turbo::fit::ice::{
    check_log, fit_ice, IceOptions, IceOutcome, LogCheck, LogSample,
};
use fdd_monitor::log::LogReader;

use super::{load_params, write_atomic, FitIoError};

/// The topics and fields the fit reads, in [`LogSample`] order after the time (the names
/// `config/import/liu_ice.toml` gives them).
pub const TOPICS: [(&str, &str); 9] = [
    ("/turbo/p_ic", "pressure_pa"),
    ("/turbo/T_ic", "temperature_k"),
    ("/turbo/p_im", "pressure_pa"),
    ("/turbo/maf", "flow_kg_s"),
    ("/turbo/engine_speed", "speed_rad_s"),
    ("/turbo/throttle", "position_pct"),
    ("/turbo/wastegate", "position"),
    ("/turbo/ambient_pressure", "pressure_pa"),
    ("/turbo/ambient_temperature", "temperature_k"),
];

/// Fewest complete rows a log must have.
pub const MIN_ROWS: usize = 100;

/// Reads a log's rows: every message of the nine topics, by log time; a row is kept where all
/// nine have a value at that time.
pub fn read_log(path: &Path) -> Result<Vec<LogSample>, FitIoError> {
    let log_err = |source| FitIoError::Log {
        file: path.to_path_buf(),
        source: Box::new(source),
    };
    let reader = LogReader::open(path).map_err(log_err)?;
    let mut rows: BTreeMap<u64, [Option<f64>; 9]> = BTreeMap::new();
    let mut seen = [false; 9];
    for msg in reader {
        let msg = msg.map_err(log_err)?;
        if let Some(k) = TOPICS.iter().position(|(t, _)| *t == &*msg.topic) {
            let v = msg.field_f64(TOPICS[k].1).map_err(log_err)?;
            seen[k] = true;
            rows.entry(msg.log_time_ns).or_insert([None; 9])[k] = Some(v);
        }
    }
    if let Some(k) = seen.iter().position(|s| !s) {
        return Err(FitIoError::MissingTopic {
            file: path.to_path_buf(),
            topic: TOPICS[k].0,
            field: TOPICS[k].1,
        });
    }
    let samples: Vec<LogSample> = rows
        .iter()
        .filter_map(|(t, r)| {
            let v: Vec<f64> = r.iter().copied().collect::<Option<Vec<f64>>>()?;
            Some(LogSample {
                t_s: *t as f64 * 1e-9,
                p_ic_pa: v[0],
                t_ic_k: v[1],
                p_im_pa: v[2],
                air_flow_kg_s: v[3],
                engine_speed_rad_s: v[4],
                throttle_pct: v[5],
                wastegate: v[6],
                ambient_pressure_pa: v[7],
                ambient_temperature_k: v[8],
            })
        })
        .collect();
    if samples.len() < MIN_ROWS {
        return Err(FitIoError::TooFewRows {
            file: path.to_path_buf(),
            rows: samples.len(),
            need: MIN_ROWS,
        });
    }
    Ok(samples)
}

/// The command's arguments.
#[derive(Debug, Clone)]
pub struct FitIceArgs {
    /// The calibration log (fault-free).
    pub log: PathBuf,
    /// Other fault-free logs, only judged.
    pub judge: Vec<PathBuf>,
    /// The start parameter file.
    pub start: PathBuf,
    /// The output parameter file.
    pub out: PathBuf,
}

/// What the command computed.
#[derive(Debug, Clone)]
pub struct FitIceRun {
    /// The fit.
    pub outcome: IceOutcome,
    /// The check on the calibration log, then on each judged log.
    pub checks: Vec<(PathBuf, LogCheck)>,
    /// The file's text as written.
    pub file_text: String,
}

/// Runs the fit and the checks, and writes the parameter file.
pub fn run(args: &FitIceArgs) -> Result<FitIceRun, FitIoError> {
    let mut inputs = vec![args.start.clone(), args.log.clone()];
    inputs.extend(args.judge.iter().cloned());
    if let Ok(out) = args.out.canonicalize() {
        if inputs
            .iter()
            .any(|i| i.canonicalize().is_ok_and(|i| i == out))
        {
            return Err(FitIoError::OutputIsInput {
                file: args.out.clone(),
            });
        }
    }
    let start = load_params(&args.start)?;
    let opts = IceOptions::liu_ice();
    let samples = read_log(&args.log)?;
    let judged = args
        .judge
        .iter()
        .map(|p| read_log(p).map(|s| (p.clone(), s)))
        .collect::<Result<Vec<_>, _>>()?;
    let outcome = fit_ice(&start, &samples, &opts)?;
    let mut checks = vec![(
        args.log.clone(),
        check_log(&outcome.params, &samples, &opts)?,
    )];
    for (p, s) in &judged {
        checks.push((p.clone(), check_log(&outcome.params, s, &opts)?));
    }
    let file_text = parameter_file(args, &outcome, &checks, &opts);
    write_atomic(&args.out, &file_text)?;
    Ok(FitIceRun {
        outcome,
        checks,
        file_text,
    })
}

/// A file name for the header (the path as given, `/` separated).
fn shown(p: &Path) -> String {
    p.to_string_lossy().replace('\\', "/")
}

/// The figures table (plain text): one block per log, the stationary model at the
/// quasi-stationary samples and the model run along the whole log.
pub fn table(checks: &[(PathBuf, LogCheck)]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "  {:<34} {:>6} {:>8} | {:>16} {:>9} | {:>16} {:>9}",
        "log (role, quasi-stat. / rows)",
        "signal",
        "mean",
        "stationary RMSE",
        "RMSE %",
        "simulated RMSE",
        "RMSE %"
    );
    for (k, (path, c)) in checks.iter().enumerate() {
        let name = path
            .file_name()
            .map_or_else(|| shown(path), |n| n.to_string_lossy().into_owned());
        let role = if k == 0 { "calibration" } else { "judged" };
        let titles = [
            name.trim_end_matches(".mcap").to_string(),
            format!("({role}, {}/{})", c.p_im.samples, c.samples),
            String::new(),
        ];
        for (j, (sig, st, sim, scale, unit)) in [
            ("p_im", &c.p_im, &c.simulated[0], 1e-3, "kPa"),
            ("p_ic", &c.p_ic, &c.simulated[1], 1e-3, "kPa"),
            ("W_af", &c.air_flow, &c.simulated[2], 1e3, "g/s"),
        ]
        .into_iter()
        .enumerate()
        {
            let _ = writeln!(
                s,
                "  {:<34} {:>6} {:>8.3} | {:>12.3} {unit:<3} {:>9.2} | {:>12.3} {unit:<3} {:>9.2}",
                titles[j],
                sig,
                st.mean * scale,
                st.rmse * scale,
                st.rmse_pct,
                sim.rmse * scale,
                sim.rmse_pct
            );
        }
    }
    s
}

/// The parameter file's text.
pub fn parameter_file(
    args: &FitIceArgs,
    o: &IceOutcome,
    checks: &[(PathBuf, LogCheck)],
    opts: &IceOptions,
) -> String {
    let judge_args: String = args
        .judge
        .iter()
        .map(|j| format!(" \\\n      --judge {}", shown(j)))
        .collect();
    let header = format!(
        "Mean value model of the air path of a turbocharged SI engine (13 states), calibrated to the
LiU-ICE engine from ONE fault-free log,
  {log},
with the VEP4 2.0 L set ({start}) as the start. Generated by `fdd fit turbo-ice`
(do not edit; FDD_BLESS=1 cargo test --release --test fit_turbo_ice regenerates it):

  fdd fit turbo-ice --log {log}{judge_args} \\
      --start {start} -o config/turbo_liu_ice.toml

Only the calibration log is fitted; the --judge logs (the other fault-free files) are only
compared, and no fault window is read. The calibration log has {qs} quasi-stationary samples
of {rows} (throttle within {thb} %-points, speed within {spb} %, wastegate within {wgb} from {settle} s
before to {after} s after the sample; chosen on the inputs only). Fitted:
- volumetric efficiency, at the {cs} samples where the manifold has settled (inputs steady
  {csettle} s before to {cafter} s after; the quasi-stationary ones are nearly all at idle): a
  quadratic in p_im + s1 n + s2 n^2 on the air flow minus the manifold's filling
  V_im/(R T_ic) dp_im/dt, p_em taken as the ambient pressure (not logged); W RMS {ve:.2} g/s;
- throttle effective area, same samples: the quadratic in the plate angle (VEP4's angle map),
  from p_ic, T_ic, p_im and the air flow minus the intercooler's filling, weighted by each
  sample's p_im sensitivity; p_im RMS {th:.0} Pa;
- boost: the turbine flow constant k1 (the one scalar p_ic against speed, air flow and wastegate
  could give), on the stationary p_ic at the quasi-stationary samples: {boost}.
- measurement noise (the [measurement_noise] table): each sensor's variance about its {lm}-sample
  centred mean at the quasi-stationary samples, floored (p 20 Pa, T 0.05 K, W 0.02 g/s std).
Lambda 1 (not logged; closed-loop SI engine); ambient pressure and temperature from the log.
Undetermined by the log and kept from VEP4: the volumes, every exhaust-side parameter (no p_em,
T_em or turbo speed is logged: exhaust temperature, pipes, exhaust restriction, turbine k2 and
efficiency, wastegate area), the compressor map, the air filter and intercooler resistances
and effectiveness, the shaft, the numerical continuations and clamps.

Whole model against the sensors on each log: its stationary point at the quasi-stationary
samples, and the model run along the whole log with the log's inputs (20 Hz, from the
stationary point at the first sample):
",
        log = shown(&args.log),
        start = shown(&args.start),
        qs = o.quasi_stationary,
        rows = o.samples,
        thb = opts.throttle_band_pct,
        spb = opts.speed_band_rel * 100.0,
        wgb = opts.wastegate_band,
        settle = opts.settle_s,
        after = opts.after_s,
        ve = o.vol_eff.rms_kg_s * 1000.0,
        th = o.throttle.rms_p_im_pa,
        cs = o.component_samples,
        csettle = opts.component_settle_s,
        cafter = opts.component_after_s,
        boost = if o.boost.determined {
            format!(
                "k1 {:.4e} (relative std error {:.2}), p_ic RMS {:.0} Pa (VEP4's k1 {}: {:.0} Pa)",
                o.boost.k1, o.boost.k1_rel_std_error, o.boost.rms_pa, o.boost.k1_start, o.boost.rms_start_pa
            )
        } else {
            format!(
                "NOT determined (relative\n  standard error {:.1e}: these samples hardly boost; p_ic RMS {:.0} Pa with VEP4's k1 {},\n  which is kept)",
                o.boost.k1_rel_std_error, o.boost.rms_start_pa, o.boost.k1_start
            )
        },
        lm = opts.local_mean_samples,
    );
    let mut s = String::new();
    for line in header.lines().chain(table(checks).lines()) {
        if line.is_empty() {
            s.push_str("#\n");
        } else {
            let _ = writeln!(s, "# {line}");
        }
    }
    s.push_str("\n[model]\n");
    for (key, value) in super::render::entries(&o.params) {
        let note: Option<String> = match key {
            "vol_eff_factor" => Some(format!(
                "Fitted (the vol_eff_* keys), {} samples; relative W RMS {:.3}.",
                o.vol_eff.points, o.vol_eff.rms_rel
            )),
            "throttle_area_coeffs_m2_rad" => Some(format!(
                "Fitted, {} samples (area step: {} with p_im/p_ic < 0.95, relative RMS {:.3}).",
                o.throttle.points, o.throttle.area_points, o.throttle.area_rms_rel
            )),
            "turbine_flow_k1_kg_k05_per_s_kpa" => Some(if o.boost.determined {
                format!(
                    "Fitted on p_ic, {} samples (VEP4 {}).",
                    o.boost.samples, o.boost.k1_start
                )
            } else {
                "VEP4's: the log's quasi-stationary p_ic does not determine it (see the header)."
                    .into()
            }),
            _ => None,
        };
        if let Some(n) = note {
            let _ = writeln!(s, "# {n}");
        }
        let _ = writeln!(s, "{key} = {}", super::render::value_text(&value));
    }
    s.push_str(
        "\n# Measurement noise variances (R of the observer), about a local mean at quasi-stationary\n\
         # samples of the calibration log, floored.\n[measurement_noise]\n",
    );
    for n in &o.noise {
        let _ = writeln!(
            s,
            "# {}: measured std {:.4e} {}, floor {:.1e}, {} samples.",
            n.name,
            n.measured_variance.sqrt(),
            n.unit,
            n.floor.sqrt(),
            n.samples
        );
        let unit = match n.unit {
            "Pa" => "pa2",
            "K" => "k2",
            _ => "kg2_per_s2",
        };
        let _ = writeln!(
            s,
            "{}_variance_{unit} = {}",
            n.name.to_lowercase(),
            super::render::num(n.variance)
        );
    }
    s
}

/// The figures as JSON.
pub fn json(run: &FitIceRun) -> serde_json::Value {
    let stats = |c: &LogCheck| {
        let one = |st: &fdd_estimators::models::turbo::fit::ice::LogStats| {
            serde_json::json!({
                "rmse": st.rmse, "mean": st.mean, "rmse_pct": st.rmse_pct, "bias": st.bias,
                "samples": st.samples,
            })
        };
        serde_json::json!({
            "p_im": one(&c.p_im), "p_ic": one(&c.p_ic), "air_flow": one(&c.air_flow),
            "simulated": {
                "p_im": one(&c.simulated[0]), "p_ic": one(&c.simulated[1]),
                "air_flow": one(&c.simulated[2]),
            },
            "rows": c.samples,
        })
    };
    let o = &run.outcome;
    serde_json::json!({
        "logs": run.checks.iter().map(|(p, c)| serde_json::json!({
            "file": shown(p), "figures": stats(c),
        })).collect::<Vec<_>>(),
        "quasi_stationary_samples": o.quasi_stationary,
        "turbine_k1": o.boost.k1,
        "noise_variance": o.noise.iter().map(|n| (n.name.to_string(), serde_json::json!(n.variance))).collect::<serde_json::Map<_, _>>(),
    })
}
