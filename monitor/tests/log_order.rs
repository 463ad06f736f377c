//! The reader yields log-time order when messages were written out of order across chunks,
//! with ties in file order; the linear fallback yields file order.

mod log_common;

use fdd_monitor::log::*;
use log_common::*;
use proptest::prelude::*;

/// Writes `times` (one message each, payload = its index) with a small chunk size, and returns
/// the file and the expected (time, index) order: a stable sort by time.
fn write_times(dir: &std::path::Path, name: &str, times: &[u64]) -> std::path::PathBuf {
    let path = dir.join(name);
    let bytes = to_bytes(
        WriteOptions {
            chunk_size: 200,
            ..WriteOptions::default()
        },
        |w| {
            for (i, &t) in times.iter().enumerate() {
                // Alternate topics so chunks hold several channels.
                if i % 2 == 0 {
                    w.write_message(
                        t,
                        &TpsVoltage {
                            voltage_v: i as f64,
                        },
                    )?;
                } else {
                    w.write_message(t, &Wattmeter { power_w: i as f64 })?;
                }
            }
            Ok(())
        },
    );
    std::fs::write(&path, bytes).unwrap();
    path
}

fn read_order(path: &std::path::Path) -> (Vec<(u64, usize)>, ReadStats, ReadMode) {
    let mut r = LogReader::open(path).unwrap();
    let mut out = Vec::new();
    while let Some(m) = r.next_message() {
        let m = m.unwrap();
        let field = if m.topic == "/throttle/tps" {
            "voltage_v"
        } else {
            "power_w"
        };
        out.push((m.log_time_ns, m.field_f64(field).unwrap() as usize));
    }
    (out, r.stats(), r.mode())
}

/// Counts the `tracing` events at WARN level emitted while `f` runs on this thread.
fn count_warnings<T>(f: impl FnOnce() -> T) -> (usize, T) {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;
    use tracing::span::{Attributes, Id, Record};
    use tracing::{Event, Level, Metadata};

    struct Counter(Arc<AtomicUsize>);
    impl tracing::Subscriber for Counter {
        fn enabled(&self, _: &Metadata<'_>) -> bool {
            true
        }
        fn new_span(&self, _: &Attributes<'_>) -> Id {
            Id::from_u64(1)
        }
        fn record(&self, _: &Id, _: &Record<'_>) {}
        fn record_follows_from(&self, _: &Id, _: &Id) {}
        fn event(&self, event: &Event<'_>) {
            if *event.metadata().level() == Level::WARN {
                self.0.fetch_add(1, Ordering::SeqCst);
            }
        }
        fn enter(&self, _: &Id) {}
        fn exit(&self, _: &Id) {}
    }
    let n = Arc::new(AtomicUsize::new(0));
    let out = tracing::subscriber::with_default(Counter(n.clone()), f);
    (n.load(Ordering::SeqCst), out)
}

fn expected(times: &[u64]) -> Vec<(u64, usize)> {
    let mut v: Vec<(u64, usize)> = times.iter().copied().zip(0..).collect();
    v.sort_by_key(|&(t, _)| t); // stable: ties keep file order
    v
}

#[test]
fn late_and_interleaved_messages_come_out_sorted() {
    // A 1 kHz stream where every 7th message arrives 40 ms late and every 11th is written
    // 25 ms early: chunks overlap in time.
    let mut times = Vec::new();
    for k in 0..3_000u64 {
        let mut t = 1_000_000_000 + k * 1_000_000;
        if k % 7 == 0 {
            t -= 40_000_000;
        } else if k % 11 == 0 {
            t += 25_000_000;
        }
        times.push(t);
        if k % 13 == 0 {
            times.push(t); // duplicate timestamps: file order decides
        }
    }
    let dir = tempfile::tempdir().unwrap();
    let path = write_times(dir.path(), "late.mcap", &times);
    let (warnings, (got, stats, mode)) = count_warnings(|| read_order(&path));
    assert_eq!(warnings, 0);
    assert_eq!(mode, ReadMode::Indexed);
    assert_eq!(got, expected(&times));
    let total = stats.chunks_total.unwrap();
    assert!(total > 50, "{stats:?}");
    assert_eq!(stats.chunks_loaded, total);
    // Only the chunks that overlap in time are in memory at once.
    assert!(stats.max_resident_chunks >= 2, "{stats:?}");
    assert!(stats.max_resident_chunks < 40, "{stats:?}");
}

#[test]
fn fully_reversed_file_is_sorted() {
    let times: Vec<u64> = (0..500u64).rev().map(|k| k * 10).collect();
    let dir = tempfile::tempdir().unwrap();
    let path = write_times(dir.path(), "reversed.mcap", &times);
    let (got, _, _) = read_order(&path);
    assert_eq!(got, expected(&times));
}

#[test]
fn linear_fallback_yields_file_order_and_warns() {
    let times: Vec<u64> = (0..300u64).map(|k| (k % 10) * 1000 + k).collect();
    let dir = tempfile::tempdir().unwrap();
    let path = write_times(dir.path(), "unsorted.mcap", &times);
    // Remove the footer's end magic: the summary cannot be found.
    let bytes = std::fs::read(&path).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() - 1]).unwrap();
    let (warnings, r) = count_warnings(|| LogReader::open(&cut));
    let mut r = r.unwrap();
    assert_eq!(warnings, 1, "opening without a summary warns once");
    assert_eq!(r.mode(), ReadMode::Linear);
    let (msgs, errs) = read_lenient(&mut r);
    // The data section is complete (up to DataEnd): every message, in the order written.
    let order: Vec<u64> = msgs.iter().map(|m| m.1).collect();
    assert_eq!(order, times);
    assert!(errs.is_empty(), "{errs:?}");
    assert_eq!(r.stats().chunks_total, None);
    assert!(r.stats().max_resident_chunks <= 1);
    // The caller can see that log times go backwards.
    assert!(order.windows(2).any(|w| w[1] < w[0]));

    // Cut in the middle: a prefix in file order, then a clear error about the cut.
    let cut = dir.path().join("half.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let mut r = LogReader::open(&cut).unwrap();
    assert_eq!(r.mode(), ReadMode::Linear);
    let (msgs, errs) = read_lenient(&mut r);
    let order: Vec<u64> = msgs.iter().map(|m| m.1).collect();
    assert!(order.len() > 50 && order.len() < times.len());
    assert_eq!(order, times[..order.len()]);
    assert_eq!(errs.len(), 1);
    assert!(errs[0].is_fatal());
    assert!(matches!(errs[0], LogError::Truncated { .. }), "{}", errs[0]);
    assert!(errs[0].to_string().contains("half.mcap"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn any_write_order_reads_back_sorted(times in prop::collection::vec(0u64..2_000, 1..400)) {
        let dir = tempfile::tempdir().unwrap();
        let path = write_times(dir.path(), "p.mcap", &times);
        let (got, stats, _) = read_order(&path);
        prop_assert_eq!(got, expected(&times));
        prop_assert_eq!(stats.chunks_loaded, stats.chunks_total.unwrap());
    }
}
