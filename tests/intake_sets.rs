//! The intake scenario sets (`fixtures/sets/intake_tuning/`, `fixtures/sets/intake_heldout/`)
//! run through the intake monitor in memory, log by log, with what `fdd evaluate` does not show:
//! per log the largest statistic of every test on fault-free segments (as a fraction of its
//! threshold), the DTCs raised, and for the fault the *observable* driving time (the truth's
//! `fault_observable`) to the first DTC and to the first correct specific DTC.
//!
//! A tuning tool, so ignored by default:
//!
//! ```text
//! FDD_SET=fixtures/sets/intake_tuning cargo test --release --test intake_sets -- --ignored --nocapture
//! ```
//!
//! `FDD_INTAKE_CONFIG=file.toml` runs another intake configuration than the embedded one.
//! The held-out set is for the final report only: never choose a setting by looking at it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fdd::config::IntakeConfig;
use fdd::evaluate::fault_types::INTAKE;
use fdd_diagnostics::dtc::StatusBit;
use fdd_estimators::models::intake::{IntakeModel, ThrottleFlow};
use fdd_fixtures::intake_sim::{IntakeScenario, IntakeSim};
use fdd_monitor::intake::{IntakeMonitor, IntakeMonitorConfig, Segment, GROUP_EVENT};
use fdd_monitor::monitor::{Monitor, Output};
use fdd_monitor::signal_table::SignalTable;

fn table() -> SignalTable {
    // One segment of 100 ms at the slowest speed the model accepts; 250 ms is lost.
    SignalTable::with_names(&IntakeMonitorConfig::default().signal_names(), 250_000_000)
        .expect("table")
}

/// One raised DTC.
#[derive(Debug, Clone)]
struct Raised {
    t_s: f64,
    /// The ranked hypotheses and the decisions after the segment (FDD_VERBOSE).
    detail: String,
    event: String,
    candidates: Vec<(String, f64)>,
    /// Truth at the time: the active faults.
    active: Vec<&'static str>,
}

/// What one log gave.
#[derive(Debug, Default)]
struct LogOutcome {
    name: String,
    fault_free_s: f64,
    /// Fault-free time flagged (s): before the first fault, and after a fault.
    flagged_before_s: f64,
    flagged_after_s: f64,
    /// Largest value / threshold of each test on fault-free segments before any fault.
    max_ratio: BTreeMap<&'static str, f64>,
    raised: Vec<Raised>,
    /// The faults of the log and, per fault, observable time (s) to the first DTC naming any
    /// active fault (group with it among the candidates, or specific) and to the first correct
    /// specific DTC; total observable time.
    faults: Vec<FaultOutcome>,
}

#[derive(Debug, Default, Clone)]
struct FaultOutcome {
    kind: &'static str,
    observable_s: f64,
    any_dtc_s: Option<f64>,
    correct_s: Option<f64>,
    wrong: Vec<String>,
    /// Whether the first specific DTC raised while the fault acts (and not right for another
    /// fault acting with it) names it.
    first_specific: Option<bool>,
    group_missed: bool,
    group: bool,
}

fn specific_ok(kind: &str, event: &str) -> bool {
    INTAKE
        .iter()
        .find(|t| t.truth == kind)
        .is_some_and(|t| t.dtcs.contains(&event))
}

fn group_ok(kind: &str, candidates: &[(String, f64)]) -> bool {
    INTAKE.iter().find(|t| t.truth == kind).is_some_and(|t| {
        candidates
            .iter()
            .any(|(c, s)| *s > 0.0 && t.scored_as.contains(&c.as_str()))
    })
}

