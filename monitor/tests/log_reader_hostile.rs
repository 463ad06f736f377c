//! Hostile input for the MCAP reader (issue 11): summaries that repeat or misplace chunk
//! indexes, lz4 chunks, chunks that all fail, corruption told apart from truncation, and the
//! limits of `ReadOptions`. The inputs are built here, from files the writers make.

mod log_common;

use std::collections::BTreeMap;
use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use fdd_monitor::log::*;
use log_common::*;

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Footer record (9-byte header, 20-byte body) and the end magic.
const FOOTER_AND_MAGIC: usize = 37;
const OP_FOOTER: u8 = 0x02;
const OP_CHUNK: u8 = 0x06;
const OP_CHUNK_INDEX: u8 = 0x08;
const OP_SUMMARY_OFFSET: u8 = 0x0E;

fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap())
}

fn summary_start(b: &[u8]) -> usize {
    u64_at(b, b.len() - FOOTER_AND_MAGIC + 9) as usize
}

/// Position of the DataEnd record (just before the summary section).
fn data_end_pos(b: &[u8]) -> usize {
    summary_start(b) - 13
}

/// (position, opcode, body length) of each record in `b[from..to]`.
fn records(b: &[u8], from: usize, to: usize) -> Vec<(usize, u8, usize)> {
    let mut out = Vec::new();
    let mut at = from;
    while at < to {
        let len = u64_at(b, at + 1) as usize;
        out.push((at, b[at], len));
        at += 9 + len;
    }
    out
}

fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut r = vec![opcode];
    r.extend_from_slice(&(body.len() as u64).to_le_bytes());
    r.extend_from_slice(body);
    r
}

/// The file with its summary records replaced by what `f` makes of them (summary offset
/// records dropped), and a footer pointing to the new summary: summary offsets none, summary
/// CRC 0 ("not computed"), as a writer may legitimately write.
fn with_summary(b: &[u8], f: impl FnOnce(Vec<(u8, Vec<u8>)>) -> Vec<(u8, Vec<u8>)>) -> Vec<u8> {
    let start = summary_start(b);
    let footer = b.len() - FOOTER_AND_MAGIC;
    let old: Vec<(u8, Vec<u8>)> = records(b, start, footer)
        .into_iter()
        .filter(|&(_, op, _)| op != OP_SUMMARY_OFFSET)
        .map(|(at, op, len)| (op, b[at + 9..at + 9 + len].to_vec()))
        .collect();
    let mut out = b[..start].to_vec();
    for (op, body) in f(old) {
        out.extend(record(op, &body));
    }
    let mut footer_body = (start as u64).to_le_bytes().to_vec();
    footer_body.extend_from_slice(&0u64.to_le_bytes());
    footer_body.extend_from_slice(&0u32.to_le_bytes());
    out.extend(record(OP_FOOTER, &footer_body));
    out.extend_from_slice(MAGIC);
    out
}

/// The file with its footer saying "no summary section" (summary start 0): complete, with a
/// valid footer and end magic, but read linearly.
fn without_summary(b: &[u8]) -> Vec<u8> {
    let mut out = b.to_vec();
    let footer = out.len() - FOOTER_AND_MAGIC;
    out[footer + 9..footer + 29].fill(0);
    out
}

/// Input samples on the three input topics (3 messages per ms), zstd, small chunks.
fn inputs_file(samples: u64, chunk_size: u64) -> Vec<u8> {
    to_bytes(
        WriteOptions {
            chunk_size,
            ..WriteOptions::default()
        },
        |w| write_inputs(w, samples),
    )
}

/// Reads everything with `options`, timing it.
fn read_timed(path: &Path, options: ReadOptions) -> (Vec<Msg>, Vec<LogError>, ReadStats, Duration) {
    let t0 = Instant::now();
    let mut r = LogReader::open_with(path, options).expect("opens");
    let (msgs, errs) = read_lenient(&mut r);
    (msgs, errs, r.stats(), t0.elapsed())
}

