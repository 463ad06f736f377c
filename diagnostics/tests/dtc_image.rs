//! The event memory image: encoding round trips (proptest), hostile input never panics,
//! decoding errors name the byte offset, and restore brings back what the configuration still
//! has while listing what it dropped.

use fdd_diagnostics::dtc::{
    DebounceConfig, DropReason, Dtc, DtcGroup, DtcStatus, EntryImage, EventConfig, EventImage,
    EventMemory, EventMemoryConfig, ImageErrorKind, MemoryImage, ReportContext,
};
use fdd_diagnostics::{TestResult, Verdict};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

fn result(verdict: Verdict) -> TestResult {
    TestResult {
        value: 1.0,
        min: 0.0,
        max: 5.0,
        verdict,
    }
}

fn event(name: &str, dtc: &str, priority: u8, ff: &[&str]) -> EventConfig {
    let mut e = EventConfig::new(name, dtc, priority);
    e.debounce = DebounceConfig::MonitorInternal;
    e.freeze_frame = ff.iter().map(|s| s.to_string()).collect();
    e
}

fn config() -> EventMemoryConfig {
    EventMemoryConfig {
        capacity: 3,
        events: vec![
            event("tps_high", "P0123-1C", 2, &["tps_v", "rpm"]),
            event("map_perf", "P0106-64", 3, &["map_kpa"]),
            event("egr_flow", "P0401-00", 4, &[]),
            event("leak", "P2279-7A", 5, &["map_kpa", "maf_gps"]),
            event("wss_lf", "C0035-00", 6, &["v_kph"]),
        ],
    }
}

/// Drives `mem` through `cycles` operation cycles starting at `t0` s with seeded random
/// verdicts (failure-prone events), returning the time after the last cycle.
fn drive(mem: &mut EventMemory, seed: u64, cycles: usize, t0: f64) -> f64 {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut t = t0;
    let ids: Vec<_> = mem.event_ids().collect();
    for _ in 0..cycles {
        mem.start_operation_cycle(t, |_| {}).unwrap();
        for _ in 0..5 {
            for &id in &ids {
                t += 0.01;
                let v = match rng.random_range(0..10) {
                    0..=2 => Verdict::Failed,
                    3..=7 => Verdict::Passed,
                    _ => Verdict::NotTested,
                };
                // Some reports carry their freeze frame, some do not (stored as missing).
                let nff = config().events[id.index()].freeze_frame.len();
                let vals: Vec<f64> = (0..nff).map(|_| rng.random_range(0.0..100.0)).collect();
                let ctx = ReportContext::at(t);
                let ctx = if rng.random_bool(0.7) {
                    ctx.with_freeze_frame(&vals)
                } else {
                    ctx
                };
                mem.report(id, &result(v), &ctx, |_| {}).unwrap();
            }
        }
        if rng.random_range(0..25) == 0 {
            let dtc = mem.dtc(ids[rng.random_range(0..ids.len())]);
            mem.clear_dtc(DtcGroup::Dtc(dtc), t, |_| {}).unwrap();
        }
        t += 1.0;
        mem.end_operation_cycle(t, |_| {}).unwrap();
    }
    t
}

/// Bitwise equality (NaN freeze-frame values compare equal to themselves).
fn same(a: &MemoryImage, b: &MemoryImage) -> bool {
    let (mut x, mut y) = (Vec::new(), Vec::new());
    a.encode(&mut x);
    b.encode(&mut y);
    x == y
}

fn infos(mem: &EventMemory) -> Vec<String> {
    mem.event_ids()
        .map(|id| {
            let mut i = mem.event_info(id);
            i.fdc = 0;
            format!("{i:?} {:?}", mem.entry(id).map(|e| format!("{e:?}")))
        })
        .collect()
}

