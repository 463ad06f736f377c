//! The A/B slot store: round trip, alternation, fallback to the other slot for every kind of
//! damage to the current one, first start, configuration changes, and an event memory image
//! restored through the store under a changed DTC table.

use std::fs;
use std::path::{Path, PathBuf};

use fdd_diagnostics::dtc::{
    DebounceConfig, DropReason, Dtc, EventConfig, EventMemory, EventMemoryConfig, MemoryImage,
    ReportContext,
};
use fdd_diagnostics::{TestResult, Verdict};
use fdd_monitor::persist::{
    config_hash, unpack_sections, ConfigHasher, PersistError, SectionWriter, SlotId, SlotProblem,
    SlotStore, MAX_SLOT_BYTES, SLOT_HEADER_BYTES, SLOT_OVERHEAD_BYTES,
};

const HASH: u64 = 0x1234_5678_9ABC_DEF0;

fn base(dir: &Path) -> PathBuf {
    dir.join("nv").join("dtc")
}

fn open(dir: &Path) -> (SlotStore, fdd_monitor::persist::Recovered) {
    SlotStore::open(base(dir), HASH).expect("open")
}

fn payload(n: usize, tag: u8) -> Vec<u8> {
    (0..n).map(|i| (i as u8).wrapping_mul(31) ^ tag).collect()
}

#[test]
fn first_start_then_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, rec) = open(tmp.path());
    assert!(rec.is_first_start());
    assert_eq!(rec.notes.len(), 2);
    assert!(rec.notes.iter().all(|n| n.problem == SlotProblem::Missing));
    assert!(
        rec.notes[0].to_string().contains("dtc.a"),
        "{}",
        rec.notes[0]
    );
    assert!(tmp.path().join("nv").is_dir(), "the directory is created");
    assert_eq!(store.next_seq(), 1);

    let w = store.write(b"hello").unwrap();
    assert_eq!((w.slot, w.seq), (SlotId::A, 1));
    assert_eq!(
        fs::metadata(store.path(SlotId::A)).unwrap().len(),
        (SLOT_OVERHEAD_BYTES + 5) as u64
    );
    let (_, rec) = open(tmp.path());
    let cur = rec.current.as_ref().unwrap();
    assert_eq!((cur.slot, cur.seq), (SlotId::A, 1));
    assert_eq!(cur.payload, b"hello");
    assert!(cur.config_matches);
    assert_eq!(cur.path, tmp.path().join("nv/dtc.a"));
    assert_eq!(rec.notes.len(), 1);
    assert_eq!(rec.notes[0].slot, SlotId::B);

    // An empty payload is a valid slot too.
    let (mut store, _) = open(tmp.path());
    store.write(&[]).unwrap();
    let (_, rec) = open(tmp.path());
    assert_eq!(rec.payload(), Some(&[][..]));
    assert_eq!(rec.current.unwrap().seq, 2);
}

#[test]
fn writes_alternate_between_the_slots_and_never_touch_the_current_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, _) = open(tmp.path());
    for k in 1..=7u64 {
        let current_before = store
            .current()
            .map(|(s, _)| (s, fs::read(store.path(s)).unwrap()));
        let w = store.write(&payload(100 + k as usize, k as u8)).unwrap();
        assert_eq!(w.seq, k);
        assert_eq!(w.slot, if k % 2 == 1 { SlotId::A } else { SlotId::B });
        assert_eq!(store.current(), Some((w.slot, k)));
        if let Some((s, bytes)) = current_before {
            assert_ne!(s, w.slot);
            assert_eq!(
                fs::read(store.path(s)).unwrap(),
                bytes,
                "previous slot untouched"
            );
            // It still holds write k - 1.
            assert_eq!(bytes[6..14], (k - 1).to_le_bytes());
        }
        // A restart sees the latest write; a store reopened continues the sequence.
        let (reopened, rec) = open(tmp.path());
        let cur = rec.current.unwrap();
        assert_eq!((cur.slot, cur.seq), (w.slot, k));
        assert_eq!(cur.payload, payload(100 + k as usize, k as u8));
        if k >= 2 {
            assert!(rec.notes.is_empty(), "{:?}", rec.notes);
        }
        assert_eq!(reopened.next_seq(), k + 1);
    }
}

/// Two writes: A holds seq 1, B (current) seq 2. Returns B's bytes.
fn two_writes(dir: &Path) -> (Vec<u8>, Vec<u8>) {
    let (mut store, _) = open(dir);
    store.write(&payload(64, 1)).unwrap();
    store.write(&payload(300, 2)).unwrap();
    let b = fs::read(store.path(SlotId::B)).unwrap();
    (payload(64, 1), b)
}