fn small_limits(f: impl FnOnce(&mut ReadOptions)) -> ReadOptions {
    let mut o = ReadOptions::default();
    f(&mut o);
    o
}

/// The error names the file, the limit (the `ReadOptions` field), its value and how to raise
/// it, and is fatal.
fn assert_limit(e: &LogError, file: &str, limit: &str, value: u64) {
    match e {
        LogError::LimitExceeded {
            limit: l, value: v, ..
        } => {
            assert_eq!((*l, *v), (limit, value), "{e}");
        }
        other => panic!("expected LimitExceeded({limit}), got {other}"),
    }
    assert!(e.is_fatal());
    let text = e.to_string();
    assert!(text.contains(file), "{text}");
    assert!(text.contains(&format!("limit {limit} = {value}")), "{text}");
    // How to raise it: the CLI's configuration key and the host's field.
    assert!(
        text.contains(&format!("`[replay.limits] {limit}`"))
            && text.contains(&format!("ReadOptions::{limit} for a host")),
        "{text}"
    );
}

// ---- 1. Chunk indexes: repeated, overlapping, outside the data section; the merge ----------

#[test]
fn a_summary_repeating_one_chunk_index_reads_each_chunk_once() {
    let bytes = inputs_file(3000, 16 << 10);
    let dir = tempfile::tempdir().unwrap();
    let (full, errs, good, _) = read_timed(
        &put(dir.path(), "good.mcap", &bytes),
        ReadOptions::default(),
    );
    assert!(errs.is_empty(), "{errs:?}");
    let chunks = good.chunks_total.unwrap();
    assert!(chunks >= 4, "{good:?}");
    assert_eq!(full.len(), 9000);

    // The summary repeats the index of a chunk in the middle 20,000 times (and one of the
    // first chunk 50 times, ahead of the others).
    const COPIES: usize = 20_000;
    let hostile = with_summary(&bytes, |recs| {
        let indexes: Vec<Vec<u8>> = recs
            .iter()
            .filter(|(op, _)| *op == OP_CHUNK_INDEX)
            .map(|(_, body)| body.clone())
            .collect();
        assert_eq!(indexes.len(), chunks);
        let middle = indexes[chunks / 2].clone();
        let first = indexes[0].clone();
        let mut out: Vec<(u8, Vec<u8>)> =
            (0..50).map(|_| (OP_CHUNK_INDEX, first.clone())).collect();
        out.extend(recs);
        out.extend((0..COPIES).map(|_| (OP_CHUNK_INDEX, middle.clone())));
        out
    });
    assert!(hostile.len() > 1_000_000, "{}", hostile.len());
    let path = put(dir.path(), "repeated.mcap", &hostile);
    let (msgs, errs, stats, elapsed) = read_timed(&path, ReadOptions::default());
    assert!(errs.is_empty(), "{errs:?}");
    // Exactly the original messages, once each, in the same order.
    assert_eq!(msgs, full);
    assert_eq!(stats.chunks_total, Some(chunks));
    assert_eq!(stats.chunks_loaded, chunks, "{stats:?}");
    assert_eq!(stats.chunks_failed, 0);
    assert_eq!(stats.duplicate_chunk_indexes, COPIES + 50);
    assert!(stats.max_resident_chunks <= 2, "{stats:?}");
    // Each chunk is decompressed once: no more than for the good file.
    assert_eq!(stats.decompressed_bytes, good.decompressed_bytes);
    assert!(elapsed < Duration::from_secs(20), "{elapsed:?}");
}

