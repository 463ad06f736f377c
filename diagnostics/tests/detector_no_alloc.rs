//! Detector steps allocate nothing on the heap.
//!
//! Onboard, a monitor step runs in a fixed time budget where a call into the allocator is not
//! acceptable, so every detector keeps fixed-size state (const-generic ring buffers) and its
//! step must not allocate. This binary installs a counting global allocator and runs many steps
//! of every detector, through fault-free data, faults, alarms and restarts, disabled steps, bad
//! input (NaN, out-of-order time stamps) and changes of degrees of freedom (which make the
//! chi-square window recompute its threshold), asserting that the number of allocations in the
//! measured section is exactly 0. Construction (the GLR computes its threshold with temporary
//! vectors) and random-number generation happen outside the section.
//!
//! Only allocations made by the measuring thread while a section is open are counted
//! (thread-local flag and counter), so tests in parallel threads cannot disturb each other; the
//! file has one test, which also checks that the counter does see an allocation.

use std::hint::black_box;

use fdd_diagnostics::detectors::{
    ChiSquareConfig, ChiSquareWindow, Cusum, CusumConfig, Detector, Glr, GlrConfig, RangeRateCheck,
    RangeRateConfig,
};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;

const STEPS: usize = 100_000;

#[global_allocator]
static GLOBAL: fdd_testkit::CountingAllocator = fdd_testkit::CountingAllocator;

use fdd_testkit::allocations_in;

#[test]
fn detector_steps_do_not_allocate() {
    // The counter counts.
    let counted = allocations_in(|| {
        black_box(vec![1_u8; 16]);
    });
    assert_eq!(
        counted, 1,
        "the counting allocator must see a Vec allocation"
    );

    let mut rng = Pcg64Mcg::seed_from_u64(42);
    let noise: Vec<f64> = (0..STEPS).map(|_| rng.sample(StandardNormal)).collect();
    let dofs: Vec<usize> = (0..STEPS).map(|_| rng.random_range(1..=3)).collect();

    let mut chi = ChiSquareWindow::<32>::new(&ChiSquareConfig {
        window: 20,
        false_alarm_probability: 1e-3,
    })
    .unwrap();
    let mut cusum = Cusum::new(&CusumConfig {
        min_bias_sigma: 1.0,
        mean_steps_between_false_alarms: Some(500.0),
        false_alarm_rate: None,
    })
    .unwrap();
    let mut glr = Glr::<64>::new(&GlrConfig {
        window: 50,
        false_alarm_probability: 1e-3,
    })
    .unwrap();
    // Full capacity, driven through the trait.
    let mut glr_full = Glr::<64>::new(&GlrConfig {
        window: 64,
        false_alarm_probability: 1e-6,
    })
    .unwrap();
    let mut range = RangeRateCheck::new(&RangeRateConfig {
        low_limit: 0.2,
        high_limit: 4.8,
        max_rate: Some(200.0),
    })
    .unwrap();

    let mut failed = [0_usize; 5];
    let allocations = allocations_in(|| {
        for (i, (&z, &dof)) in noise.iter().zip(&dofs).enumerate() {
            // A 2-sigma bias in one stretch out of four, steps disabled in another, a NaN and
            // a reset now and then.
            let phase = (i / 5000) % 4;
            let bias = if phase == 1 { 2.0 } else { 0.0 };
            let enabled = phase != 3 || i % 2 == 0;
            let z = if i % 9973 == 0 { f64::NAN } else { z + bias };
            let dof = if phase == 2 { dof } else { 2 };
            let nis = z * z * dof as f64;

            let results = [
                chi.step(nis, dof, enabled),
                cusum.step(z, enabled),
                glr.step(z, enabled),
                Detector::step(&mut glr_full, z, enabled),
            ];
            for (count, result) in failed.iter_mut().zip(&results) {
                *count += (result.verdict == fdd_diagnostics::Verdict::Failed) as usize;
                black_box(result.obd06(0xA1, 0x81, 0x01));
            }

            // A throttle position voltage: noisy, with an open circuit, a short and a jump;
            // time stamps 1 ms apart, with a duplicate and an out-of-order one now and then.
            let volts = match i % 1000 {
                100..=110 => 0.0,
                500..=505 => 5.0,
                700 => 3.9,
                _ => 1.0 + 0.01 * z.clamp(-3.0, 3.0),
            };
            let t = match i % 4000 {
                17 => (i as f64 - 5.0) * 1e-3,
                18 => (i as f64 - 1.0) * 1e-3,
                _ => i as f64 * 1e-3,
            };
            let r = range.step(volts, t, enabled);
            failed[4] += r.fault.is_some() as usize;
            black_box((r.verdict(), r.range.obd06(0x01, 0x0B, 0x0A)));

            black_box((chi.last_result(), cusum.last_result(), glr.last_result()));
            if i % 25_000 == 24_999 {
                Detector::reset(&mut chi);
                Detector::reset(&mut cusum);
                Detector::reset(&mut glr);
                Detector::reset(&mut glr_full);
                range.reset();
            }
        }
    });
    println!("failed steps (chi-square, CUSUM, GLR 50, GLR 64, range/rate): {failed:?}");
    assert!(
        failed.iter().all(|&n| n > 0),
        "every detector must have been driven into alarm: {failed:?}"
    );
    assert_eq!(
        allocations, 0,
        "detector steps allocated {allocations} times"
    );
}