/// Opens and checks that slot A (seq 1, `older`) was taken because B is invalid; returns B's
/// problem.
fn falls_back(dir: &Path, older: &[u8]) -> SlotProblem {
    let (_, rec) = open(dir);
    let cur = rec.current.as_ref().expect("slot A is still valid");
    assert_eq!((cur.slot, cur.seq), (SlotId::A, 1));
    assert_eq!(cur.payload, older);
    assert_eq!(rec.notes.len(), 1, "{:?}", rec.notes);
    assert_eq!(rec.notes[0].slot, SlotId::B);
    assert!(rec.notes[0].path.ends_with("dtc.b"));
    rec.notes[0].problem.clone()
}

#[test]
fn any_damaged_byte_of_the_current_slot_falls_back_to_the_other() {
    let tmp = tempfile::tempdir().unwrap();
    let (older, good) = two_writes(tmp.path());
    let b_path = base(tmp.path()).with_extension("b");
    let n = good.len();
    let mut counts = [0usize; 5];
    // Every byte: header, payload, CRC; a single-bit flip and a whole-byte flip.
    for i in 0..n {
        for mask in [0x01u8, 0xFF] {
            let mut bad = good.clone();
            bad[i] ^= mask;
            fs::write(&b_path, &bad).unwrap();
            let problem = falls_back(tmp.path(), &older);
            let k = match (i, &problem) {
                (0..=3, SlotProblem::BadMagic { .. }) => 0,
                (4..=5, SlotProblem::UnsupportedVersion(_)) => 1,
                (22..=25, SlotProblem::Torn { .. } | SlotProblem::TrailingBytes { .. }) => 2,
                (6..=21, SlotProblem::BadCrc { .. }) => 3,
                (_, SlotProblem::BadCrc { .. }) if i >= SLOT_HEADER_BYTES => 4,
                _ => panic!("byte {i} ^ {mask:#x}: unexpected {problem:?}"),
            };
            counts[k] += 1;
        }
    }
    assert_eq!(counts, [8, 4, 8, 32, 2 * (n - SLOT_HEADER_BYTES)]);

    // Truncated at several lengths (a write cut short) and one byte too long.
    for len in [0, 1, 4, 13, 25, 26, 29, 30, 31, 100, n / 2, n - 4, n - 1] {
        fs::write(&b_path, &good[..len]).unwrap();
        let problem = falls_back(tmp.path(), &older);
        let want_short = len < SLOT_OVERHEAD_BYTES;
        match problem {
            SlotProblem::Short { len: l } if want_short => assert_eq!(l, len as u64),
            SlotProblem::Torn { expected, len: l } if !want_short => {
                assert_eq!((expected, l), (n as u64, len as u64));
            }
            p => panic!("cut at {len}: unexpected {p:?}"),
        }
    }
    let mut long = good.clone();
    long.push(0);
    fs::write(&b_path, &long).unwrap();
    assert!(matches!(
        falls_back(tmp.path(), &older),
        SlotProblem::TrailingBytes { .. }
    ));

    // After the fallback the next write goes to the damaged slot, not to the current one.
    let a_before = fs::read(base(tmp.path()).with_extension("a")).unwrap();
    let (mut store, _) = open(tmp.path());
    let w = store.write(b"repaired").unwrap();
    assert_eq!((w.slot, w.seq), (SlotId::B, 2));
    assert_eq!(
        fs::read(base(tmp.path()).with_extension("a")).unwrap(),
        a_before
    );
    let (_, rec) = open(tmp.path());
    assert_eq!(rec.payload(), Some(&b"repaired"[..]));
    assert!(rec.notes.is_empty());
}

#[test]
fn both_slots_damaged_is_a_first_start_with_a_note_per_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, good) = two_writes(tmp.path());
    let a = base(tmp.path()).with_extension("a");
    let b = base(tmp.path()).with_extension("b");
    fs::write(&a, &good[..10]).unwrap();
    let mut bad = good.clone();
    bad[SLOT_HEADER_BYTES + 7] ^= 0x40;
    fs::write(&b, &bad).unwrap();
    let (mut store, rec) = open(tmp.path());
    assert!(rec.is_first_start());
    let notes: Vec<String> = rec.notes.iter().map(|n| n.to_string()).collect();
    assert_eq!(notes.len(), 2);
    assert!(
        notes[0].contains("dtc.a") && notes[0].contains("10 bytes"),
        "{notes:?}"
    );
    assert!(
        notes[1].contains("dtc.b") && notes[1].contains("CRC mismatch"),
        "{notes:?}"
    );
    let w = store.write(b"fresh").unwrap();
    assert_eq!((w.slot, w.seq), (SlotId::A, 1));
}