fn run_log(path: &Path, cfg: &IntakeConfig) -> LogOutcome {
    let text = std::fs::read_to_string(path).expect("read scenario");
    let sc = IntakeScenario::from_toml_str(&text, &path.display().to_string()).expect("scenario");
    let model = IntakeModel::new(cfg.model.clone(), ThrottleFlow::Nozzle).expect("model");
    let mut mon = IntakeMonitor::new(&model, &cfg.monitor, &table()).expect("monitor");
    mon.start_operation_cycle(0, &mut |_| {});
    let mut o = LogOutcome {
        name: sc.name.clone(),
        ..LogOutcome::default()
    };
    let kinds: Vec<&'static str> = sc.faults().map(|f| f.name()).collect();
    o.faults = kinds
        .iter()
        .filter(|k| **k != "none")
        .map(|k| FaultOutcome {
            kind: k,
            ..FaultOutcome::default()
        })
        .collect();
    let mut last_t = 0.0;
    // FDD_TRACE=file: one CSV-ish line per segment (inputs, readings, truth, every test's value
    // and every innovation normalized), for a single log (use FDD_FILTER).
    let mut trace = std::env::var("FDD_TRACE")
        .ok()
        .map(|p| std::io::BufWriter::new(std::fs::File::create(p).expect("trace file")));
    let mut trace_line = String::new();
    let mut seen_fault = false;
    let verbose = std::env::var("FDD_VERBOSE").is_ok();
    // The candidates of the group DTC while it is failed: a fault that becomes observable
    // meanwhile with its kind among them has a DTC from then on.
    let mut group_active: Option<Vec<(String, f64)>> = None;
    for f in IntakeSim::from_scenario(&sc).expect("sim") {
        let t_s = f.t_ns as f64 * 1e-9;
        let dt = t_s - last_t;
        last_t = t_s;
        let active: Vec<&'static str> = f.active_faults().collect();
        let free = active.is_empty();
        // Statistics are taken before any fault (after one, a healing fault's tail is not
        // nominal driving).
        let nominal = free && !seen_fault;
        if free {
            o.fault_free_s += dt;
        }
        for (slot, fo) in o.faults.iter_mut().enumerate() {
            if f.fault_observable_in(slot) {
                fo.observable_s += dt;
            }
        }
        let seg = Segment {
            speed_rpm: f.n_rpm,
            throttle_deg: f.throttle_deg,
            egr_cmd: f.egr_cmd,
            map_pa: f.map_pa,
            maf_kg_s: f.maf_kg_s,
        };
        let mut raised: Vec<Raised> = Vec::new();
        let mut group_passed = false;
        let group_passed_ref = &mut group_passed;
        let mut flagged = false;
        let flagged_ref = &mut flagged;
        let max_ratio = &mut o.max_ratio;
        let trace_line = &mut trace_line;
        trace_line.clear();
        if trace.is_some() {
            trace_line.push_str(&format!(
                "{t_s:.4},{:.1},{:.2},{:.3},{:.0},{:.6},{:.0},{}",
                f.n_rpm,
                f.throttle_deg,
                f.egr_cmd,
                f.map_pa,
                f.maf_kg_s,
                f.truth.p_m,
                u8::from(!free)
            ));
        }
        mon.process_segment(f.t_ns, &seg, &mut |out| match out {
            Output::Test { test, result }
                if trace.is_some() && !test.starts_with("intake_input") =>
            {
                trace_line.push_str(&format!(",{test}={:.4}", result.value));
                if nominal
                    && result.max > 0.0
                    && result.value.is_finite()
                    && test != "intake_isolation"
                {
                    let r = result.value / result.max;
                    let e = max_ratio.entry(test).or_insert(0.0);
                    if r > *e {
                        *e = r;
                    }
                }
            }
            Output::Innovation {
                filter,
                residual,
                variance,
                ..
            } if trace.is_some() => {
                for (r, v) in residual.iter().zip(variance) {
                    trace_line.push_str(&format!(",{filter}={:.3}", r / v.sqrt()));
                }
            }
            Output::Test { test, result }
                if nominal
                    && result.max > 0.0
                    && result.value.is_finite()
                    && !matches!(test, "intake_input_range" | "intake_isolation") =>
            {
                let r = result.value / result.max;
                let e = max_ratio.entry(test).or_insert(0.0);
                if r > *e {
                    *e = r;
                }
            }
            Output::Diagnosis { flagged, .. } => *flagged_ref = flagged,
            Output::Event(ev)
                if ev.event == GROUP_EVENT
                    && ev.bit_changed(StatusBit::TestFailed)
                    && !ev.status_after.test_failed() =>
            {
                *group_passed_ref = true;
            }
            Output::Event(ev)
                if ev.bit_changed(StatusBit::TestFailed) && ev.status_after.test_failed() =>
            {
                raised.push(Raised {
                    t_s,
                    detail: String::new(),
                    event: ev.event.to_string(),
                    candidates: ev
                        .candidates
                        .iter()
                        .map(|(n, s)| (n.to_string(), *s))
                        .collect(),
                    active: active.clone(),
                });
            }
            _ => {}
        });
        if verbose {
            for r in &mut raised {
                let fits: Vec<String> = mon
                    .ranked_hypotheses()
                    .iter()
                    .map(|f| {
                        format!(
                            "{}:{:.0}[p={:.4e} g={:.3e} o={:.3e} r={:.3e} lag={}]",
                            f.fault.name(),
                            f.glr,
                            f.parameter,
                            f.gain,
                            f.offset,
                            f.rate,
                            f.lag_s
                        )
                    })
                    .collect();
                let decided: Vec<String> = mon
                    .decisions()
                    .flatten()
                    .map(|d| format!("{d:?}"))
                    .collect();
                r.detail = format!("fits {} | decided {}", fits.join(" "), decided.join("; "));
            }
        }
        if group_passed {
            group_active = None;
        }
        for r in &raised {
            if r.event == GROUP_EVENT {
                group_active = Some(r.candidates.clone());
            }
            for fo in o.faults.iter_mut() {
                if !r.active.contains(&fo.kind) {
                    continue;
                }
                let group = r.event == GROUP_EVENT;
                if !group
                    && fo.first_specific.is_none()
                    && (specific_ok(fo.kind, &r.event)
                        || !r.active.iter().any(|k| specific_ok(k, &r.event)))
                {
                    fo.first_specific = Some(specific_ok(fo.kind, &r.event));
                }
                if group {
                    fo.group = true;
                    // The group DTC names the fault if any active fault is a candidate.
                    if !r.active.iter().any(|k| group_ok(k, &r.candidates)) {
                        fo.group_missed = true;
                    }
                    if group_ok(fo.kind, &r.candidates) {
                        fo.any_dtc_s.get_or_insert(fo.observable_s);
                    }
                } else if specific_ok(fo.kind, &r.event) {
                    fo.any_dtc_s.get_or_insert(fo.observable_s);
                    fo.correct_s.get_or_insert(fo.observable_s);
                } else if !r.active.iter().any(|k| specific_ok(k, &r.event)) {
                    fo.wrong.push(r.event.clone());
                }
            }
        }
        if let Some(c) = &group_active {
            for (slot, fo) in o.faults.iter_mut().enumerate() {
                if f.fault_observable_in(slot) && group_ok(fo.kind, c) {
                    fo.any_dtc_s.get_or_insert(fo.observable_s);
                }
            }
        }
        if free && flagged {
            if seen_fault {
                o.flagged_after_s += dt;
            } else {
                o.flagged_before_s += dt;
            }
        }
        seen_fault |= !free;
        if let Some(w) = trace.as_mut() {
            use std::io::Write;
            writeln!(w, "{trace_line}").expect("trace");
        }
        o.raised.extend(raised);
    }
    o
}