#[test]
fn a_real_memory_round_trips_and_restores_exactly() {
    let mut mem = EventMemory::new(&config()).unwrap();
    let t = drive(&mut mem, 7, 30, 0.0);
    assert!(mem.entries_used() > 0);
    assert!(mem.event_ids().any(|id| mem.status(id).confirmed()));
    let image = mem.image();
    let mut bytes = Vec::new();
    image.encode(&mut bytes);
    let mut direct = Vec::new();
    mem.encode_image(&mut direct);
    assert_eq!(
        bytes, direct,
        "encode_image writes what image().encode writes"
    );
    let back = MemoryImage::decode(&bytes).unwrap();
    assert!(same(&back, &image));

    let mut fresh = EventMemory::new(&config()).unwrap();
    let report = fresh.restore(&back);
    assert!(report.nothing_dropped(), "{report:?}");
    assert_eq!(report.restored_events, 5);
    assert_eq!(report.restored_entries, mem.entries_used());
    assert!(report.not_in_image.is_empty());
    assert_eq!(infos(&fresh), infos(&mem));
    assert_eq!(fresh.overflow(), mem.overflow());
    assert_eq!(fresh.overflow_count(), mem.overflow_count());
    assert_eq!(
        fresh.operation_cycles_started(),
        mem.operation_cycles_started()
    );
    assert!(!fresh.operation_cycle_active());
    assert!(same(&fresh.image(), &image));

    // The host clock restarts at power-up: t = 0 is accepted after an image taken at t > 30 s.
    assert!(t > 30.0);
    fresh.start_operation_cycle(0.0, |_| {}).unwrap();

    fresh.end_operation_cycle(0.5, |_| {}).unwrap();
}

#[test]
fn a_restored_memory_continues_like_the_original() {
    for seed in 0..20 {
        let mut a = EventMemory::new(&config()).unwrap();
        let t = drive(&mut a, seed, 15, 0.0);
        let mut bytes = Vec::new();
        a.encode_image(&mut bytes);
        let mut b = EventMemory::new(&config()).unwrap();
        let r = b.restore(&MemoryImage::decode(&bytes).unwrap());
        assert!(r.nothing_dropped());
        // Same reports, the restored one on a clock that restarted at 0.
        drive(&mut a, seed + 1000, 15, t);
        drive(&mut b, seed + 1000, 15, 0.0);
        let strip = |m: &EventMemory| {
            let mut i = m.image();
            for e in &mut i.events {
                if let Some(x) = &mut e.entry {
                    x.stored_time_s = 0.0;
                }
            }
            i
        };
        assert!(same(&strip(&a), &strip(&b)), "seed {seed}");
    }
}

#[test]
fn a_confirmed_status_is_restored_as_persisted_and_the_cycle_start_applies() {
    let mut mem = EventMemory::new(&config()).unwrap();
    let id = mem.event_id("tps_high").unwrap();
    for c in 0..2 {
        let t = 10.0 * c as f64;
        mem.start_operation_cycle(t, |_| {}).unwrap();
        let ff = [4.9, 2500.0];
        let ctx = ReportContext::at(t + 1.0).with_freeze_frame(&ff);
        mem.report(id, &result(Verdict::Failed), &ctx, |_| {})
            .unwrap();
        mem.end_operation_cycle(t + 2.0, |_| {}).unwrap();
    }
    assert_eq!(mem.status(id).byte(), 0xAF);
    let mut fresh = EventMemory::new(&config()).unwrap();
    fresh.restore(&mem.image());
    assert_eq!(fresh.status(id).byte(), 0xAF);
    let entry = fresh.entry(id).unwrap();
    assert_eq!(
        entry.freeze_frame().collect::<Vec<_>>(),
        [("tps_v", 4.9), ("rpm", 2500.0)]
    );
    assert_eq!(entry.stored_time_s, 1.0);
    fresh.start_operation_cycle(0.0, |_| {}).unwrap();
    // testFailedThisOperationCycle cleared, testNotCompletedThisOperationCycle set.
    assert_eq!(fresh.status(id).byte(), 0xED);
}