#[test]
fn a_changed_configuration_hash_is_reported_and_the_next_write_carries_the_new_one() {
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, _) = SlotStore::open(base(tmp.path()), 1).unwrap();
    store.write(b"old config").unwrap();
    let (mut store, rec) = SlotStore::open(base(tmp.path()), 2).unwrap();
    let cur = rec.current.unwrap();
    assert!(!cur.config_matches);
    assert_eq!(cur.config_hash, 1);
    assert_eq!(cur.payload, b"old config");
    store.write(b"new config").unwrap();
    let (_, rec) = SlotStore::open(base(tmp.path()), 2).unwrap();
    let cur = rec.current.unwrap();
    assert!(cur.config_matches);
    assert_eq!((cur.seq, cur.config_hash), (2, 2));
}

#[test]
fn odd_files_are_notes_and_io_errors_name_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, _) = open(tmp.path());
    store.write(b"x").unwrap();
    // A huge (sparse) B is not read.
    let b = base(tmp.path()).with_extension("b");
    fs::File::create(&b)
        .unwrap()
        .set_len(MAX_SLOT_BYTES + 1)
        .unwrap();
    let (_, rec) = open(tmp.path());
    assert_eq!(
        rec.notes[0].problem,
        SlotProblem::TooLarge {
            len: MAX_SLOT_BYTES + 1
        }
    );
    assert_eq!(rec.payload(), Some(&b"x"[..]));
    // Equal sequence numbers (files copied by hand): A is taken, B noted.
    fs::copy(base(tmp.path()).with_extension("a"), &b).unwrap();
    let (_, rec) = open(tmp.path());
    assert_eq!(rec.current.unwrap().slot, SlotId::A);
    assert_eq!(rec.notes[0].problem, SlotProblem::SameSeq(1));

    // A directory where slot A should be: open notes it, write fails naming it.
    let tmp = tempfile::tempdir().unwrap();
    fs::create_dir_all(base(tmp.path()).with_extension("a")).unwrap();
    let (mut store, rec) = open(tmp.path());
    assert!(rec.is_first_start());
    assert!(
        matches!(rec.notes[0].problem, SlotProblem::Unreadable { .. }),
        "{:?}",
        rec.notes
    );
    let e = store.write(b"x").unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, PersistError::Io { .. })
            && msg.contains("dtc.a")
            && msg.contains("open for writing"),
        "{msg}"
    );
    assert_eq!(store.current(), None);

    // The base needs a file name; a directory that cannot be created is an error.
    assert!(matches!(
        SlotStore::open("/", HASH),
        Err(PersistError::BadBase(_))
    ));
    let file = tmp.path().join("plain_file");
    fs::write(&file, b"").unwrap();
    let e = SlotStore::open(file.join("dtc"), HASH).unwrap_err();
    assert!(e.to_string().contains("create directory"), "{e}");
}

#[test]
fn the_config_hash_is_fnv1a_over_lines() {
    // Published FNV-1a 64 vectors, and this module's line convention.
    assert_eq!(ConfigHasher::new().finish(), 0xcbf2_9ce4_8422_2325);
    assert_eq!(config_hash(["a"]), 0x089b_dc07_b544_e7b2);
    let dtc = |s: &str| s.parse::<Dtc>().unwrap();
    let mut h = ConfigHasher::new();
    h.event("intake", "map_perf", dtc("P0106-64"))
        .event("throttle", "tps_high", dtc("P0123-1C"));
    assert_eq!(h.finish(), 0x3f47_a01c_00b4_f208);
    assert_eq!(
        h.finish(),
        config_hash(["intake/map_perf/P0106-64", "throttle/tps_high/P0123-1C"])
    );
    assert_ne!(
        config_hash(["intake/map_perf/P0106-64"]),
        config_hash(["intake/map_perf/P0106-00"])
    );
}