#[test]
fn overlapping_and_out_of_range_chunk_indexes_are_refused_with_a_clear_error() {
    let bytes = inputs_file(2000, 16 << 10);
    let dir = tempfile::tempdir().unwrap();
    let (full, _, good, _) = read_timed(
        &put(dir.path(), "good.mcap", &bytes),
        ReadOptions::default(),
    );
    let chunks = good.chunks_total.unwrap();
    let data_end = data_end_pos(&bytes) as u64;
    let hostile = with_summary(&bytes, |mut recs| {
        let body = recs
            .iter()
            .find(|(op, _)| *op == OP_CHUNK_INDEX)
            .unwrap()
            .1
            .clone();
        // The same chunk, one byte further: overlaps the real one.
        let mut shifted = body.clone();
        let offset = u64_at(&body, 16);
        shifted[16..24].copy_from_slice(&(offset + 1).to_le_bytes());
        // A chunk ending past the DataEnd record.
        let mut outside = body.clone();
        outside[16..24].copy_from_slice(&(data_end - 5).to_le_bytes());
        recs.push((OP_CHUNK_INDEX, shifted));
        recs.push((OP_CHUNK_INDEX, outside));
        recs
    });
    let path = put(dir.path(), "overlap.mcap", &hostile);
    let mut r = LogReader::open(&path).unwrap();
    assert_eq!(r.mode(), ReadMode::Indexed);
    let (msgs, errs) = read_lenient(&mut r);
    // The real chunks are all read; the two bad indexes are reported.
    assert_eq!(msgs, full);
    assert_eq!(errs.len(), 2, "{errs:?}");
    let texts: Vec<String> = errs.iter().map(|e| e.to_string()).collect();
    for e in &errs {
        assert!(matches!(e, LogError::BadChunk { .. }), "{e}");
        assert!(!e.is_fatal());
        assert!(e.to_string().contains("overlap.mcap"), "{e}");
    }
    assert!(
        texts.iter().any(|t| t.contains("overlap the chunk")),
        "{texts:?}"
    );
    assert!(
        texts.iter().any(|t| t.contains("outside the data section")),
        "{texts:?}"
    );
    let stats = r.stats();
    assert_eq!(stats.chunks_total, Some(chunks + 2));
    assert_eq!(stats.chunks_loaded, chunks);
    assert_eq!(stats.chunks_failed, 2);
    assert!(!stats.all_chunks_failed());
}

#[test]
fn many_chunks_overlapping_in_time_merge_in_log_time_order() {
    // Times in a scrambled order, 2 or 3 messages per chunk: nearly every chunk spans most of
    // the run, so nearly all are resident at once and the merge picks among hundreds.
    let n = 6000u64;
    let times: Vec<u64> = (0..n).map(|k| (k * 7919) % n * 1000).collect();
    let bytes = to_bytes(
        WriteOptions {
            chunk_size: 120,
            compression: ChunkCompression::None,
            message_indexes: false,
        },
        |w| {
            for (k, &t) in times.iter().enumerate() {
                w.write_message(
                    t,
                    &TpsVoltage {
                        voltage_v: k as f64,
                    },
                )?;
            }
            Ok(())
        },
    );
    let dir = tempfile::tempdir().unwrap();
    let (msgs, errs, stats, elapsed) = read_timed(
        &put(dir.path(), "scrambled.mcap", &bytes),
        ReadOptions::default(),
    );
    assert!(errs.is_empty(), "{errs:?}");
    let got: Vec<u64> = msgs.iter().map(|m| m.1).collect();
    let mut want = times.clone();
    want.sort_unstable();
    assert_eq!(got, want);
    assert!(stats.max_resident_chunks > 500, "{stats:?}");
    assert_eq!(stats.chunks_loaded, stats.chunks_total.unwrap());
    assert!(elapsed < Duration::from_secs(20), "{elapsed:?}");
}

// ---- 2. lz4 chunks; files whose chunks all fail ------------------------------------------