#[test]
fn restore_with_a_changed_configuration_keeps_what_matches_and_lists_the_rest() {
    let mut mem = EventMemory::new(&config()).unwrap();
    // Every event fails in two cycles: all confirmed, the 3 highest priorities stored.
    let ids: Vec<_> = mem.event_ids().collect();
    for c in 0..2 {
        let t = c as f64 * 10.0;
        mem.start_operation_cycle(t, |_| {}).unwrap();
        for (j, &id) in ids.iter().enumerate() {
            let n = config().events[j].freeze_frame.len();
            let ff: Vec<f64> = (0..n).map(|k| (10 * j + k) as f64).collect();
            let ctx = ReportContext::at(t + 1.0).with_freeze_frame(&ff);
            mem.report(id, &result(Verdict::Failed), &ctx, |_| {})
                .unwrap();
        }
        mem.end_operation_cycle(t + 2.0, |_| {}).unwrap();
    }
    let mut image = mem.image();
    assert_eq!(image.events.iter().filter(|e| e.entry.is_some()).count(), 3);
    // Give "leak" and "wss_lf" entries too, as a bigger memory would have held them.
    for (name, seq) in [("leak", 10), ("wss_lf", 11)] {
        let e = image.events.iter_mut().find(|e| e.name == name).unwrap();
        e.entry = Some(EntryImage {
            stored_seq: seq,
            stored_time_s: 3.0,
            freeze_frame: config()
                .events
                .iter()
                .find(|c| c.name == name)
                .unwrap()
                .freeze_frame
                .iter()
                .map(|s| (s.clone(), 1.5))
                .collect(),
        });
    }
    // A duplicate record.
    let dup = image.events[0].clone();
    image.events.push(dup);

    // The new configuration: map_perf's DTC changed, egr_flow removed, tps_high's freeze frame
    // gained a signal, a new event, capacity 2.
    let mut cfg = config();
    cfg.capacity = 2;
    cfg.events[1].dtc = "P0106-00".into();
    cfg.events.remove(2);
    cfg.events[0].freeze_frame.push("iat_c".into());
    cfg.events.push(event("new_one", "P0299-00", 1, &[]));
    let mut fresh = EventMemory::new(&cfg).unwrap();
    let report = fresh.restore(&image);
    let reasons: Vec<(String, String)> = report
        .dropped
        .iter()
        .map(|d| {
            let r = match &d.reason {
                DropReason::NotConfigured => "not_configured".to_string(),
                DropReason::DtcChanged { configured } => format!("dtc_changed {configured}"),
                DropReason::DuplicateInImage => "duplicate".into(),
                DropReason::FreezeFrameChanged { persisted } => format!("ff {persisted:?}"),
                DropReason::CapacityExceeded { capacity } => format!("capacity {capacity}"),
            };
            (d.name.clone(), r)
        })
        .collect();
    let want: Vec<(String, String)> = [
        ("tps_high", r#"ff ["tps_v", "rpm"]"#),
        ("map_perf", "dtc_changed P0106-00"),
        ("egr_flow", "not_configured"),
        ("tps_high", "duplicate"),
        // tps_high (priority 2), leak (5, seq 10), wss_lf (6, seq 11): tps_high and leak stay.
        ("wss_lf", "capacity 2"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    assert_eq!(reasons, want);
    for d in &report.dropped {
        // Every reason reads as a sentence naming the event and its DTC.
        let s = d.to_string();
        assert!(s.contains(&d.name) && s.contains(&d.dtc.to_string()), "{s}");
    }
    assert_eq!(report.restored_events, 3, "tps_high, leak, wss_lf");
    assert_eq!(report.restored_entries, 2);
    let names: Vec<_> = report
        .not_in_image
        .iter()
        .map(|&id| fresh.name(id).to_string())
        .collect();
    assert_eq!(names, ["map_perf", "new_one"]);

    let id = |n: &str| fresh.event_id(n).unwrap();
    // tps_high: status and entry restored, freeze-frame values missing.
    assert_eq!(fresh.status(id("tps_high")).byte(), 0xAF);
    let e = fresh.entry(id("tps_high")).unwrap();
    assert_eq!(e.freeze_frame().count(), 3);
    assert!(e.freeze_frame().all(|(_, v)| v.is_nan()));
    // leak: entry with values.
    let e = fresh.entry(id("leak")).unwrap();
    assert_eq!(
        e.freeze_frame().collect::<Vec<_>>(),
        [("map_kpa", 1.5), ("maf_gps", 1.5)]
    );
    // wss_lf: status and counters kept, entry dropped as an overflow.
    assert_eq!(fresh.status(id("wss_lf")).byte(), 0xAF);
    assert!(fresh.entry(id("wss_lf")).is_none());
    assert!(fresh.overflow());
    assert_eq!(fresh.overflow_count(), mem.overflow_count() + 1);
    // Dropped and new events start as after ClearDTC.
    assert_eq!(fresh.status(id("map_perf")), DtcStatus::AFTER_CLEAR);
    assert_eq!(fresh.status(id("new_one")), DtcStatus::AFTER_CLEAR);
    // New entries come after the restored ones.
    assert!(fresh.image().next_seq > 10);
}

// ------------------------------------------------------------------------------ encoding

fn sample_bytes() -> Vec<u8> {
    let mut mem = EventMemory::new(&config()).unwrap();
    drive(&mut mem, 3, 12, 0.0);
    let mut b = Vec::new();
    mem.encode_image(&mut b);
    b
}

#[test]
fn decoding_errors_name_what_and_where() {
    let good = sample_bytes();
    assert!(MemoryImage::decode(&good).is_ok());

    let mut b = good.clone();
    b[1] = b'X';
    let e = MemoryImage::decode(&b).unwrap_err();
    assert!(matches!(e.kind, ImageErrorKind::BadMagic { .. }));
    assert_eq!(e.offset, 0);

    let mut b = good.clone();
    b[4] = 9;
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.kind, ImageErrorKind::UnsupportedVersion(9));
    assert_eq!(e.offset, 4);
    assert!(e.to_string().contains("version 9"), "{e}");

    let mut b = good.clone();
    b[22] = 2; // overflow flag
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.offset, 22);
    assert!(matches!(
        e.kind,
        ImageErrorKind::InvalidFlag {
            field: "overflow flag",
            value: 2
        }
    ));

    let mut b = good.clone();
    b.push(0);
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.kind, ImageErrorKind::TrailingBytes(1));
    assert_eq!(e.offset, good.len());

    // The first event's DTC follows the 27-byte header, the count, the name length and "tps_high".
    let mut b = good.clone();
    b[37..41].copy_from_slice(&0x0100_0000u32.to_le_bytes());
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.kind, ImageErrorKind::DtcOutOfRange(0x0100_0000));
    assert_eq!((e.offset, e.event), (37, Some(0)));
    assert!(e.to_string().contains("at byte 37 (event record 0)"), "{e}");

    let mut b = good.clone();
    b[30] = 0xFF; // inside "tps_high"
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.offset, 29);
    assert!(matches!(e.kind, ImageErrorKind::InvalidUtf8 { .. }));

    // An event count the input cannot hold is refused before anything is allocated.
    let mut b = good[..27].to_vec();
    b.extend_from_slice(&[0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0x0F]);
    let e = MemoryImage::decode(&b).unwrap_err();
    assert_eq!(e.offset, 27);
    assert!(matches!(
        e.kind,
        ImageErrorKind::Truncated {
            field: "event count",
            ..
        }
    ));
    let mut b = good[..27].to_vec();
    b.extend_from_slice(&[0xFF; 11]);
    let e = MemoryImage::decode(&b).unwrap_err();
    assert!(matches!(e.kind, ImageErrorKind::BadVarint { .. }), "{e}");
}

