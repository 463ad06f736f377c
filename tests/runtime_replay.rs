//! `fdd replay` on the runtime (`fdd_monitor::Runtime`):
//!
//! - every committed fixture gives exactly the DTC status changes the replay gave before the
//!   runtime took it over (`tests/data/replay_events.txt`, recorded from that replay: times,
//!   events, DTCs, triggers, status bytes and memory actions);
//! - a disabled monitor and a truncated log raise no false "no signal" DTC;
//! - the runtime's ring-buffer ingestion counts lost samples exactly and raises the queue's
//!   event with the count; samples pushed from several threads at once are each processed in
//!   order or counted as lost.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use fdd::replay::{replay, ReplayOptions, RuntimeConfig};
use fdd_monitor::monitor::Output;
use fdd_monitor::runtime::{Runtime, Stamped};

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/data")
}

/// `fixture -> lines "time_s event dtc trigger before after memory"` of the recorded file.
fn recorded() -> BTreeMap<String, Vec<String>> {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/replay_events.txt"),
    )
    .expect("tests/data/replay_events.txt");
    let mut m: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for line in text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let (fixture, rest) = line.split_once(' ').expect("fixture name first");
        m.entry(fixture.to_string())
            .or_default()
            .push(rest.to_string());
    }
    m
}

/// The same line for each event the replay writes to `--events` now.
fn replayed(log: &Path, cfg: &RuntimeConfig) -> Vec<String> {
    let dir = tempfile::tempdir().expect("tempdir");
    let events = dir.path().join("events.jsonl");
    let opts = ReplayOptions {
        events: Some(events.clone()),
        ..ReplayOptions::default()
    };
    replay(log, cfg, &opts).expect("replay runs");
    std::fs::read_to_string(&events)
        .expect("events file")
        .lines()
        .map(|l| {
            let e: serde_json::Value = serde_json::from_str(l).expect("event JSON");
            // The number as written (serde_json's default float parser is not always
            // correctly rounded, so it is compared as text).
            let time = l
                .strip_prefix("{\"time_s\":")
                .and_then(|r| r.split_once(','))
                .map(|(t, _)| t)
                .expect("time_s first");
            format!(
                "{} {} {} {} {} {} {}",
                python_repr(time.parse().expect("time_s")),
                e["event"].as_str().expect("event"),
                e["dtc"].as_str().expect("dtc"),
                e["trigger"].as_str().expect("trigger"),
                e["status_before"],
                e["status_after"],
                e["memory"].as_str().expect("memory"),
            )
        })
        .collect()
}

/// Python's `repr` of a float, as the recording script wrote it (shortest round trip, `.0` for
/// integral values). Rust's `str::parse` is correctly rounded, so the text round-trips.
fn python_repr(x: f64) -> String {
    let s = format!("{x:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

#[test]
fn every_fixture_replays_to_the_recorded_events() {
    let cfg = RuntimeConfig::load(None).expect("embedded config");
    let recorded = recorded();
    let mut names: Vec<String> = std::fs::read_dir(fixtures())
        .expect("fixtures/data")
        .filter_map(|e| {
            let p = e.ok()?.path();
            let stem = p.file_stem()?.to_string_lossy().into_owned();
            (p.extension()? == "mcap").then_some(stem)
        })
        .collect();
    names.sort();
    assert_eq!(
        names,
        recorded.keys().cloned().collect::<Vec<_>>(),
        "every fixture has a recording and every recording a fixture"
    );
    // `FDD_BLESS=1 cargo test --release --test runtime_replay` rewrites the recording after a
    // deliberate change of behaviour (review its diff before committing).
    if std::env::var_os("FDD_BLESS").is_some() {
        let mut text = String::from(
            "# DTC status changes of `fdd replay` on every fixture; tests/runtime_replay.rs checks\n\
             # they are unchanged (FDD_BLESS=1 rewrites this file after a deliberate change).\n\
             # fixture time_s event dtc trigger status_before status_after memory\n",
        );
        for name in &names {
            for line in replayed(&fixtures().join(format!("{name}.mcap")), &cfg) {
                text.push_str(&format!("{name} {line}\n"));
            }
        }
        std::fs::write(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/replay_events.txt"),
            text,
        )
        .expect("write tests/data/replay_events.txt");
        return;
    }
    let mut total = 0;
    for name in &names {
        let got = replayed(&fixtures().join(format!("{name}.mcap")), &cfg);
        let want = &recorded[name];
        assert_eq!(&got, want, "{name}: events differ from the recording");
        total += got.len();
    }
    assert!(total >= 200, "{total} events over {} fixtures", names.len());
}

/// DTCs raised (testFailed 0 -> 1) by a replay.
fn raised(log: &Path, cfg: &RuntimeConfig) -> Vec<String> {
    replay(log, cfg, &ReplayOptions::default())
        .expect("replay runs")
        .dtcs
        .iter()
        .filter(|d| d.raised > 0)
        .map(|d| d.dtc.to_string())
        .collect()
}

#[test]
fn a_disabled_monitor_raises_no_no_signal_dtc() {
    let text = fdd::replay::config::DEFAULT_RUNTIME_TOML.replace("intake = true", "intake = false");
    let cfg = RuntimeConfig::parse(&text, "no-intake.toml").expect("valid");
    let got = raised(&fixtures().join("throttle_tps_open.mcap"), &cfg);
    assert_eq!(got, ["P0122-16", "P2106-00"], "{got:?}");
    // The intake monitor disabled on an intake log: nothing watches its signals. (The
    // throttle monitor runs, since the log has no topic of any enabled monitor, which looks
    // like a mapping error, and reports its own signals missing.)
    let got = raised(&fixtures().join("intake_leak.mcap"), &cfg);
    let intake = ["P0335-31", "P0220-31", "P0403-31", "P0105-31", "P0100-31"];
    assert!(got.iter().all(|d| !intake.contains(&d.as_str())), "{got:?}");
    assert_eq!(got, ["P2100-31", "P0120-31", "P1650-31"], "{got:?}");
}

#[test]
fn a_truncated_log_raises_no_false_no_signal_dtc() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = std::fs::read(fixtures().join("throttle_tps_open.mcap")).expect("fixture");
    let cut = dir.path().join("truncated.mcap");
    std::fs::write(&cut, &src[..src.len() * 2 / 3]).expect("write");
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let summary = replay(&cut, &cfg, &ReplayOptions::default()).expect("replays what it can");
    assert!(summary.stopped_early.is_some() || summary.messages > 0);
    let names: Vec<&str> = summary.monitors.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["staleness", "throttle"], "{names:?}");
    let no_signal: Vec<String> = summary
        .dtcs
        .iter()
        .filter(|d| d.raised > 0 && d.dtc.ftb == 0x31)
        .map(|d| d.dtc.to_string())
        .collect();
    assert!(no_signal.is_empty(), "false no-signal DTCs: {no_signal:?}");
}

