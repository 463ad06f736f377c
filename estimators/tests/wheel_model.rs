//! The quarter car and its EKF (estimators/src/models/wheel.rs): the friction law, the slip's
//! branches, the analytic Jacobian against central differences, the tutorial's P0 = 0 start,
//! and the filter on a braking stop integrated finely from the continuous model.

use fdd_estimators::models::wheel::{
    slip, slip_with_slopes, Burckhardt, Friction, QuarterCar, Surface, WheelEkf,
    WheelEstimatorParams, WheelFilterParams, WheelParams, X_MASS, X_MU, X_OMEGA, X_SLIP, X_V,
};
use fdd_estimators::{numerical_jacobian, TransitionModel};
use nalgebra::SVector;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::Deserialize;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    model: WheelParams,
    filter: WheelFilterParams,
    estimator: WheelEstimatorParams,
}

fn config() -> File {
    let text = include_str!("../../config/wheel.toml");
    let f: File = toml::from_str(text).expect("config/wheel.toml parses");
    f.model.validate().expect("[model] valid");
    f.filter.validate().expect("[filter] valid");
    f.estimator.validate().expect("[estimator] valid");
    f
}

#[test]
fn burckhardt_is_odd_peaks_where_its_slope_vanishes_and_matches_the_table() {
    let p = config().model;
    let dry = p.surfaces.curve(Surface::Dry);
    for l in [0.01, 0.1, 0.3, 0.9] {
        assert_eq!(dry.mu(-l), -dry.mu(l));
        assert_eq!(dry.slope(-l), dry.slope(l));
        let h = 1e-6;
        let num = (dry.mu(l + h) - dry.mu(l - h)) / (2.0 * h);
        assert!((num - dry.slope(l)).abs() < 1e-6, "{l}: {num}");
    }
    // Dry asphalt's peak: slip 0.17, friction 1.17 (the curve's known maximum).
    let (l, m) = dry.peak();
    assert!(
        (l - 0.170).abs() < 0.002 && (m - 1.17).abs() < 0.005,
        "{l} {m}"
    );
    assert!(dry.slope(l).abs() < 1e-9);
    // Peaks fall from dry to ice; ice rises to slip 1 (c3 = 0).
    let peaks: Vec<f64> = Surface::ALL
        .iter()
        .map(|&s| p.surfaces.curve(s).peak().1)
        .collect();
    assert!(peaks.windows(2).all(|w| w[0] > w[1]), "{peaks:?}");
    assert_eq!(p.surfaces.curve(Surface::Ice).peak().0, 1.0);
    assert!((peaks[3] - 0.05).abs() < 1e-3);
}

#[test]
fn slip_is_braking_traction_or_bounded_near_standstill_and_continuous_between() {
    let (r, vmin) = (0.31, 0.5);
    // Braking: (v - r w) / v; traction: (v - r w) / (r w); both within [-1, 1].
    assert!((slip(20.0, 0.8 * 20.0 / r, r, vmin) - 0.2).abs() < 1e-12);
    assert!((slip(10.0, 12.5 / r, r, vmin) + 0.2).abs() < 1e-12);
    assert_eq!(slip(20.0, 0.0, r, vmin), 1.0);
    assert_eq!(slip(0.0, 30.0, r, vmin), -1.0);
    // Near standstill the difference is divided by v_min, not by a vanishing speed.
    assert!((slip(0.1, 0.05 / r, r, vmin) - 0.1).abs() < 1e-12);
    assert_eq!(slip(0.0, 0.0, r, vmin), 0.0);
    // Continuous across the branches' borders (v = r w, and v = v_min).
    for (v, w) in [
        (0.5, 0.3 / r),
        (0.3, 0.5 / r),
        (5.0, 5.0 / r),
        (0.5, 0.5 / r),
    ] {
        let a = slip(v, w, r, vmin);
        let b = slip(v + 1e-9, w, r, vmin);
        let c = slip(v, w + 1e-9, r, vmin);
        assert!((a - b).abs() < 1e-7 && (a - c).abs() < 1e-7, "{v} {w}");
    }
    // The slopes are the branch's derivatives.
    for (v, w) in [(20.0, 50.0), (10.0, 40.0), (0.2, 0.3)] {
        let (_, dw, dv) = slip_with_slopes(v, w, r, vmin);
        let h = 1e-7;
        let nw = (slip(v, w + h, r, vmin) - slip(v, w - h, r, vmin)) / (2.0 * h);
        let nv = (slip(v + h, w, r, vmin) - slip(v - h, w, r, vmin)) / (2.0 * h);
        assert!((nw - dw).abs() < 1e-6 && (nv - dv).abs() < 1e-6, "{v} {w}");
    }
}