#[test]
fn encode_image_into_a_large_enough_buffer_does_not_allocate() {
    let mut mem = EventMemory::new(&config()).unwrap();
    drive(&mut mem, 5, 10, 0.0);
    let mut buf = Vec::with_capacity(4096);
    let n = fdd_testkit::allocations_in(|| {
        for _ in 0..100 {
            buf.clear();
            mem.encode_image(&mut buf);
        }
    });
    assert_eq!(n, 0);
    assert!(MemoryImage::decode(&buf).is_ok());
}

#[test]
fn every_truncation_is_an_error_at_or_before_the_cut() {
    let good = sample_bytes();
    for n in 0..good.len() {
        let e = MemoryImage::decode(&good[..n]).expect_err("truncated input");
        assert!(e.offset <= n, "cut at {n}: {e}");
    }
}

#[test]
fn random_bytes_and_byte_flips_never_panic() {
    let good = sample_bytes();
    let mut rng = Pcg64::seed_from_u64(1);
    let mut ok = 0;
    for _ in 0..20_000 {
        let mut b = good.clone();
        for _ in 0..rng.random_range(1..4) {
            let i = rng.random_range(0..b.len());
            b[i] = rng.random();
        }
        if let Ok(img) = MemoryImage::decode(&b) {
            ok += 1;
            // Whatever decodes re-encodes to the same bytes.
            let mut again = Vec::new();
            img.encode(&mut again);
            assert_eq!(again, b);
        }
    }
    assert!(ok > 0, "flips of counters and values decode");
    for _ in 0..20_000 {
        let n = rng.random_range(0..200);
        let mut b: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        if rng.random_bool(0.5) && b.len() >= 6 {
            b[..4].copy_from_slice(b"FDEM");
            b[4..6].copy_from_slice(&1u16.to_le_bytes());
        }
        let _ = MemoryImage::decode(&b);
    }
}

