//! SIGKILL harness for the slot store: a writer process is killed at random moments while it
//! runs operation cycles and persists its event memory; after every kill the store must give
//! back the last acknowledged write (or the one after it, if the kill landed between the end
//! of that write and its acknowledgement), never nothing once a write was acknowledged.
//!
//! The writer is this test binary itself, re-executed with `--exact sigkill_writer_child` and
//! [`CHILD_DIR_ENV`] naming the store's directory. It restores its memory from the store (so
//! the state carries over from kill to kill, on a clock that restarts at 0 each time), then
//! loops: operation cycles in which events fail at random (DTCs get confirmed over cycles),
//! ClearDTC now and then, and a persist (image -> sections -> slot write) at each cycle end, at
//! each confirmation and at each clear. Around each write it prints, flushing each line,
//!
//! ```text
//! @fdd pending <seq> <payload hash> <confirmed DTCs>    before the write starts
//! @fdd ack <seq> <slot> <payload hash> <confirmed DTCs> after the write returned
//! ```
//!
//! The parent kills it with SIGKILL after a random delay (seeded; 10 % right after the start,
//! the others uniform in 0..40 ms), reads the lines, opens the store and checks the recovered
//! payload byte for byte (through its hash) against the last `ack` or the `pending` after it,
//! then decodes and restores it. `FDD_SIGKILL_TRIALS` overrides the 1000 trials.
//!
//! A SIGKILL stops the process, not the machine: the page cache survives, so this checks the
//! write protocol (target slot, sequence numbers, fallback on a torn slot), not the device's
//! behaviour on power loss, which the fsync ordering addresses.

use std::collections::BTreeSet;
use std::env;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::ExitStatusExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use fdd_diagnostics::dtc::{
    DebounceConfig, DtcGroup, DtcStatus, EventConfig, EventMemory, EventMemoryConfig, MemoryImage,
    ReportContext,
};
use fdd_diagnostics::event::DiagnosticEvent;
use fdd_diagnostics::{TestResult, Verdict};
use fdd_monitor::persist::{unpack_sections, SectionWriter, SlotId, SlotProblem, SlotStore};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// Set in the child: the store's directory.
const CHILD_DIR_ENV: &str = "FDD_SIGKILL_CHILD_DIR";
/// Set in the child: its RNG seed.
const CHILD_SEED_ENV: &str = "FDD_SIGKILL_CHILD_SEED";
const CHILD_TEST: &str = "sigkill_writer_child";
/// Starts every line the writer prints for the parent.
const MARK: &str = "@fdd ";
const TRIALS_ENV: &str = "FDD_SIGKILL_TRIALS";
const SECTION: &str = "sigkill";
const CONFIG_HASH: u64 = 0x00C0_FFEE;
/// A child that was not killed stops by itself after this long.
const CHILD_MAX_RUN: Duration = Duration::from_secs(10);

fn config() -> EventMemoryConfig {
    let ev = |name: &str, dtc: &str, priority: u8, ff: &[&str]| {
        let mut e = EventConfig::new(name, dtc, priority);
        e.debounce = DebounceConfig::MonitorInternal;
        e.aging_threshold = 4;
        e.freeze_frame = ff.iter().map(|s| s.to_string()).collect();
        e
    };
    // Capacity 4 for 6 events: displacement and overflow happen too.
    EventMemoryConfig {
        capacity: 4,
        events: vec![
            ev("map_perf", "P0106-64", 2, &["map_kpa", "rpm"]),
            ev("egr_low", "P0401-00", 3, &["egr_pos", "map_kpa"]),
            ev("leak", "P2279-7A", 3, &["map_kpa", "maf_gps", "rpm"]),
            ev("tps_high", "P0123-1C", 1, &["tps_v"]),
            ev("boost_low", "P0299-00", 4, &[]),
            ev("wss_lf", "C0035-00", 5, &["v_kph"]),
        ],
    }
}

/// Chance per operation cycle that an event's fault is present.
const FAULT_CHANCE: [f64; 6] = [0.6, 0.4, 0.3, 0.2, 0.5, 0.1];

fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x100_0000_01b3)
    })
}

fn dtc_list(dtcs: impl Iterator<Item = String>) -> String {
    let v: Vec<String> = dtcs.collect();
    if v.is_empty() {
        "-".into()
    } else {
        v.join(",")
    }
}

// ------------------------------------------------------------------------------ the writer

/// The writer: only active in the child process (with [`CHILD_DIR_ENV`] set); a no-op test
/// otherwise.
#[test]
fn sigkill_writer_child() {
    let Ok(dir) = env::var(CHILD_DIR_ENV) else {
        return;
    };
    let seed: u64 = env::var(CHILD_SEED_ENV)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    writer(Path::new(&dir), seed);
}

fn writer(dir: &Path, seed: u64) {
    let started = Instant::now();
    let (mut store, rec) = SlotStore::open(dir.join("dtc"), CONFIG_HASH).expect("open the store");
    let mut mem = EventMemory::new(&config()).expect("valid config");
    if let Some(payload) = rec.payload() {
        let sections = unpack_sections(payload).expect("sections");
        let image = MemoryImage::decode(sections[0].1).expect("decodable image");
        let report = mem.restore(&image);
        assert!(report.nothing_dropped(), "{report:?}");
    }
    let ids: Vec<_> = mem.event_ids().collect();
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut payload = Vec::with_capacity(4096);
    let mut stdout = std::io::stdout().lock();
    let mut persist = |mem: &EventMemory, store: &mut SlotStore| -> bool {
        payload.clear();
        let mut w = SectionWriter::new(&mut payload);
        w.section(SECTION, |b| mem.encode_image(b)).expect("fits");
        w.finish();
        let dtcs = dtc_list(
            mem.dtcs_by_status_mask(DtcStatus::CDTC)
                .map(|(d, _)| d.to_string()),
        );
        let seq = store.next_seq();
        let h = fnv(&payload);
        if writeln!(stdout, "{MARK}pending {seq} {h:016x} {dtcs}")
            .and_then(|_| stdout.flush())
            .is_err()
        {
            return false; // the parent is gone
        }
        let w = store.write(&payload).expect("slot write");
        assert_eq!(w.seq, seq);
        writeln!(stdout, "{MARK}ack {seq} {} {h:016x} {dtcs}", w.slot)
            .and_then(|_| stdout.flush())
            .is_ok()
    };

    // The host clock restarts at 0 at every power-up; 10 ms per report.
    let mut t = 0.0;
    let failed = TestResult {
        value: 9.0,
        min: 0.0,
        max: 5.0,
        verdict: Verdict::Failed,
    };
    let passed = TestResult {
        verdict: Verdict::Passed,
        ..failed
    };
    while started.elapsed() < CHILD_MAX_RUN {
        mem.start_operation_cycle(t, |_| {}).expect("cycle start");
        let faulty: Vec<bool> = FAULT_CHANCE.iter().map(|&p| rng.random_bool(p)).collect();
        let mut confirmed = false;
        for _ in 0..3 {
            for (j, &id) in ids.iter().enumerate() {
                t += 0.01;
                let ff: Vec<f64> = (0..config().events[j].freeze_frame.len())
                    .map(|_| rng.random_range(0.0..5000.0))
                    .collect();
                let ctx = ReportContext::at(t).with_freeze_frame(&ff);
                let r = if faulty[j] { &failed } else { &passed };
                mem.report(id, r, &ctx, |e: DiagnosticEvent| {
                    confirmed |= !e.status_before.confirmed() && e.status_after.confirmed();
                })
                .expect("report");
            }
        }
        if confirmed && !persist(&mem, &mut store) {
            return;
        }
        if rng.random_range(0..8) == 0 {
            let group = if rng.random_range(0..5) == 0 {
                DtcGroup::All
            } else {
                DtcGroup::Dtc(mem.dtc(ids[rng.random_range(0..ids.len())]))
            };
            mem.clear_dtc(group, t, |_| {}).expect("clear");
            if !persist(&mem, &mut store) {
                return;
            }
        }
        t += 0.1;
        mem.end_operation_cycle(t, |_| {}).expect("cycle end");
        if !persist(&mem, &mut store) {
            return;
        }
    }
}

