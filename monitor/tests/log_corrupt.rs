//! Truncated and corrupt files: clear errors naming the file, or a clean linear fallback; never
//! a panic.

mod log_common;

use std::path::{Path, PathBuf};

use fdd_monitor::log::*;
use log_common::*;
use proptest::prelude::*;

fn validating() -> ReadOptions {
    ReadOptions {
        validate_crcs: true,
        ..ReadOptions::default()
    }
}

fn small_file(compression: ChunkCompression) -> Vec<u8> {
    to_bytes(
        WriteOptions {
            chunk_size: 400,
            compression,
            ..WriteOptions::default()
        },
        |w| {
            write_examples(w, 0)?;
            for k in 0..60u64 {
                w.write_message(
                    10_000_000 + k * 1_000_000,
                    &TpsVoltage {
                        voltage_v: 1000.0 + k as f64,
                    },
                )?;
            }
            Ok(())
        },
    )
}

/// A smaller file (short schemas, several chunks) for the byte-by-byte sweeps.
fn tiny_file() -> Vec<u8> {
    to_bytes(
        WriteOptions {
            chunk_size: 300,
            compression: ChunkCompression::Zstd { level: 3 },
            ..WriteOptions::default()
        },
        |w| {
            for k in 0..40u64 {
                let t = k * 1_000_000;
                w.write_message(
                    t,
                    &TpsVoltage {
                        voltage_v: k as f64,
                    },
                )?;
                if k % 4 == 0 {
                    w.write_message(t, &Wattmeter { power_w: k as f64 })?;
                }
            }
            Ok(())
        },
    )
}