fn arb_name() -> impl Strategy<Value = String> {
    prop_oneof![
        "[a-z_]{1,12}",
        any::<String>(),
        proptest::collection::vec(any::<char>(), 0..200).prop_map(|v| v.into_iter().collect()),
    ]
}

fn arb_event() -> impl Strategy<Value = EventImage> {
    (
        arb_name(),
        0u32..=0xFF_FFFF,
        any::<[u8; 5]>(),
        any::<i8>(),
        proptest::option::of((
            any::<u64>(),
            any::<f64>(),
            proptest::collection::vec((arb_name(), any::<f64>()), 0..6),
        )),
    )
        .prop_map(|(name, dtc, c, max_fdc, entry)| EventImage {
            name,
            dtc: Dtc::from_u32(dtc).unwrap(),
            status: DtcStatus::from_byte(c[0]),
            failed_cycles: c[1],
            healing_cycles: c[2],
            aging_counter: c[3],
            occurrence_counter: c[4],
            max_fdc,
            entry: entry.map(|(stored_seq, stored_time_s, freeze_frame)| EntryImage {
                stored_seq,
                stored_time_s,
                freeze_frame,
            }),
        })
}

fn arb_image() -> impl Strategy<Value = MemoryImage> {
    (
        any::<u64>(),
        any::<bool>(),
        any::<u32>(),
        any::<u64>(),
        proptest::collection::vec(arb_event(), 0..20),
    )
        .prop_map(
            |(next_seq, overflow, overflow_count, operation_cycles_started, events)| MemoryImage {
                next_seq,
                overflow,
                overflow_count,
                operation_cycles_started,
                events,
            },
        )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn any_image_round_trips(image in arb_image()) {
        let mut bytes = vec![0xAA; 3];
        image.encode(&mut bytes);
        // encode appends.
        prop_assert_eq!(&bytes[..3], &[0xAA; 3]);
        let back = MemoryImage::decode(&bytes[3..]).unwrap();
        prop_assert!(same(&back, &image));
        let has_nan = image.events.iter().any(|e| e.entry.as_ref().is_some_and(|x| {
            x.stored_time_s.is_nan() || x.freeze_frame.iter().any(|(_, v)| v.is_nan())
        }));
        if !has_nan {
            prop_assert_eq!(back, image);
        }
    }

    #[test]
    fn any_truncation_or_flip_of_any_image_is_handled(
        image in arb_image(), cut in any::<prop::sample::Index>(), flip in any::<prop::sample::Index>(), byte in any::<u8>()
    ) {
        let mut bytes = Vec::new();
        image.encode(&mut bytes);
        let n = cut.index(bytes.len());
        prop_assert!(MemoryImage::decode(&bytes[..n]).is_err());
        let i = flip.index(bytes.len());
        bytes[i] = byte;
        let _ = MemoryImage::decode(&bytes);
    }
}