/// An lz4-compressed file written by the mcap crate's own writer, and its messages.
fn lz4_file(n: u64) -> (Vec<u8>, Vec<Msg>) {
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Lz4))
        .chunk_size(Some(600))
        .library("log_reader_hostile")
        .create(Cursor::new(Vec::new()))
        .unwrap();
    let schema = w
        .add_schema("fdd.TpsVoltage", "jsonschema", br#"{"type":"object"}"#)
        .unwrap();
    let tps = w
        .add_channel(schema, "/throttle/tps", "json", &BTreeMap::new())
        .unwrap();
    let watt = w
        .add_channel(schema, "/throttle/wattmeter", "json", &BTreeMap::new())
        .unwrap();
    let mut expected = Vec::new();
    for k in 0..n {
        let t = k * 1_000_000;
        for (channel, topic, field) in [
            (tps, "/throttle/tps", "voltage_v"),
            (watt, "/throttle/wattmeter", "power_w"),
        ] {
            let data = format!(r#"{{"{field}":{}}}"#, k as f64 * 0.25);
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: k as u32,
                log_time: t,
                publish_time: t,
            };
            w.write_to_known_channel(&header, data.as_bytes()).unwrap();
            expected.push((topic.to_string(), t, data.into_bytes()));
        }
    }
    w.finish().unwrap();
    (w.into_inner().into_inner(), expected)
}