fn put(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// Position of the DataEnd record (just before the summary section).
fn data_end_pos(bytes: &[u8]) -> usize {
    let footer = bytes.len() - 37;
    let summary_start = u64::from_le_bytes(bytes[footer + 9..footer + 17].try_into().unwrap());
    summary_start as usize - 13
}

/// Start of the top-level record (a chunk) that holds byte `pos`.
fn record_containing(bytes: &[u8], pos: usize) -> usize {
    let mut at = 8;
    loop {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        if pos < at + 9 + len {
            return at;
        }
        at += 9 + len;
    }
}

fn find(bytes: &[u8], needle: &[u8]) -> usize {
    bytes
        .windows(needle.len())
        .position(|w| w == needle)
        .expect("needle in file")
}

#[test]
fn truncated_files_give_a_prefix_and_a_clear_error() {
    let bytes = tiny_file();
    let dir = tempfile::tempdir().unwrap();
    let full = read_all(
        &put(dir.path(), "full.mcap", &bytes),
        ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(full.len(), 50);
    for options in [ReadOptions::default(), validating()] {
        let mut previous = 0;
        for cut in 0..bytes.len() {
            let path = put(dir.path(), "cut.mcap", &bytes[..cut]);
            let mut r = match LogReader::open_with(&path, options.clone()) {
                Ok(r) => r,
                Err(e) => {
                    assert!(cut < 8, "cut at {cut}: {e}");
                    assert!(e.is_fatal());
                    assert!(e.to_string().contains("cut.mcap"), "{e}");
                    continue;
                }
            };
            assert_eq!(r.mode(), ReadMode::Linear, "cut at {cut}");
            let (msgs, errs) = read_lenient(&mut r);
            // What is read is the beginning of the file, intact.
            assert_eq!(msgs[..], full[..msgs.len()], "cut at {cut}");
            // Messages only ever appear as the cut moves on.
            assert!(msgs.len() >= previous, "cut at {cut}");
            previous = msgs.len();
            match &errs[..] {
                [] => {
                    // Only a cut after the DataEnd record reads cleanly, and only without CRC
                    // checks (which read on through the summary).
                    assert!(cut > data_end_pos(&bytes), "cut at {cut}");
                    assert!(!options.validate_crcs);
                    assert_eq!(msgs.len(), full.len());
                }
                [e] => {
                    assert!(e.is_fatal(), "cut at {cut}: {e}");
                    assert!(matches!(e, LogError::Truncated { .. }), "cut at {cut}: {e}");
                    let text = e.to_string();
                    assert!(
                        text.contains("cut.mcap") && text.contains("truncated"),
                        "{text}"
                    );
                    assert!(e.offset().unwrap() <= cut as u64);
                }
                more => panic!("cut at {cut}: {more:?}"),
            }
        }
        assert_eq!(previous, full.len());
    }
}

#[test]
fn every_flipped_byte_is_caught_with_crc_validation() {
    let bytes = tiny_file();
    let dir = tempfile::tempdir().unwrap();
    let full = read_all(&put(dir.path(), "full.mcap", &bytes), validating()).unwrap();
    let mut crc_errors = 0;
    for pos in 0..bytes.len() {
        let mut bad = bytes.clone();
        bad[pos] ^= 0x5A;
        let path = put(dir.path(), "flipped.mcap", &bad);
        // Validating: the damage is reported, at open or while reading.
        match LogReader::open_with(&path, validating()) {
            Err(e) => {
                assert!(e.is_fatal());
                assert!(e.to_string().contains("flipped.mcap"), "{e}");
                crc_errors += matches!(e, LogError::CrcMismatch { .. }) as usize;
            }
            Ok(mut r) => {
                let (msgs, errs) = read_lenient(&mut r);
                assert!(
                    !errs.is_empty(),
                    "byte {pos} flipped: no error ({} messages, {} expected)",
                    msgs.len(),
                    full.len()
                );
                for e in &errs {
                    assert!(e.to_string().contains("flipped.mcap"), "{e}");
                }
            }
        }
        // Not validating: anything may come out, but no panic and it ends.
        if let Ok(mut r) = LogReader::open(&path) {
            let (msgs, _) = read_lenient(&mut r);
            for (_, _, data) in msgs.iter().take(5) {
                let _ = json_field_f64(data, "voltage_v");
            }
        }
    }
    assert!(crc_errors > bytes.len() / 2, "{crc_errors} CRC errors");
}

#[test]
fn a_corrupt_chunk_is_a_crc_error_and_the_other_chunks_still_read() {
    let mut bytes = small_file(ChunkCompression::None);
    let dir = tempfile::tempdir().unwrap();
    let full = read_all(&put(dir.path(), "full.mcap", &bytes), validating()).unwrap();

    // One digit of one message changes: still valid JSON, but the chunk CRC fails.
    let pos = find(&bytes, b"1042.0") + 2;
    bytes[pos] = b'9';
    // With the data section CRC, opening already fails.
    let path = put(dir.path(), "corrupt.mcap", &bytes);
    let e = LogReader::open_with(&path, validating()).unwrap_err();
    assert!(
        matches!(
            e,
            LogError::CrcMismatch {
                section: CrcSection::DataSection,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("corrupt.mcap"), "{e}");
    assert!(e.to_string().contains("CRC mismatch"), "{e}");

    // A file without a data section CRC: the chunk CRC catches it, and reading goes on. Chunk
    // CRCs are checked with or without `validate_crcs`.
    let de = data_end_pos(&bytes);
    bytes[de + 9..de + 13].fill(0);
    let path = put(dir.path(), "corrupt.mcap", &bytes);
    for options in [validating(), ReadOptions::default()] {
        let mut r = LogReader::open_with(&path, options).unwrap();
        assert_eq!(r.mode(), ReadMode::Indexed);
        let (msgs, errs) = read_lenient(&mut r);
        assert_eq!(errs.len(), 1, "{errs:?}");
        let e = &errs[0];
        assert!(
            matches!(
                e,
                LogError::CrcMismatch {
                    section: CrcSection::Chunk,
                    ..
                }
            ),
            "{e}"
        );
        assert!(!e.is_fatal());
        assert!(e.to_string().contains("corrupt.mcap"), "{e}");
        assert!(e.offset().unwrap() < pos as u64);
        // The other chunks' messages all came through, and no damaged one.
        assert!(msgs.len() < full.len() && msgs.len() > full.len() - 20);
        assert!(msgs.iter().all(|m| full.contains(m)));
        assert!(msgs.iter().any(|m| m.2 == br#"{"voltage_v":1059.0}"#));
        assert!(!msgs.iter().any(|m| m.2 == br#"{"voltage_v":1092.0}"#));
    }
}

#[test]
fn a_message_on_an_unknown_channel_is_reported_and_skipped() {
    let mut bytes = small_file(ChunkCompression::None);
    let json = find(&bytes, br#"{"voltage_v":1030.0}"#);
    // The message header (channel id, sequence, log time, publish time) precedes the data.
    bytes[json - 22..json - 20].copy_from_slice(&0x7777u16.to_le_bytes());
    // Mark the chunk's CRC as not computed (opcode, length, start and end time, uncompressed
    // size precede it), so the damage passes the CRC check like a writer bug would.
    let chunk = record_containing(&bytes, json);
    assert_eq!(bytes[chunk], 0x06);
    bytes[chunk + 33..chunk + 37].fill(0);
    let dir = tempfile::tempdir().unwrap();
    let path = put(dir.path(), "channel.mcap", &bytes);
    let mut r = LogReader::open(&path).unwrap();
    let (msgs, errs) = read_lenient(&mut r);
    assert_eq!(msgs.len(), 69);
    assert_eq!(errs.len(), 1);
    let e = &errs[0];
    assert!(matches!(
        e,
        LogError::UnknownChannel {
            channel_id: 0x7777,
            log_time_ns: 40_000_000,
            ..
        }
    ));
    assert!(!e.is_fatal());
    let text = e.to_string();
    assert!(
        text.contains("channel.mcap") && text.contains("40000000 ns"),
        "{text}"
    );
}

#[test]
fn a_chunk_index_pointing_elsewhere_is_a_bad_chunk() {
    let bytes = small_file(ChunkCompression::Zstd { level: 3 });
    let dir = tempfile::tempdir().unwrap();
    let full = read_all(
        &put(dir.path(), "full.mcap", &bytes),
        ReadOptions::default(),
    )
    .unwrap();
    // Find the last chunk index record (opcode 0x08) in the summary (the first chunks may hold
    // only schema and channel records) and move its chunk offset by one byte. Without CRC
    // checks the summary is trusted as far as it is consistent.
    let summary = data_end_pos(&bytes) + 13;
    let mut bad = bytes.clone();
    let mut at = summary;
    let mut last_index = None;
    while bad[at] != 0x02 {
        if bad[at] == 0x08 {
            last_index = Some(at);
        }
        at += 9 + u64::from_le_bytes(bad[at + 1..at + 9].try_into().unwrap()) as usize;
    }
    let off = last_index.unwrap() + 9 + 16;
    let v = u64::from_le_bytes(bad[off..off + 8].try_into().unwrap());
    bad[off..off + 8].copy_from_slice(&(v + 1).to_le_bytes());
    let path = put(dir.path(), "index.mcap", &bad);
    let mut r = LogReader::open(&path).unwrap();
    let (msgs, errs) = read_lenient(&mut r);
    assert_eq!(errs.len(), 1, "{errs:?}");
    assert!(matches!(errs[0], LogError::BadChunk { .. }), "{}", errs[0]);
    assert!(!errs[0].is_fatal());
    assert!(
        !msgs.is_empty() && msgs.len() < full.len(),
        "{} of {}",
        msgs.len(),
        full.len()
    );
    // With validation the summary CRC rejects the file at open.
    let e = LogReader::open_with(&path, validating()).unwrap_err();
    assert!(matches!(
        e,
        LogError::CrcMismatch {
            section: CrcSection::Summary,
            ..
        }
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Random damage and cuts: the reader never panics, always ends, and a fatal error is
    /// always the last item (read_lenient checks that).
    #[test]
    fn random_damage_never_panics(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
        cut in any::<prop::sample::Index>(),
        do_cut in any::<bool>(),
        validate in any::<bool>(),
        zstd in any::<bool>(),
    ) {
        let compression = if zstd {
            ChunkCompression::Zstd { level: 3 }
        } else {
            ChunkCompression::None
        };
        let mut bytes = small_file(compression);
        for (i, v) in flips {
            let i = i.index(bytes.len());
            bytes[i] = v;
        }
        if do_cut {
            bytes.truncate(cut.index(bytes.len()));
        }
        let dir = tempfile::tempdir().unwrap();
        let path = put(dir.path(), "fuzz.mcap", &bytes);
        let options = ReadOptions { validate_crcs: validate, ..ReadOptions::default() };
        match LogReader::open_with(&path, options) {
            Ok(mut r) => {
                let (msgs, errs) = read_lenient(&mut r);
                for (_, _, data) in &msgs {
                    let _ = json_field_f64(data, "voltage_v");
                }
                for e in &errs {
                    prop_assert!(e.to_string().contains("fuzz.mcap"));
                }
            }
            Err(e) => {
                prop_assert!(e.is_fatal());
                prop_assert!(e.to_string().contains("fuzz.mcap"));
            }
        }
    }
}