/// Counts of what a sink saw.
#[derive(Default)]
struct Seen {
    raised: Vec<(String, f64)>,
}

#[test]
fn a_full_queue_counts_its_losses_and_raises_the_event_with_the_count() {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (mut rt, mut producers) = Runtime::builder(cfg)
        .only_monitors(&["throttle"])
        .queue("adc", 64, "P1680-00")
        .build()
        .expect("runtime");
    let tps = rt.signal("tps").expect("tps");
    let mut seen = Seen::default();
    let mut sink = |o: Stamped<'_>| {
        if let Output::Event(e) = o.output {
            if e.raised() && e.event == "adc_samples_lost" {
                let v = e.test_result.map_or(f64::NAN, |r| r.value);
                seen.raised.push((e.dtc.to_string(), v));
            }
        }
    };
    rt.start_operation_cycle(0, &mut sink).expect("cycle");
    let p = &mut producers[0];
    let mut accepted = 0;
    for k in 0..100u64 {
        if p.push(tps, k * 1_000, 1.0 + k as f64 * 1e-3) {
            accepted += 1;
        }
    }
    assert_eq!(accepted, 64);
    assert_eq!(p.lost(), 36);
    rt.advance_to(20_000_000, &mut sink).expect("advance");
    assert_eq!(seen.raised, [("P1680-00".to_string(), 36.0)]);
    let st = &rt.queue_stats()[0];
    assert_eq!(
        (st.pushed, st.lost, st.applied, st.rejected),
        (64, 36, 64, 0)
    );
}

#[test]
fn samples_from_several_threads_are_processed_in_order_or_counted_lost() {
    let cfg = RuntimeConfig::load(None).expect("embedded");
    let (mut rt, producers) = Runtime::builder(cfg)
        .only_monitors(&["throttle"])
        .queue("can", 256, "P1680-00")
        .queue("adc", 256, "P1681-00")
        .queue("power", 256, "P1682-00")
        .build()
        .expect("runtime");
    let signals = ["motor_voltage", "tps", "wattmeter"].map(|n| rt.signal(n).expect("signal"));
    const N: u64 = 20_000;
    let handles: Vec<_> = producers
        .into_iter()
        .zip(signals)
        .map(|(mut p, id)| {
            std::thread::spawn(move || {
                let mut ok = 0u64;
                for k in 0..N {
                    // 1 kHz; the values encode the time so order can be checked.
                    if p.push(id, k * 1_000_000, k as f64) {
                        ok += 1;
                    }
                    if k % 512 == 0 {
                        std::thread::yield_now();
                    }
                }
                (ok, p.lost())
            })
        })
        .collect();
    // The consumer advances while the producers push; every step checks that the table holds
    // values no newer than the step (queued samples are applied in time order).
    let mut sink = |_: Stamped<'_>| {};
    rt.start_operation_cycle(0, &mut sink).expect("cycle");
    let mut t = 0u64;
    let mut last_seen = [f64::NEG_INFINITY; 3];
    while handles.iter().any(|h| !h.is_finished()) || t < N * 1_000_000 {
        if t >= N * 1_000_000 {
            std::thread::yield_now();
            continue;
        }
        t += 5_000_000;
        rt.advance_to(t, &mut sink).expect("advance");
        for (k, &id) in signals.iter().enumerate() {
            if let Some(s) = rt.signals().get(id) {
                assert!(s.t_ns <= t, "a sample from the future was applied");
                assert!(s.value >= last_seen[k], "signal {k} went back in time");
                assert_eq!(
                    s.value,
                    (s.t_ns / 1_000_000) as f64,
                    "value and time disagree"
                );
                last_seen[k] = s.value;
            }
        }
    }
    let pushed: Vec<(u64, u64)> = handles
        .into_iter()
        .map(|h| h.join().expect("producer"))
        .collect();
    rt.advance_to(t + 1, &mut sink).expect("drain");
    for (k, st) in rt.queue_stats().iter().enumerate() {
        let (ok, lost) = pushed[k];
        assert_eq!(ok + lost, N, "{st:?}");
        assert_eq!(st.pushed, ok);
        assert_eq!(st.lost, lost);
        // Every accepted sample was applied (time increases per queue) and none refused.
        assert_eq!(st.applied, ok, "{st:?}");
        assert_eq!(st.rejected, 0, "{st:?}");
    }
}