/// The number of messages the official Python reader reads from `path`, checking CRCs;
/// `None` when Python, its `mcap` package or its `lz4` package is missing.
fn python_message_count(path: &Path) -> Option<usize> {
    const SCRIPT: &str = "import sys\nfrom mcap.reader import make_reader\n\
        r = make_reader(open(sys.argv[1], 'rb'), validate_crcs=True)\n\
        print(sum(1 for _ in r.iter_messages()))\n";
    let available = std::process::Command::new("python3")
        .args(["-c", "import mcap.reader, lz4.frame"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !available {
        return None;
    }
    let out = std::process::Command::new("python3")
        .args(["-c", SCRIPT])
        .arg(path)
        .output()
        .expect("run python3");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    Some(String::from_utf8_lossy(&out.stdout).trim().parse().unwrap())
}

#[test]
fn lz4_chunks_are_read() {
    let (bytes, expected) = lz4_file(400);
    // It is an lz4 file of several chunks.
    let chunks = records(&bytes, 8, data_end_pos(&bytes))
        .into_iter()
        .filter(|r| r.1 == OP_CHUNK)
        .count();
    assert!(chunks > 5, "{chunks}");
    assert!(bytes.windows(3).any(|w| w == b"lz4"));
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "lz4.mcap", &bytes);
    // The official Python reader validates it (when installed, with its lz4 package).
    if let Some(n) = python_message_count(&path) {
        assert_eq!(n, expected.len());
    }
    for validate_crcs in [false, true] {
        let options = ReadOptions {
            validate_crcs,
            ..ReadOptions::default()
        };
        let mut r = LogReader::open_with(&path, options).unwrap();
        assert_eq!(r.mode(), ReadMode::Indexed);
        let (msgs, errs) = read_lenient(&mut r);
        assert!(errs.is_empty(), "{errs:?}");
        assert_eq!(msgs, expected);
        let s = r.stats();
        assert_eq!(s.chunks_loaded, chunks);
        assert_eq!(s.chunks_failed, 0);
    }
    // Linear reading (no summary) too.
    let path = put(dir.path(), "lz4_linear.mcap", &without_summary(&bytes));
    let mut r = LogReader::open(&path).unwrap();
    assert_eq!(r.mode(), ReadMode::Linear);
    let (msgs, errs) = read_lenient(&mut r);
    assert!(errs.is_empty(), "{errs:?}");
    assert_eq!(msgs, expected);
}

#[test]
fn a_file_whose_chunks_all_fail_is_not_an_empty_log() {
    let (mut bytes, _) = lz4_file(200);
    // Every chunk names a compression no reader knows ("lz5"): each fails to decode.
    let mut chunks = 0;
    for (at, op, _) in records(&bytes, 8, data_end_pos(&bytes)) {
        if op == OP_CHUNK {
            // Body: start, end, uncompressed size (8 each), CRC (4), compression string.
            let name = at + 9 + 28;
            assert_eq!(
                u32::from_le_bytes(bytes[name..name + 4].try_into().unwrap()),
                3
            );
            assert_eq!(&bytes[name + 4..name + 7], b"lz4");
            bytes[name + 6] = b'5';
            chunks += 1;
        }
    }
    assert!(chunks > 3);
    let dir = tempfile::tempdir().unwrap();
    for (name, file) in [
        ("all_bad.mcap", bytes.clone()),
        ("all_bad_linear.mcap", without_summary(&bytes)),
    ] {
        let path = put(dir.path(), name, &file);
        let mut r = LogReader::open(&path).unwrap();
        let (msgs, errs) = read_lenient(&mut r);
        assert!(msgs.is_empty());
        assert_eq!(errs.len(), chunks, "{errs:?}");
        for e in &errs {
            assert!(matches!(e, LogError::BadChunk { .. }), "{e}");
            assert!(e.to_string().contains(name), "{e}");
        }
        let s = r.stats();
        assert_eq!(s.chunks_failed, chunks, "{s:?}");
        assert_eq!(s.chunks_loaded, 0);
        assert!(s.all_chunks_failed(), "{s:?}");
    }
    // A file that is really empty is not "all failed".
    let empty = to_bytes(WriteOptions::default(), |_| Ok(()));
    let mut r = LogReader::open(put(dir.path(), "empty.mcap", &empty)).unwrap();
    let (msgs, errs) = read_lenient(&mut r);
    assert!(msgs.is_empty() && errs.is_empty());
    assert!(!r.stats().all_chunks_failed());
    assert_eq!(r.stats().chunks_failed, 0);
}

// ---- 3. Corruption is not truncation ------------------------------------------------------

#[test]
fn a_bad_record_length_in_a_complete_file_is_corruption_not_truncation() {
    let original = inputs_file(2000, 8 << 10);
    let bytes = without_summary(&original);
    let chunk_records: Vec<(usize, u8, usize)> = records(&bytes, 8, data_end_pos(&original))
        .into_iter()
        .filter(|r| r.1 == OP_CHUNK)
        .collect();
    assert!(chunk_records.len() > 3);
    let (second, _, _) = chunk_records[1];
    let dir = tempfile::tempdir().unwrap();
    let clean = read_lenient(&mut LogReader::open(put(dir.path(), "clean.mcap", &bytes)).unwrap());
    assert!(clean.1.is_empty(), "{:?}", clean.1);

    // The second chunk's length runs past the end of the file; the file still ends with a
    // valid footer and end magic.
    for bad_len in [1u64 << 40, bytes.len() as u64] {
        let mut bad = bytes.clone();
        bad[second + 1..second + 9].copy_from_slice(&bad_len.to_le_bytes());
        let path = put(dir.path(), "corrupt.mcap", &bad);
        let mut r = LogReader::open(&path).unwrap();
        assert_eq!(r.mode(), ReadMode::Linear);
        let (msgs, errs) = read_lenient(&mut r);
        // The first chunk was read, then the damage stops the reading.
        assert!(!msgs.is_empty() && msgs.len() < clean.0.len());
        assert_eq!(msgs[..], clean.0[..msgs.len()]);
        assert_eq!(errs.len(), 1, "{errs:?}");
        let e = &errs[0];
        assert!(matches!(e, LogError::Corrupt { .. }), "{e}");
        assert!(e.is_fatal());
        assert_eq!(e.offset(), Some(second as u64));
        let text = e.to_string();
        assert!(
            text.contains("corrupt.mcap") && text.contains("corrupt at byte"),
            "{text}"
        );
        assert!(!text.contains("truncated"), "{text}");
    }

    // The same file cut short (no footer, no end magic) is truncated.
    let cut = &bytes[..second + 100];
    let path = put(dir.path(), "cut.mcap", cut);
    let mut r = LogReader::open(&path).unwrap();
    let (msgs, errs) = read_lenient(&mut r);
    assert_eq!(msgs[..], clean.0[..msgs.len()]);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert!(matches!(errs[0], LogError::Truncated { .. }), "{}", errs[0]);
    assert_eq!(errs[0].offset(), Some(second as u64));
    assert!(errs[0].to_string().contains("truncated at byte"));
}

// ---- 4. Limits ----------------------------------------------------------------------------

#[test]
fn defaults_are_stated() {
    let o = ReadOptions::default();
    assert_eq!(o.max_record_bytes, 256 << 20);
    assert_eq!(o.max_chunk_indexes, 1_000_000);
    assert_eq!(o.max_channels, 10_000);
    assert_eq!(o.max_schemas, 10_000);
    assert_eq!(o.max_message_bytes, 16 << 20);
    assert_eq!(o.max_summary_bytes, 128 << 20);
    assert_eq!(o.max_decompression_ratio, 1000);
    assert_eq!(o.decompressed_bytes_floor, 64 << 20);
    assert_eq!(o.decompressed_budget(1000), 64 << 20);
    assert_eq!(o.decompressed_budget(1 << 20), 1000 << 20);
    assert_eq!(o.decompressed_budget(u64::MAX), u64::MAX);
}

#[test]
fn too_many_chunk_indexes() {
    let bytes = inputs_file(2000, 8 << 10);
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "chunks.mcap", &bytes);
    let n = LogReader::open(&path)
        .unwrap()
        .stats()
        .chunks_total
        .unwrap() as u64;
    assert!(n > 3);
    let e = LogReader::open_with(&path, small_limits(|o| o.max_chunk_indexes = 3)).unwrap_err();
    assert_limit(&e, "chunks.mcap", "max_chunk_indexes", 3);
    assert!(LogReader::open_with(&path, small_limits(|o| o.max_chunk_indexes = n)).is_ok());
}