#[test]
fn the_analytic_jacobian_matches_central_differences_on_every_branch() {
    let p = config().model;
    for friction in [
        Friction::Curve(p.surfaces.curve(Surface::Wet)),
        Friction::RandomWalk,
    ] {
        let model = QuarterCar::new(p, friction);
        for x in [
            [60.0, 20.0, 0.07, 0.6, 450.0],
            [30.0, 10.0, -0.05, -0.3, 380.0],
            [0.5, 0.2, 0.02, 0.05, 520.0],
        ] {
            let x = SVector::<f64, 5>::from(x);
            let u = SVector::<f64, 2>::new(900.0, 100.0);
            let (_, f) = model.transition_with_jacobian(&x, &u);
            let n = numerical_jacobian(|z| model.transition(z, &u), &x);
            let err = (f - n).abs().max();
            assert!(err < 1e-5, "{friction:?} at {x:?}: {err}\n{f}\n{n}");
        }
    }
}

#[test]
fn a_zero_initial_covariance_starts_from_q_and_the_covariance_stays_positive_definite() {
    let c = config();
    assert_eq!(c.filter.initial_variance, [0.0; 5], "the tutorial's P0 = 0");
    let model = QuarterCar::new(
        c.model,
        Friction::Curve(c.model.surfaces.curve(Surface::Dry)),
    );
    let mut ekf = WheelEkf::new(model, &c.filter, 20.0, 450.0).expect("filter");
    let u = SVector::<f64, 2>::new(0.0, 0.0);
    ekf.step(20.0 / 0.31, &u, false).expect("first step");
    // After the first update the covariance is the posterior of the prior Q: below Q on omega,
    // Q elsewhere (nothing else is correlated with omega yet).
    let p = ekf.covariance();
    assert!(p[(X_OMEGA, X_OMEGA)] < 1e-4 && p[(X_OMEGA, X_OMEGA)] > 0.0);
    assert_eq!(p[(X_MASS, X_MASS)], 1e-6);
    // A long run through braking to standstill, then a restart: P symmetric positive definite
    // at every step (each update checks it by Cholesky and would refuse the step).
    let mut omega: f64 = 20.0 / 0.31;
    for k in 0..4000 {
        let brake = if k < 3000 { 900.0 } else { 0.0 };
        omega = (omega - 0.005 * 9.81 * 0.7 / 0.31).max(0.0);
        ekf.step(omega, &SVector::<f64, 2>::new(brake, 0.0), false)
            .unwrap_or_else(|e| panic!("step {k}: {e}"));
        let p = ekf.covariance();
        assert!(p.iter().all(|v| v.is_finite()));
        assert!((p - p.transpose()).abs().max() < 1e-9 * p.abs().max());
        assert!(p.symmetric_eigenvalues().min() > 0.0, "step {k}");
    }
    assert!(ekf.state()[X_V] >= 0.0 && ekf.state()[X_OMEGA] >= 0.0);
}

/// The continuous quarter car integrated by RK4 at 0.1 ms between the filter's 5 ms steps.
struct Truth {
    p: WheelParams,
    curve: Burckhardt,
    mass: f64,
    omega: f64,
    v: f64,
}

impl Truth {
    fn advance(&mut self, dt: f64, brake: f64) {
        self.advance_with(dt, brake, 0.0);
    }

    fn advance_with(&mut self, dt: f64, brake: f64, drive: f64) {
        let n = (dt / 1e-4).round() as usize;
        let h = dt / n as f64;
        for _ in 0..n {
            let d = |w: f64, v: f64| {
                QuarterCar::derivatives(&self.p, &self.curve, w, v, self.mass, brake, drive)
            };
            let (w, v) = (self.omega, self.v);
            let k1 = d(w, v);
            let k2 = d(w + 0.5 * h * k1.0, v + 0.5 * h * k1.1);
            let k3 = d(w + 0.5 * h * k2.0, v + 0.5 * h * k2.1);
            let k4 = d(w + h * k3.0, v + h * k3.1);
            self.omega = (w + h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0)).max(0.0);
            self.v = (v + h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1)).max(0.0);
        }
    }

    fn slip(&self) -> f64 {
        slip(self.v, self.omega, self.p.radius_m, self.p.min_speed_m_s)
    }
}

