//! Streaming a million messages: the reader loads one chunk at a time (lazily, never the whole
//! file) and is fast; the writer flushes chunks as it goes. Prints the measured throughput.
//!
//! One test in its own binary, so the memory figures are not disturbed by other tests.

mod log_common;

use std::time::Instant;

use fdd_monitor::log::*;

const SAMPLES: u64 = 333_334; // x 3 topics = 1,000,002 messages

/// Resident set size of this process, bytes (Linux; `None` elsewhere).
fn rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[test]
fn a_million_messages_stream_in_bounded_memory() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("million.mcap");

    // Write: chunks go to the file as they fill, so memory does not grow with the log.
    let rss_start = rss_bytes();
    let t = Instant::now();
    let mut w = LogWriter::create(&path).unwrap();
    log_common::write_inputs(&mut w, SAMPLES).unwrap();
    let n = w.messages_written();
    let rss_written = rss_bytes();
    w.finish().unwrap();
    let write_s = t.elapsed().as_secs_f64();
    let size = std::fs::metadata(&path).unwrap().len();
    assert_eq!(n, 3 * SAMPLES);

    // Read lazily: opening reads no chunk; the first message loads exactly one.
    let rss_before = rss_bytes();
    let t = Instant::now();
    let mut r = LogReader::open(&path).unwrap();
    assert_eq!(r.mode(), ReadMode::Indexed);
    assert_eq!(r.message_count(), Some(n));
    let chunks = r.stats().chunks_total.unwrap();
    assert!(chunks > 10, "{chunks} chunks");
    assert_eq!(r.stats().chunks_loaded, 0);
    {
        let first = r.next_message().unwrap().unwrap();
        assert_eq!(first.log_time_ns, 0);
    }
    assert_eq!(r.stats().chunks_loaded, 1);
    assert_eq!(r.stats().resident_chunks, 1);

    let mut count = 1u64;
    let mut last = 0u64;
    let mut rss_mid = None;
    let mut checksum = 0usize;
    while let Some(m) = r.next_message() {
        let m = m.unwrap();
        assert!(m.log_time_ns >= last);
        last = m.log_time_ns;
        checksum = checksum.wrapping_add(m.data.len());
        count += 1;
        if count == n / 2 {
            rss_mid = rss_bytes();
            let s = r.stats();
            assert!(s.chunks_loaded < chunks, "{s:?}");
        }
    }
    let read_s = t.elapsed().as_secs_f64();
    assert_eq!(count, n);
    let stats = r.stats();
    assert_eq!(stats.chunks_loaded, chunks);
    assert!(stats.max_resident_chunks <= 2, "{stats:?}");
    assert!(checksum > 0);

    // Read again, extracting a field from every message (what the runtime does per frame).
    let t = Instant::now();
    let mut r = LogReader::open(&path).unwrap();
    let mut sum = 0.0;
    while let Some(m) = r.next_message() {
        let m = m.unwrap();
        let field = match m.topic {
            "/throttle/motor_voltage" | "/throttle/tps" => "voltage_v",
            _ => "power_w",
        };
        sum += m.field_f64(field).unwrap();
    }
    let decode_s = t.elapsed().as_secs_f64();
    assert!(sum.is_finite());

    // Validating CRCs.
    let t = Instant::now();
    let mut r = LogReader::open_with(
        &path,
        ReadOptions {
            validate_crcs: true,
            ..ReadOptions::default()
        },
    )
    .unwrap();
    let mut validated = 0u64;
    while let Some(m) = r.next_message() {
        m.unwrap();
        validated += 1;
    }
    let validate_s = t.elapsed().as_secs_f64();
    assert_eq!(validated, n);

    let per_s = |s: f64| n as f64 / s;
    println!(
        "{n} messages, {chunks} chunks, {:.1} MB file ({:.1} bytes/message)",
        size as f64 / 1e6,
        size as f64 / n as f64
    );
    println!("write:                 {:>12.0} messages/s", per_s(write_s));
    println!("read (log-time order): {:>12.0} messages/s", per_s(read_s));
    println!(
        "read + field_f64:      {:>12.0} messages/s",
        per_s(decode_s)
    );
    println!(
        "read, CRCs validated:  {:>12.0} messages/s",
        per_s(validate_s)
    );
    if let (Some(start), Some(written)) = (rss_start, rss_written) {
        let grown = written.saturating_sub(start);
        println!("RSS grew by {:.1} MB while writing", grown as f64 / 1e6);
        assert!(grown < 24 << 20, "RSS grew by {grown} bytes while writing");
    }
    if let (Some(before), Some(mid)) = (rss_before, rss_mid) {
        let grown = mid.saturating_sub(before);
        println!(
            "RSS grew by {:.1} MB while reading (messages hold {:.1} MB uncompressed)",
            grown as f64 / 1e6,
            checksum as f64 / 1e6
        );
        // The messages alone are ~20 MB; holding them would show.
        assert!(grown < 12 << 20, "RSS grew by {grown} bytes");
    }
    if !cfg!(debug_assertions) {
        // Far below what is measured (several million per second), to catch a regression
        // without being flaky on a slow machine.
        assert!(per_s(read_s) > 1.0e6, "{} messages/s", per_s(read_s));
    }
}