fn set_dir() -> PathBuf {
    let dir = std::env::var("FDD_SET").unwrap_or_else(|_| "fixtures/sets/intake_tuning".into());
    let p = PathBuf::from(&dir);
    if p.is_absolute() {
        p
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
    }
}

fn config() -> IntakeConfig {
    let path = std::env::var("FDD_INTAKE_CONFIG").ok().map(PathBuf::from);
    IntakeConfig::load(path.as_deref()).expect("intake config")
}

/// Runs the logs of `FDD_SET` (default the tuning set) on 2 threads and prints what they gave.
#[test]
#[ignore = "tuning tool: FDD_SET=dir cargo test --release --test intake_sets -- --ignored --nocapture"]
fn intake_set_report() {
    // RUST_LOG=fdd_monitor=debug shows the monitor's decisions, refits and healings.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_test_writer()
        .try_init();
    let dir = set_dir();
    let cfg = config();
    let filter = std::env::var("FDD_FILTER").unwrap_or_default();
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| p.to_string_lossy().contains(&filter))
        .collect();
    files.sort();
    let threads: usize = std::env::var("FDD_THREADS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2);
    let chunks: Vec<Vec<PathBuf>> = (0..threads)
        .map(|i| files.iter().skip(i).step_by(threads).cloned().collect())
        .collect();
    let mut outcomes: Vec<LogOutcome> = std::thread::scope(|s| {
        let handles: Vec<_> = chunks
            .iter()
            .map(|c| {
                let cfg = &cfg;
                s.spawn(move || c.iter().map(|p| run_log(p, cfg)).collect::<Vec<_>>())
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("thread"))
            .collect()
    });
    outcomes.sort_by(|a, b| a.name.cmp(&b.name));
    let mut worst: BTreeMap<&'static str, (f64, String)> = BTreeMap::new();
    let (mut n_faults, mut within2, mut correct, mut groups, mut group_missed) = (0, 0, 0, 0, 0);
    let mut never_observable = 0usize;
    let (mut specific, mut specific_right) = (0, 0);
    let mut free_h = 0.0;
    let mut false_dtcs = 0;
    let (mut flag_before, mut flag_after) = (0.0, 0.0);
    for o in &outcomes {
        free_h += o.fault_free_s / 3600.0;
        for (t, r) in &o.max_ratio {
            let e = worst.entry(t).or_insert((0.0, String::new()));
            if *r > e.0 {
                *e = (*r, o.name.clone());
            }
        }
        let false_here: Vec<String> = o
            .raised
            .iter()
            .filter(|r| r.active.is_empty())
            .map(|r| format!("{}@{:.1}", r.event, r.t_s))
            .collect();
        false_dtcs += false_here.len();
        let stats: Vec<String> = o
            .max_ratio
            .iter()
            .filter(|(_, r)| **r > 0.5)
            .map(|(t, r)| format!("{}={r:.2}", t.trim_start_matches("intake_")))
            .collect();
        let mut line = format!("{:40} ", o.name);
        for fo in &o.faults {
            if fo.observable_s <= 0.0 {
                // Never observable (a leak near wide-open throttle throughout): nothing to
                // detect, as `fdd evaluate` counts it.
                never_observable += 1;
                line += &format!("{} never observable | ", fo.kind);
                continue;
            }
            n_faults += 1;
            let ok2 = fo.any_dtc_s.is_some_and(|t| t <= 2.0);
            within2 += usize::from(ok2);
            correct += usize::from(fo.correct_s.is_some());
            specific += usize::from(fo.first_specific.is_some());
            specific_right += usize::from(fo.first_specific == Some(true));
            groups += usize::from(fo.group);
            group_missed += usize::from(fo.group_missed);
            line += &format!(
                "{} obs {:.1} s: DTC {} correct {}{}{}{} | ",
                fo.kind,
                fo.observable_s,
                fo.any_dtc_s.map_or("-".into(), |t| format!("{t:.2}")),
                fo.correct_s.map_or("-".into(), |t| format!("{t:.2}")),
                if fo.group { " G" } else { "" },
                if fo.group_missed { " GROUP-MISSED" } else { "" },
                if fo.wrong.is_empty() {
                    String::new()
                } else {
                    format!(" WRONG {:?}", fo.wrong)
                },
            );
            if !ok2 {
                line += "SLOW ";
            }
        }
        if !false_here.is_empty() {
            line += &format!("FALSE {false_here:?} ");
        }
        if o.flagged_before_s + o.flagged_after_s > 0.0 {
            line += &format!(
                "FLAGGED-FREE {:.1}/{:.1} s ",
                o.flagged_before_s, o.flagged_after_s
            );
        }
        flag_before += o.flagged_before_s;
        flag_after += o.flagged_after_s;
        line += &stats.join(" ");
        println!("{line}");
        if std::env::var("FDD_VERBOSE").is_ok() {
            for r in &o.raised {
                println!(
                    "    {:8.2} {} {:?} active {:?}\n             {}",
                    r.t_s, r.event, r.candidates, r.active, r.detail
                );
            }
        }
    }
    println!("\nlargest statistic / threshold per test before any fault:");
    for (t, (r, log)) in &worst {
        println!("  {t:32} {r:6.3}  ({log})");
    }
    println!(
        "\nfault-free time flagged: {flag_before:.1} s before any fault, {flag_after:.1} s after one\n{} logs, {free_h:.2} h fault-free, {false_dtcs} false DTCs; {n_faults} observable faults ({never_observable} never observable): {within2} with a DTC within 2 s observable ({:.1} %), {correct} with a correct specific DTC; first specific DTC right for {specific_right} of {specific} ({:.1} %); {groups} with a group DTC ({group_missed} lacking the truth)",
        outcomes.len(),
        100.0 * within2 as f64 / n_faults.max(1) as f64,
        100.0 * specific_right as f64 / specific.max(1) as f64,
    );
}