/// Root-mean-square errors after the first 0.5 s of a 20 m/s stop under a constant brake torque
/// asking 60 % of the surface's peak friction (a stable slip below the peak), down to 3 m/s:
/// `(v, mu, slip, slip from the raw measurement and the true speed)`. Measurement noise 1 rad/s
/// (the tutorial's R).
fn braking_errors(
    p: &WheelParams,
    filter: &WheelFilterParams,
    surface: Surface,
    friction: Friction,
    seed: u64,
) -> [f64; 4] {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let curve = p.surfaces.curve(surface);
    let mut truth = Truth {
        p: *p,
        curve,
        mass: 450.0,
        omega: 20.0 / p.radius_m,
        v: 20.0,
    };
    let mut ekf =
        WheelEkf::new(QuarterCar::new(*p, friction), filter, 20.0, 450.0).expect("filter");
    let brake = 0.6 * curve.peak().1 * 450.0 * p.gravity_m_s2 * p.radius_m;
    let noise = Normal::new(0.0, 1.0).expect("std");
    let mut sums = [0.0; 4];
    let (mut n, mut t) = (0.0, 0.0);
    while truth.v > 3.0 && t < 60.0 {
        truth.advance(p.dt_s, brake);
        t += p.dt_s;
        let meas = truth.omega + noise.sample(&mut rng);
        ekf.step(meas, &SVector::<f64, 2>::new(brake, 0.0), false)
            .expect("step");
        if t > 0.5 {
            let x = ekf.state();
            let s_true = truth.slip();
            let raw = slip(truth.v, meas, p.radius_m, p.min_speed_m_s);
            for (k, e) in [
                x[X_V] - truth.v,
                x[X_MU] - curve.mu(s_true),
                x[X_SLIP] - s_true,
                raw - s_true,
            ]
            .into_iter()
            .enumerate()
            {
                sums[k] += e * e;
            }
            n += 1.0;
        }
    }
    sums.map(|s| (s / n).sqrt())
}

#[test]
fn the_tutorial_euler_chain_from_slip_to_friction_to_wheel_speed_is_unstable_at_5_ms() {
    // omega -> lambda (next step) -> mu (the step after) -> omega: a loop gain of
    // Ts r g m / J * r / v * dmu/dlambda = 6.8 * 0.0155 * 30.2 = 3.2 at 20 m/s on dry asphalt;
    // with omega's own integration, z^3 - z^2 + 3.2 = 0 has a root of modulus about 1.6. The tutorial's filter survives it only because its Q on slip and friction
    // (1 each) is so large that the prediction hardly counts: its friction estimate is then as
    // noisy as the wheel speed's differences.
    let c = config();
    let p = c.model;
    let curve = p.surfaces.curve(Surface::Dry);
    let model = QuarterCar::new(p, Friction::Curve(curve));
    let x = SVector::<f64, 5>::from([20.0 / p.radius_m, 20.0, 0.0, 0.0, 450.0]);
    let (_, f) = model.transition_with_jacobian(&x, &SVector::<f64, 2>::zeros());
    let radius = f
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    let gain: f64 = 0.005 * p.radius_m * p.gravity_m_s2 * 450.0 / p.inertia_kg_m2 * p.radius_m
        / 20.0
        * curve.slope(0.0);
    assert!((gain - 3.2).abs() < 0.01, "{gain}");
    assert!(radius > 1.5, "{radius}");
    // Unknown surface (friction a random walk): no such loop, every eigenvalue 1 or 0.
    let rw = QuarterCar::new(p, Friction::RandomWalk);
    let (_, f) = rw.transition_with_jacobian(&x, &SVector::<f64, 2>::zeros());
    let radius = f
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    assert!((radius - 1.0).abs() < 1e-12);
    // With the tutorial's noise the filter on the known curve tracks the speed but its
    // friction estimate is off by several tenths (RMS) on every surface.
    for s in [Surface::Dry, Surface::Wet] {
        let [ev, emu, ..] =
            braking_errors(&p, &c.filter, s, Friction::Curve(p.surfaces.curve(s)), 14);
        assert!(ev < 0.1 && emu > 0.3, "{}: v {ev} mu {emu}", s.name());
    }
}

#[test]
fn with_friction_a_random_walk_the_filter_tracks_friction_and_halves_the_slip_error() {
    // Q of slip and friction 1e-4 (the tutorial's others): a unit test of the structure on the
    // filter's own continuous model, not a tuned setting.
    let c = config();
    let mut filter = c.filter;
    filter.process_noise = [1e-4, 1e-4, 1e-4, 1e-4, 1e-6];
    for s in Surface::ALL {
        let [ev, emu, eslip, eraw] = braking_errors(&c.model, &filter, s, Friction::RandomWalk, 15);
        println!(
            "{}: v {ev:.4} m/s, mu {emu:.4}, slip {eslip:.4} (raw {eraw:.4})",
            s.name()
        );
        assert!(ev < 0.05, "{}: v {ev}", s.name());
        assert!(emu < 0.03, "{}: mu {emu}", s.name());
        assert!(eslip < 0.6 * eraw, "{}: slip {eslip} raw {eraw}", s.name());
    }
}

