//! Cost of the whole intake monitor per crank segment: the three filters (centralized EKF,
//! decentralized pair, federated filter), the residual tests, the hypothesis bank and the event
//! memory, on recorded segments of a simulated drive at three speed bands.
//!
//! `cargo bench --bench intake_monitor`. Each iteration is one `process_segment` call; the
//! segments come from the `mixed` drive profile restricted to one speed, so the filters see
//! realistic transients. The monitor starts from a cloned, warmed-up state each sample.

use divan::Bencher;
use fdd_fixtures::intake_profile::{MixedSpec, ProfileSpec};
use fdd_fixtures::intake_sim::{default_intake_model, IntakeFault, IntakeScenario, IntakeSim};
use fdd_monitor::intake::{IntakeMonitor, IntakeMonitorConfig, Segment};
use fdd_monitor::monitor::Monitor;
use fdd_monitor::signal_table::SignalTable;

fn main() {
    divan::main();
}

fn table() -> SignalTable {
    // One segment of 100 ms at the slowest speed the model accepts; 250 ms is lost.
    SignalTable::with_names(&IntakeMonitorConfig::default().signal_names(), 250_000_000)
        .expect("table")
}

/// Segments of a drive whose speed stays near `speed` rpm (+-10 %).
fn segments(speed: f64) -> Vec<(u64, Segment)> {
    let spec = ProfileSpec::Mixed(MixedSpec {
        speed_rpm: [speed * 0.9, speed * 1.1],
        ..MixedSpec::default()
    });
    let sc = IntakeScenario::new("bench", 20.0, 7, spec, IntakeFault::None);
    IntakeSim::from_scenario(&sc)
        .expect("scenario")
        .map(|f| {
            (
                f.t_ns,
                Segment {
                    speed_rpm: f.n_rpm,
                    throttle_deg: f.throttle_deg,
                    egr_cmd: f.egr_cmd,
                    map_pa: f.map_pa,
                    maf_kg_s: f.maf_kg_s,
                },
            )
        })
        .collect()
}

#[divan::bench(args = [800, 3000, 6000], sample_count = 200, sample_size = 64)]
fn intake_monitor_segment(bencher: Bencher, speed: u32) {
    let segs = segments(f64::from(speed));
    let mut mon = IntakeMonitor::new(
        &default_intake_model(),
        &IntakeMonitorConfig::default(),
        &table(),
    )
    .expect("monitor");
    mon.start_operation_cycle(0, &mut |_| {});
    // Warm up over the first half; time the second half, cycling through it.
    let half = segs.len() / 2;
    for (t, s) in &segs[..half] {
        mon.process_segment(*t, s, &mut |_| {});
    }
    let timed = &segs[half..];
    let mut k = 0;
    bencher.bench_local(|| {
        let (t, s) = &timed[k % timed.len()];
        k += 1;
        let mut sink = |o: fdd_monitor::monitor::Output<'_>| {
            divan::black_box(o);
        };
        mon.process_segment(*t + k as u64, divan::black_box(s), &mut sink);
    });
}

/// The one-off cost of opening an isolation episode with the longest look-back the monitor
/// allows: 256 recorded segments refitted into the onset scan's 16 banks.
#[divan::bench(sample_count = 200, sample_size = 16)]
fn intake_alarm_refit_256_segments(bencher: Bencher) {
    use fdd_monitor::intake::{OnsetScan, SegmentRecord};
    let records: Vec<SegmentRecord> = (0..256)
        .map(|k| SegmentRecord {
            z_p: (k as f64 * 0.37).sin() * 3.0,
            s_p: 800.0,
            z_w: (k as f64 * 0.11).cos(),
            s_w: 3e-4,
            map_flow_gain: -2e-8,
            decay: 0.85,
            input_gain: 3.5e5,
            maf: 0.02,
            egr_full: 0.011,
            egr_cmd: if k % 50 < 25 { 0.0 } else { 0.3 },
            leak_unit: 240.0,
            p_ref: 50_000.0,
            dt: 0.02,
        })
        .collect();
    bencher.bench_local(|| {
        let mut scan = OnsetScan::new(0, 255);
        for (k, r) in records.iter().enumerate() {
            scan.push(k as u64, divan::black_box(r));
        }
        divan::black_box(scan.ranked())
    });
}