// ------------------------------------------------------------------------------ the parent

#[derive(Debug, Clone, PartialEq)]
struct Line {
    seq: u64,
    hash: u64,
    dtcs: String,
}

fn parse(line: &str) -> Option<(bool, Line)> {
    // libtest may have printed "test sigkill_writer_child ... " on the same line.
    let line = &line[line.find(MARK)? + MARK.len()..];
    let mut it = line.split_whitespace();
    let ack = match it.next()? {
        "ack" => true,
        "pending" => false,
        _ => return None,
    };
    let seq = it.next()?.parse().ok()?;
    if ack {
        it.next()?; // slot
    }
    let hash = u64::from_str_radix(it.next()?, 16).ok()?;
    let dtcs = it.next()?.to_string();
    Some((ack, Line { seq, hash, dtcs }))
}

#[derive(Debug, Default)]
struct Figures {
    trials: usize,
    killed_before_first_write_started: usize,
    killed_before_first_ack: usize,
    writes_acked: usize,
    restored_from: [usize; 2],
    first_starts: usize,
    restored_last_ack: usize,
    restored_one_newer: usize,
    in_flight_write_lost: usize,
    fallbacks_over_damaged_slot: usize,
    damaged: [usize; 3],
}

#[test]
fn sigkill_during_writes_never_loses_an_acknowledged_write() {
    if env::var(CHILD_DIR_ENV).is_ok() {
        return; // in the child
    }
    let trials: usize = env::var(TRIALS_ENV)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let exe = env::current_exe().expect("test binary path");
    let tmp = tempfile::tempdir().expect("temp dir");
    let mut rng = Pcg64::seed_from_u64(0x5157_4B11);
    let started = Instant::now();
    let mut f = Figures::default();
    // What the store holds before the trial (None: nothing yet).
    let mut baseline: Option<Line> = None;

    for trial in 0..trials {
        let delay = if rng.random_bool(0.1) {
            Duration::ZERO
        } else {
            Duration::from_micros(rng.random_range(0..40_000))
        };
        let mut child = Command::new(&exe)
            .args(["--exact", CHILD_TEST, "--nocapture", "--test-threads=1"])
            .env(CHILD_DIR_ENV, tmp.path())
            .env(CHILD_SEED_ENV, trial.to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn the writer");
        let stdout = child.stdout.take().expect("piped stdout");
        let reader = thread::spawn(move || {
            BufReader::new(stdout)
                .lines()
                .map_while(Result::ok)
                .collect::<Vec<String>>()
        });
        thread::sleep(delay);
        child.kill().expect("SIGKILL");
        let status = child.wait().expect("wait");
        let lines = reader.join().expect("reader thread");
        let mut stderr = String::new();
        if let Some(mut e) = child.stderr.take() {
            let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
        }
        assert_eq!(
            status.signal(),
            Some(9),
            "trial {trial}: the writer ended by itself ({status}): {stderr}"
        );

        let mut acks: Vec<Line> = Vec::new();
        let mut pending: Option<Line> = None;
        for (ack, l) in lines.iter().filter_map(|s| parse(s)) {
            if ack {
                let p = pending.take().expect("ack after pending");
                assert_eq!(p, l, "trial {trial}: ack matches its pending line");
                let prev = acks.last().or(baseline.as_ref()).map_or(0, |b| b.seq);
                assert_eq!(
                    l.seq,
                    prev + 1,
                    "trial {trial}: consecutive sequence numbers"
                );
                acks.push(l);
            } else {
                assert!(pending.is_none());
                pending = Some(l);
            }
        }
        f.trials += 1;
        f.writes_acked += acks.len();
        if acks.is_empty() {
            f.killed_before_first_ack += 1;
            if pending.is_none() {
                f.killed_before_first_write_started += 1;
            }
        }
        let last_ack = acks.last().cloned().or(baseline.clone());

        // Power-up: open, check against what was acknowledged, decode and restore.
        let (_, rec) = SlotStore::open(tmp.path().join("dtc"), CONFIG_HASH).expect("open");
        for n in &rec.notes {
            match n.problem {
                SlotProblem::Missing => f.damaged[0] += 1,
                SlotProblem::Short { .. } => f.damaged[1] += 1,
                _ => f.damaged[2] += 1,
            }
        }
        let Some(cur) = rec.current.as_ref() else {
            assert!(
                last_ack.is_none(),
                "trial {trial}: nothing recovered after write {last_ack:?} was acknowledged; notes {:?}",
                rec.notes
            );
            f.first_starts += 1;
            continue;
        };
        assert!(cur.config_matches);
        let got = Line {
            seq: cur.seq,
            hash: fnv(&cur.payload),
            dtcs: String::new(),
        };
        let expected = if last_ack.as_ref().is_some_and(|a| a.seq == got.seq) {
            f.restored_last_ack += 1;
            if pending.is_some() {
                f.in_flight_write_lost += 1;
                if rec.notes.iter().any(|n| n.problem != SlotProblem::Missing) {
                    f.fallbacks_over_damaged_slot += 1;
                }
            }
            last_ack.clone().expect("checked")
        } else if pending.as_ref().is_some_and(|p| p.seq == got.seq) {
            f.restored_one_newer += 1;
            pending.clone().expect("checked")
        } else {
            panic!(
                "trial {trial}: recovered seq {} but the last ack is {last_ack:?} and the write in flight {pending:?}",
                got.seq
            );
        };
        assert_eq!(
            got.hash, expected.hash,
            "trial {trial}: seq {} payload differs from what was written",
            got.seq
        );
        f.restored_from[match cur.slot {
            SlotId::A => 0,
            SlotId::B => 1,
        }] += 1;

        let sections = unpack_sections(&cur.payload).expect("sections");
        let image = MemoryImage::decode(sections[0].1).expect("image decodes");
        let mut mem = EventMemory::new(&config()).expect("config");
        let report = mem.restore(&image);
        assert!(report.nothing_dropped(), "trial {trial}: {report:?}");
        let restored: BTreeSet<String> = mem
            .dtcs_by_status_mask(DtcStatus::CDTC)
            .map(|(d, _)| d.to_string())
            .collect();
        let wanted: BTreeSet<String> = expected
            .dtcs
            .split(',')
            .filter(|s| *s != "-")
            .map(str::to_string)
            .collect();
        assert_eq!(restored, wanted, "trial {trial}: confirmed DTCs");
        if let Some(a) = &last_ack {
            if a.seq == got.seq {
                let acked: BTreeSet<String> = a
                    .dtcs
                    .split(',')
                    .filter(|s| *s != "-")
                    .map(str::to_string)
                    .collect();
                assert!(restored.is_superset(&acked));
            }
        }
        baseline = Some(expected);
    }

    let secs = started.elapsed().as_secs_f64();
    println!("persist_sigkill: {} trials in {secs:.1} s", f.trials);
    println!(
        "  writes acknowledged: {} ({:.1} per trial); last seq {}",
        f.writes_acked,
        f.writes_acked as f64 / f.trials as f64,
        baseline.as_ref().map_or(0, |b| b.seq)
    );
    println!(
        "  killed before the first write was acknowledged: {} (before it started: {})",
        f.killed_before_first_ack, f.killed_before_first_write_started
    );
    println!(
        "  restored from A: {}, from B: {}, first start (nothing written yet): {}",
        f.restored_from[0], f.restored_from[1], f.first_starts
    );
    println!(
        "  restored the last acknowledged write: {}; one write newer (killed after the slot was written, before its ack): {}",
        f.restored_last_ack, f.restored_one_newer
    );
    println!(
        "  write in flight lost: {}, of which fell back over a damaged slot: {}",
        f.in_flight_write_lost, f.fallbacks_over_damaged_slot
    );
    println!(
        "  slot notes at restore: missing {}, short (torn at truncate) {}, other damage {}",
        f.damaged[0], f.damaged[1], f.damaged[2]
    );
    assert_eq!(
        f.restored_from[0] + f.restored_from[1] + f.first_starts,
        f.trials
    );
}