#[test]
fn sections_round_trip_and_bad_input_is_an_error() {
    let mut payload = vec![9u8; 2];
    let mut w = SectionWriter::new(&mut payload);
    w.section("intake", |b| b.extend_from_slice(&[1, 2, 3]))
        .unwrap();
    w.section("", |_| {}).unwrap();
    w.section("throttle", |b| b.extend_from_slice(&[4; 300]))
        .unwrap();
    assert!(w.section(&"x".repeat(70_000), |_| {}).is_err());
    w.finish();
    let got = unpack_sections(&payload[2..]).unwrap();
    assert_eq!(
        got,
        [
            ("intake", &[1u8, 2, 3][..]),
            ("", &[][..]),
            ("throttle", &[4u8; 300][..])
        ]
    );
    let bytes = &payload[2..];
    for n in 0..bytes.len() {
        assert!(unpack_sections(&bytes[..n]).is_err(), "cut at {n}");
    }
    let mut long = bytes.to_vec();
    long.push(0);
    let e = unpack_sections(&long).unwrap_err();
    assert_eq!(e.offset, bytes.len());
    // A huge count in a short input.
    assert!(unpack_sections(&[0xFF, 0xFF, 0xFF, 0xFF]).is_err());
    // A fill function that eats what it did not write is an error, not a panic.
    let mut other = Vec::new();
    let mut w = SectionWriter::new(&mut other);
    assert_eq!(
        w.section("bad", |b| b.truncate(1)),
        Err(fdd_monitor::persist::SectionWriteError::BufferShrunk)
    );
    w.finish();
}

// ------------------------------------------------------------------------------ with images

fn event(name: &str, dtc: &str, priority: u8) -> EventConfig {
    let mut e = EventConfig::new(name, dtc, priority);
    e.debounce = DebounceConfig::MonitorInternal;
    e
}

fn hash_of(monitor: &str, cfg: &EventMemoryConfig) -> u64 {
    let mut h = ConfigHasher::new();
    for e in &cfg.events {
        h.event(monitor, &e.name, e.dtc.parse().unwrap());
    }
    h.finish()
}

#[test]
fn an_image_restored_under_a_changed_dtc_table_keeps_what_matches() {
    let old = EventMemoryConfig {
        capacity: 4,
        events: vec![
            event("map_perf", "P0106-64", 2),
            event("egr_low", "P0401-00", 3),
            event("leak", "P2279-7A", 4),
        ],
    };
    let mut mem = EventMemory::new(&old).unwrap();
    let failed = TestResult {
        value: 9.0,
        min: 0.0,
        max: 5.0,
        verdict: Verdict::Failed,
    };
    for c in 0..2 {
        let t = 100.0 + c as f64;
        mem.start_operation_cycle(t, |_| {}).unwrap();
        for name in ["map_perf", "egr_low"] {
            let id = mem.event_id(name).unwrap();
            mem.report(id, &failed, &ReportContext::at(t + 0.5), |_| {})
                .unwrap();
        }
        mem.end_operation_cycle(t + 0.9, |_| {}).unwrap();
    }
    let mut p = Vec::new();
    let mut w = SectionWriter::new(&mut p);
    w.section("intake", |b| mem.encode_image(b)).unwrap();
    w.finish();
    let tmp = tempfile::tempdir().unwrap();
    let (mut store, _) = SlotStore::open(base(tmp.path()), hash_of("intake", &old)).unwrap();
    store.write(&p).unwrap();

    // New software: egr_low got another FTB, leak was removed, a new event was added.
    let new = EventMemoryConfig {
        capacity: 4,
        events: vec![
            event("map_perf", "P0106-64", 2),
            event("egr_low", "P0401-92", 3),
            event("overboost", "P0234-00", 2),
        ],
    };
    let (_, rec) = SlotStore::open(base(tmp.path()), hash_of("intake", &new)).unwrap();
    let cur = rec.current.unwrap();
    assert!(!cur.config_matches, "the DTC table changed");
    let sections = unpack_sections(&cur.payload).unwrap();
    assert_eq!(sections.len(), 1);
    assert_eq!(sections[0].0, "intake");
    let image = MemoryImage::decode(sections[0].1).unwrap();
    let mut fresh = EventMemory::new(&new).unwrap();
    let report = fresh.restore(&image);
    let dropped: Vec<_> = report
        .dropped
        .iter()
        .map(|d| (d.name.as_str(), d.reason.clone()))
        .collect();
    assert_eq!(
        dropped,
        [
            (
                "egr_low",
                DropReason::DtcChanged {
                    configured: "P0401-92".parse().unwrap()
                }
            ),
            ("leak", DropReason::NotConfigured),
        ]
    );
    assert_eq!(report.restored_events, 1);
    assert_eq!(report.restored_entries, 1);
    let id = |n: &str| fresh.event_id(n).unwrap();
    assert_eq!(fresh.status(id("map_perf")).byte(), 0xAF);
    assert!(fresh.entry(id("map_perf")).is_some());
    assert_eq!(fresh.status(id("egr_low")).byte(), 0x50);
    assert_eq!(fresh.status(id("overboost")).byte(), 0x50);
    // The clock restarted at power-up.
    let map_perf = id("map_perf");
    fresh.start_operation_cycle(0.0, |_| {}).unwrap();
    assert_eq!(fresh.status(map_perf).byte(), 0xED);
}
