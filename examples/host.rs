//! A host program embedding fdd: the loop a vehicle monitoring task runs, fed here from a
//! recorded log instead of a bus.
//!
//! ```sh
//! cargo run --release --example host -- fixtures/data/throttle_tps_open.mcap
//! cargo run --release --example host -- fixtures/data/intake_leak.mcap intake
//! ```
//!
//! The second argument names the monitors the vehicle has (default `throttle`; comma-separated),
//! so the "no signal" monitor watches only their signals.
//!
//! It builds the runtime from the embedded default configuration, resolves the signals once,
//! then per 1 ms frame pushes the samples, advances the runtime's time and drains the event
//! queue; at the end it reads the DTC memory by status mask (UDS 0x19 0x02), prints the freeze
//! frame and extended data of each DTC, clears them (UDS 0x14) and starts the next operation
//! cycle, as after a workshop visit.

use std::process::ExitCode;

use fdd_diagnostics::dtc::DtcGroup;
use fdd_monitor::log::LogReader;
use fdd_monitor::runtime::{EventQueue, Runtime, RuntimeConfig};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "fixtures/data/throttle_tps_open.mcap".into());
    let monitors = std::env::args().nth(2).unwrap_or_else(|| "throttle".into());
    let monitors: Vec<&str> = monitors.split(',').collect();
    let cfg = RuntimeConfig::embedded()?;
    let (mut rt, _) = Runtime::builder(cfg.clone())
        .only_monitors(&monitors)
        .build()?;
    // Resolve each mapped topic to its signal once.
    let mapping: Vec<_> = cfg
        .signals
        .iter()
        .filter_map(|s| Some((s.topic.clone(), s.field.clone(), rt.signal(&s.name)?)))
        .collect();
    let mut events = EventQueue::new(64);
    let mut reader = LogReader::open(std::path::Path::new(&path))?;

    let mut started = false;
    let mut frame_ns = None;
    let mut last_ns = 0;
    while let Some(msg) = reader.next_message() {
        let msg = msg?;
        let t = msg.log_time_ns;
        if !started {
            rt.start_operation_cycle(t, &mut events)?; // ignition on
            started = true;
        }
        if frame_ns != Some(t) {
            // A new frame: every step due before it runs on the samples so far.
            if let Some(prev) = frame_ns {
                rt.advance_to(t.max(prev + 1) - 1, &mut events)?;
            }
            frame_ns = Some(t);
        }
        for (topic, field, id) in &mapping {
            if topic == msg.topic {
                if let Ok(v) = msg.field_f64(field) {
                    // A refused sample (NaN, time not increasing) is the host's to count.
                    let _ = rt.push(*id, t, v);
                }
            }
        }
        last_ns = t;
        while let Some(e) = events.pop() {
            if e.raised() {
                let (name, monitor) = rt.event_name(e.dtc).unwrap_or(("?", "?"));
                println!(
                    "{:>10.3} s  {}  {:<24} status 0x{:02X}  ({monitor})",
                    e.time_s,
                    e.dtc,
                    name,
                    e.status_after.byte()
                );
            }
        }
    }
    rt.advance_to(last_ns, &mut events)?;
    if let Some(p) = events.estimate("throttle_angle") {
        println!(
            "throttle position {:.1} deg [{:.1}, {:.1}] from {}",
            p.value, p.lower, p.upper, p.source
        );
    }

    // The workshop tester: DTCs with testFailedThisOperationCycle or pendingDTC (mask 0x06).
    println!("DTCs by status mask 0x06:");
    for (dtc, status) in rt.dtcs_by_status_mask(0x06) {
        let ext = rt.extended_data(dtc);
        println!(
            "  {dtc}  0x{:02X}  occurrences {}",
            status.byte(),
            ext.map_or(0, |x| x.occurrence_counter)
        );
        if let Some(entry) = rt.freeze_frame(dtc) {
            let frame: Vec<String> = entry
                .freeze_frame()
                .map(|(s, v)| format!("{s}={v:.4}"))
                .collect();
            println!("    freeze frame: {}", frame.join(" "));
        }
    }
    let end = last_ns + 1;
    rt.end_operation_cycle(end, &mut events)?; // ignition off
    let cleared = rt.clear_dtc(DtcGroup::All, end, &mut events)?;
    println!("cleared {cleared} DTCs");
    rt.start_operation_cycle(end + 1, &mut events)?; // the next drive
    let left = rt.dtcs_by_status_mask(0x2F).count();
    println!("DTCs with any failure bit after the clear: {left}");
    Ok(())
}
