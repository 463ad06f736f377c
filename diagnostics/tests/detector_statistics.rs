//! The detectors' false-alarm and detection figures, measured on seeded white Gaussian
//! innovations (>= 10^6 samples per figure) and compared with what their configuration
//! promises. Run with `--nocapture` to see the measured and predicted figures.
//!
//! - Chi-square window and GLR: the configured probability is per decision, and decisions of a
//!   sliding window W steps apart share no sample. Counting only decisions on non-overlapping
//!   windows (every W-th step) gives independent Bernoulli(p) trials, so the number of false
//!   alarms must fall inside the central 99% interval of Binomial(n, p). (All decisions are
//!   counted too and printed, for information: their rate is also p, but they are correlated, so
//!   the binomial interval does not apply to them.)
//! - CUSUM: the measured mean time between false alarms (run lengths between restarts) must be
//!   within 20% of the configured value, and for a 1-sigma bias the mean detection delay (from
//!   the first biased sample, inclusive, statistic starting at 0) within 20% of Siegmund's
//!   prediction. With ~2000 false alarms (~100 000 detections) the sampling error is ~2% (~0.5%),
//!   so the 20% band leaves the approximation's own error (about 1%) plenty of room.
//!
//! Seeds are fixed, so the figures are reproducible. Each test prints its own run time; the
//! whole file takes well under a second in release on a 2-core machine.

use std::time::Instant;

use fdd_diagnostics::detectors::{
    ChiSquareConfig, ChiSquareWindow, Cusum, CusumConfig, Detector, Glr, GlrConfig,
};
use fdd_diagnostics::Verdict;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use statrs::distribution::{Binomial, DiscreteCDF};

const SAMPLES: usize = 1_000_000;

/// Central 99% interval of Binomial(n, p): `[q(0.005), q(0.995)]`, `q` the quantile
/// (smallest x with `P(X <= x) >= level`).
fn binomial_interval_99(n: u64, p: f64) -> (u64, u64) {
    let dist = Binomial::new(p, n).unwrap();
    let quantile = |level: f64| {
        let mean = n as f64 * p;
        let sd = (mean * (1.0 - p)).sqrt();
        let mut x = (mean - 8.0 * sd - 2.0).max(0.0) as u64;
        while dist.cdf(x) < level {
            x += 1;
        }
        x
    };
    (quantile(0.005), quantile(0.995))
}

fn normal(rng: &mut Pcg64Mcg) -> f64 {
    rng.sample(StandardNormal)
}

/// Counts false alarms over `SAMPLES` steps; `decide(step)` returns the verdict of step `step`.
/// Decisions at steps `window - 1 + j * window` use disjoint samples.
fn count_false_alarms(name: &str, window: usize, p: f64, mut decide: impl FnMut(usize) -> Verdict) {
    let start = Instant::now();
    let (mut independent, mut independent_alarms) = (0_u64, 0_u64);
    let (mut all, mut all_alarms) = (0_u64, 0_u64);
    for step in 0..SAMPLES {
        let verdict = decide(step);
        if !verdict.tested() {
            continue;
        }
        let failed = verdict == Verdict::Failed;
        all += 1;
        all_alarms += failed as u64;
        if (step + 1) % window == 0 {
            independent += 1;
            independent_alarms += failed as u64;
        }
    }
    let (lo, hi) = binomial_interval_99(independent, p);
    println!(
        "{name}: {independent} non-overlapping decisions, {independent_alarms} false alarms \
         (rate {:.5}); configured p = {p}, expected {:.1}, 99% binomial interval [{lo}, {hi}]; \
         all {all} decisions: rate {:.5}; {:.2} s",
        independent_alarms as f64 / independent as f64,
        independent as f64 * p,
        all_alarms as f64 / all as f64,
        start.elapsed().as_secs_f64(),
    );
    assert!(
        (lo..=hi).contains(&independent_alarms),
        "{name}: {independent_alarms} false alarms outside [{lo}, {hi}]"
    );
}

#[test]
fn chi_square_false_alarm_rate() {
    // (window, dof per step, p); dof 0 means "1, 2 or 3 at random" (partial updates), which
    // exercises the threshold following the window's total degrees of freedom.
    for (seed, (window, dof, p)) in [(10, 2, 0.01), (50, 3, 0.05), (1, 1, 1e-3), (20, 0, 0.01)]
        .into_iter()
        .enumerate()
    {
        let config = ChiSquareConfig {
            window,
            false_alarm_probability: p,
        };
        let mut detector = ChiSquareWindow::<64>::new(&config).unwrap();
        let mut rng = Pcg64Mcg::seed_from_u64(1000 + seed as u64);
        let name = if dof == 0 {
            format!("chi-square W={window} dof=1..3 random")
        } else {
            format!("chi-square W={window} dof={dof}")
        };
        count_false_alarms(&name, window as usize, p, |_| {
            let d = if dof == 0 {
                rng.random_range(1..=3)
            } else {
                dof
            };
            let nis: f64 = (0..d).map(|_| normal(&mut rng).powi(2)).sum();
            detector.step(nis, d, true).verdict
        });
    }
}