/// Braking events (1.5 s at 50 % of dry asphalt's peak), each followed by rolling, driving back
/// up to speed and rolling again, on the continuous model with a true quarter mass of 450 kg and
/// the filter started at `m0`: the number of braking events after which the mass estimate is
/// within 5 % and stays there (None: not within 20 events), and the estimate at the end.
fn mass_events(c: &File, filter: &WheelFilterParams, m0: f64, seed: u64) -> (Option<usize>, f64) {
    let p = c.model;
    let curve = p.surfaces.curve(Surface::Dry);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let noise = Normal::new(0.0, 1.0).expect("std");
    let mut truth = Truth {
        p,
        curve,
        mass: 450.0,
        omega: 20.0 / p.radius_m,
        v: 20.0,
    };
    let friction = Friction::TorqueBalance { pull: 0.25 };
    let mut ekf = WheelEkf::new(QuarterCar::new(p, friction), filter, 20.0, m0).expect("filter");
    let torque = 0.5 * curve.peak().1 * 450.0 * p.gravity_m_s2 * p.radius_m;
    let mut within_since = None;
    let steps = |s: f64| (s / p.dt_s).round() as usize;
    for event in 1..=20 {
        for (brake, drive, secs) in [
            (torque, 0.0, 1.5),
            (0.0, 0.0, 1.5),
            (0.0, torque, 1.5),
            (0.0, 0.0, 1.5),
        ] {
            for _ in 0..steps(secs) {
                truth.advance_with(p.dt_s, brake, drive);
                let meas = truth.omega + noise.sample(&mut rng);
                let rolling = brake == 0.0 && drive == 0.0;
                ekf.step(meas, &SVector::<f64, 2>::new(brake, drive), rolling)
                    .expect("step");
            }
        }
        let m = ekf.state()[X_MASS];
        if (m - 450.0).abs() <= 0.05 * 450.0 {
            within_since.get_or_insert(event);
        } else {
            within_since = None;
        }
    }
    (within_since, ekf.state()[X_MASS])
}

#[test]
fn pulled_to_the_torque_balance_and_anchored_by_the_rolling_slip_the_mass_is_learned() {
    let c = config();
    let mut filter = c.filter;
    // The unit test's settings (not a tuned monitor's): friction pulled toward the torque
    // balance with a 20 ms time constant (0.25 per 5 ms step), Q of v 1e-6 and of mu 1e-5 per
    // step, the mass's initial standard deviation 150 kg, the rolling slip's 0.005.
    filter.process_noise = [1e-4, 1e-6, 1e-4, 1e-5, 1e-6];
    filter.initial_variance = [0.0, 0.0, 0.0, 0.0, 150.0 * 150.0];
    filter.rolling_slip_std = 0.005;
    for m0 in [300.0, 600.0] {
        let (events, m) = mass_events(&c, &filter, m0, 16);
        println!("from {m0} kg: within 5 % after {events:?} events, {m:.1} kg at the end");
        assert!(
            events.is_some_and(|n| n <= 10),
            "from {m0}: {events:?}, {m}"
        );
    }
    // Without the rolling slip nothing anchors the speed: its error is taken for a mass error,
    // and the mass wanders off.
    filter.rolling_slip_std = 0.0;
    let (events, m) = mass_events(&c, &filter, 300.0, 16);
    assert!(
        events.is_none() && (m - 450.0).abs() > 0.1 * 450.0,
        "{events:?} {m}"
    );
}

#[test]
fn bad_parameters_are_refused_naming_the_key() {
    let c = config();
    let mut p = c.model;
    p.radius_m = -0.3;
    let e = p.validate().unwrap_err();
    assert_eq!(e.key, "radius_m", "{e}");
    let mut p = c.model;
    p.surfaces.snow = [0.1, 1.0, 0.2];
    let e = p.validate().unwrap_err();
    assert_eq!(e.key, "surfaces.snow[2]", "{e}");
    assert!(e.to_string().contains("c1 c2"), "{e}");
    let mut f = c.filter;
    f.process_noise[3] = f64::NAN;
    assert_eq!(f.validate().unwrap_err().key, "process_noise[3]");
    let mut f = c.filter;
    f.rolling_slip_std = -1.0;
    assert_eq!(f.validate().unwrap_err().key, "rolling_slip_std");
    // An array of the wrong length is a parse error, not a silent truncation.
    let text = include_str!("../../config/wheel.toml").replace(
        "dry = [1.2801, 23.99, 0.52]",
        "dry = [1.2801, 23.99, 0.52, 1.0]",
    );
    let e = toml::from_str::<File>(&text).err().expect("refused");
    assert!(e.to_string().contains("exactly 3"), "{e}");
}