#[test]
fn too_many_channels_and_schemas() {
    // Three topics, each with its own schema and channel.
    let bytes = inputs_file(100, 8 << 10);
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "topics.mcap", &bytes);
    let linear = put(dir.path(), "topics_linear.mcap", &without_summary(&bytes));
    for (limit, set) in [
        (
            "max_channels",
            (|o: &mut ReadOptions| o.max_channels = 2) as fn(&mut ReadOptions),
        ),
        ("max_schemas", |o: &mut ReadOptions| o.max_schemas = 2),
    ] {
        // Indexed: the summary defines them, opening fails.
        let e = LogReader::open_with(&path, small_limits(set)).unwrap_err();
        assert_limit(&e, "topics.mcap", limit, 2);
        // Linear: the chunks define them, the reading stops at the third.
        let mut r = LogReader::open_with(&linear, small_limits(set)).unwrap();
        let (msgs, errs) = read_lenient(&mut r);
        assert!(msgs.is_empty());
        assert_eq!(errs.len(), 1, "{errs:?}");
        assert_limit(&errs[0], "topics_linear.mcap", limit, 2);
        assert!(errs[0].offset().is_some());
    }
    // Three of each is enough.
    let three = small_limits(|o| {
        o.max_channels = 3;
        o.max_schemas = 3;
    });
    assert_eq!(read_all(&path, three.clone()).unwrap().len(), 300);
    assert_eq!(read_all(&linear, three).unwrap().len(), 300);
}