#[test]
fn glr_false_alarm_rate() {
    for (seed, (window, p)) in [(20, 0.01), (5, 1e-3), (100, 0.05)].into_iter().enumerate() {
        let config = GlrConfig {
            window,
            false_alarm_probability: p,
        };
        let built = Instant::now();
        let mut detector = Glr::<128>::new(&config).unwrap();
        println!(
            "GLR M={window}, p={p}: threshold {:.6} (prefail {:.6}), computed in {:.1} ms",
            detector.threshold(),
            detector.prefail_level(),
            built.elapsed().as_secs_f64() * 1e3
        );
        let mut rng = Pcg64Mcg::seed_from_u64(2000 + seed as u64);
        count_false_alarms(&format!("GLR M={window}"), window as usize, p, |_| {
            detector.step(normal(&mut rng), true).verdict
        });
    }
}

#[test]
fn cusum_mean_time_between_false_alarms() {
    for (seed, (delta, arl0)) in [(1.0, 500.0), (0.5, 1000.0)].into_iter().enumerate() {
        let start = Instant::now();
        let mut cusum = Cusum::new(&CusumConfig {
            min_bias_sigma: delta,
            mean_steps_between_false_alarms: Some(arl0),
            false_alarm_rate: None,
        })
        .unwrap();
        let mut rng = Pcg64Mcg::seed_from_u64(3000 + seed as u64);
        let (mut run, mut runs, mut total) = (0_u64, 0_u64, 0_u64);
        for _ in 0..SAMPLES {
            run += 1;
            if cusum.step(normal(&mut rng), true).verdict == Verdict::Failed {
                runs += 1;
                total += run;
                run = 0;
            }
        }
        let measured = total as f64 / runs as f64;
        println!(
            "CUSUM delta={delta} (k={}, h={:.4}): mean time between false alarms measured \
             {measured:.1} steps over {runs} alarms, configured {arl0} (Siegmund), ratio {:.3}; \
             {:.2} s",
            cusum.reference(),
            cusum.threshold(),
            measured / arl0,
            start.elapsed().as_secs_f64(),
        );
        assert!(
            (measured / arl0 - 1.0).abs() < 0.2,
            "measured {measured} vs configured {arl0}"
        );
    }
}

#[test]
fn cusum_detection_delay_for_a_one_sigma_bias() {
    for (seed, (delta, arl0)) in [(1.0, 500.0), (1.0, 1e4), (0.5, 1000.0)]
        .into_iter()
        .enumerate()
    {
        let start = Instant::now();
        let mut cusum = Cusum::new(&CusumConfig {
            min_bias_sigma: delta,
            mean_steps_between_false_alarms: Some(arl0),
            false_alarm_rate: None,
        })
        .unwrap();
        let bias = 1.0;
        let predicted = cusum.predicted_delay(bias);
        let mut rng = Pcg64Mcg::seed_from_u64(4000 + seed as u64);
        let (mut samples, mut trials, mut total) = (0_usize, 0_u64, 0_u64);
        while samples < SAMPLES {
            // Statistic at 0, bias from the first sample on; delay counts that sample as 1.
            cusum.reset();
            let mut delay = 0_u64;
            loop {
                delay += 1;
                if cusum.step(bias + normal(&mut rng), true).verdict == Verdict::Failed {
                    break;
                }
            }
            samples += delay as usize;
            trials += 1;
            total += delay;
        }
        let measured = total as f64 / trials as f64;
        println!(
            "CUSUM delta={delta}, ARL0={arl0} (h={:.4}): mean delay for a {bias}-sigma bias \
             measured {measured:.3} steps over {trials} detections ({samples} samples), \
             predicted {predicted:.3} (Siegmund), ratio {:.3}; {:.2} s",
            cusum.threshold(),
            measured / predicted,
            start.elapsed().as_secs_f64(),
        );
        assert!(
            (measured / predicted - 1.0).abs() < 0.2,
            "measured {measured} vs predicted {predicted}"
        );
    }
}