#[test]
fn too_large_a_message() {
    let bytes = inputs_file(100, 8 << 10);
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "big.mcap", &bytes);
    let longest = read_all(&path, ReadOptions::default())
        .unwrap()
        .iter()
        .map(|m| m.2.len() as u64)
        .max()
        .unwrap();
    for p in [
        path.clone(),
        put(dir.path(), "big_linear.mcap", &without_summary(&bytes)),
    ] {
        let mut r = LogReader::open_with(&p, small_limits(|o| o.max_message_bytes = 10)).unwrap();
        let (msgs, errs) = read_lenient(&mut r);
        assert!(msgs.is_empty());
        assert_eq!(errs.len(), 1, "{errs:?}");
        let name = p.file_name().unwrap().to_str().unwrap();
        assert_limit(&errs[0], name, "max_message_bytes", 10);
        assert!(errs[0].to_string().contains("bytes"), "{}", errs[0]);
        // At the longest message's size, everything reads.
        let ok = small_limits(|o| o.max_message_bytes = longest);
        assert_eq!(read_all(&p, ok).unwrap().len(), 300);
    }
}

#[test]
fn too_large_a_summary() {
    let bytes = inputs_file(100, 8 << 10);
    let summary = (bytes.len() - FOOTER_AND_MAGIC - summary_start(&bytes)) as u64;
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "summary.mcap", &bytes);
    let e = LogReader::open_with(&path, small_limits(|o| o.max_summary_bytes = 64)).unwrap_err();
    assert_limit(&e, "summary.mcap", "max_summary_bytes", 64);
    assert!(e.to_string().contains(&format!("{summary} bytes")), "{e}");
    assert!(LogReader::open_with(&path, small_limits(|o| o.max_summary_bytes = summary)).is_ok());
}

#[test]
fn decompression_budget() {
    // Very compressible messages: the chunks decompress to many times the file's size.
    let bytes = to_bytes(
        WriteOptions {
            chunk_size: 64 << 10,
            message_indexes: false,
            ..WriteOptions::default()
        },
        |w| {
            for k in 0..20_000u64 {
                w.write_message(k * 1000, &TpsVoltage { voltage_v: 1.0 })?;
            }
            Ok(())
        },
    );
    let file_len = bytes.len() as u64;
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "bomb.mcap", &bytes);
    let (msgs, errs, stats, _) = read_timed(&path, ReadOptions::default());
    assert!(errs.is_empty());
    assert_eq!(msgs.len(), 20_000);
    let ratio = stats.decompressed_bytes / file_len;
    assert!(ratio >= 3, "{} of {file_len}", stats.decompressed_bytes);

    // A ratio of 2 (and no floor): the reading stops, naming the ratio.
    let tight = small_limits(|o| {
        o.max_decompression_ratio = 2;
        o.decompressed_bytes_floor = 0;
    });
    let mut r = LogReader::open_with(&path, tight).unwrap();
    let (msgs, errs) = read_lenient(&mut r);
    assert!(msgs.len() < 20_000);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_limit(&errs[0], "bomb.mcap", "max_decompression_ratio", 2);
    assert!(errs[0].offset().is_some());
    assert!(r.stats().decompressed_bytes <= 2 * file_len);

    // The floor rescues a small file.
    let floor = small_limits(|o| {
        o.max_decompression_ratio = 2;
        o.decompressed_bytes_floor = stats.decompressed_bytes;
    });
    assert_eq!(read_all(&path, floor).unwrap().len(), 20_000);

    // When the floor sets the budget, the error names the floor.
    let by_floor = small_limits(|o| {
        o.max_decompression_ratio = 0;
        o.decompressed_bytes_floor = 1000;
    });
    let mut r = LogReader::open_with(&path, by_floor).unwrap();
    let (_, errs) = read_lenient(&mut r);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert_limit(&errs[0], "bomb.mcap", "decompressed_bytes_floor", 1000);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Any list of chunk indexes (real ones repeated, moved, resized, retimed, or pointing
    /// anywhere): no panic, the reading ends, no message comes out twice, no chunk is
    /// decompressed twice, and every index is accounted for.
    #[test]
    fn arbitrary_chunk_indexes_never_repeat_or_blow_up(
        entries in proptest::collection::vec(
            (0u8..5, proptest::prelude::any::<proptest::sample::Index>(), proptest::prelude::any::<u64>()),
            0..300,
        ),
        keep_real in proptest::prelude::any::<bool>(),
    ) {
        use std::sync::OnceLock;
        static FILE: OnceLock<(Vec<u8>, u64)> = OnceLock::new();
        let (bytes, good_decompressed) = FILE.get_or_init(|| {
            let bytes = inputs_file(400, 2 << 10);
            let dir = tempfile::tempdir().unwrap();
            let (_, _, s, _) = read_timed(&put(dir.path(), "f.mcap", &bytes), ReadOptions::default());
            (bytes, s.decompressed_bytes)
        });
        let file_len = bytes.len() as u64;
        let hostile = with_summary(bytes, |recs| {
            let real: Vec<Vec<u8>> = recs
                .iter()
                .filter(|(op, _)| *op == OP_CHUNK_INDEX)
                .map(|(_, b)| b.clone())
                .collect();
            let mut out: Vec<(u8, Vec<u8>)> = recs
                .into_iter()
                .filter(|(op, _)| keep_real || *op != OP_CHUNK_INDEX)
                .collect();
            for (kind, i, v) in &entries {
                let mut body = real[i.index(real.len())].clone();
                let field = |b: &mut Vec<u8>, at: usize, x: u64| b[at..at + 8].copy_from_slice(&x.to_le_bytes());
                match kind {
                    0 => {}
                    1 => {
                        let off = u64_at(&body, 16);
                        field(&mut body, 16, off.wrapping_add(v % 101).wrapping_sub(50));
                    }
                    2 => field(&mut body, 24, v % (2 * file_len)),
                    3 => field(&mut body, 0, *v),
                    _ => field(&mut body, 16, v % (2 * file_len)),
                }
                out.push((OP_CHUNK_INDEX, body));
            }
            out
        });
        let dir = tempfile::tempdir().unwrap();
        let path = put(dir.path(), "arbitrary.mcap", &hostile);
        let mut r = match LogReader::open(&path) {
            Ok(r) => r,
            Err(e) => {
                proptest::prop_assert!(e.is_fatal());
                return Ok(());
            }
        };
        let (msgs, errs) = read_lenient(&mut r);
        let mut seen = std::collections::HashSet::new();
        for m in &msgs {
            proptest::prop_assert!(seen.insert((m.0.clone(), m.1)), "{:?} twice", (&m.0, m.1));
        }
        for e in &errs {
            proptest::prop_assert!(e.to_string().contains("arbitrary.mcap"));
        }
        let s = r.stats();
        proptest::prop_assert!(s.decompressed_bytes <= *good_decompressed, "{s:?}");
        if r.mode() == ReadMode::Indexed && errs.iter().all(|e| !e.is_fatal()) {
            proptest::prop_assert_eq!(s.chunks_loaded + s.chunks_failed, s.chunks_total.unwrap());
        }
    }
}

/// A record header inside a 12 kB chunk claiming 238 MB made the mcap crate's reader reserve
/// the whole length before decompressing it: 4 kB of input cost 240 MB (the `mcap_reader` fuzz
/// target's input, kept in fuzz/regressions/). The records of a chunk are now limited to what
/// the chunk can hold, so the record is refused by its length instead of being allocated.
#[test]
fn a_record_longer_than_its_chunk_is_refused_before_it_is_allocated() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/regressions/mcap_reader/a_record_claiming_more_than_its_chunk_holds.mcap");
    let mut reader = LogReader::open(&path).expect("the file opens (linear)");
    let mut errors = Vec::new();
    while let Some(item) = reader.next_message() {
        match item {
            Ok(m) => panic!("a message from a damaged chunk: {}", m.topic),
            Err(e) => errors.push(e.to_string()),
        }
    }
    assert!(
        errors
            .first()
            .is_some_and(|e| e.contains("length exceeds limit") && e.contains("238157865")),
        "{errors:?}"
    );
}
