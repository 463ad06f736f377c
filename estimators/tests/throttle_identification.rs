//! Re-identification of the throttle model on records simulated from a known, perturbed plant
//! of the same structure: the identified model predicts the records as well as their noise
//! allows, where Table I does not.

use fdd_estimators::models::throttle::{ThrottleModel, ThrottleParams};
use fdd_estimators::models::throttle_identification::{
    identify, spectral_radii, IdSample, IdentifyError, IdentifySettings,
};
use fdd_estimators::TransitionModel;
use nalgebra::{Vector1, Vector3};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use rand_pcg::Pcg64Mcg;

#[derive(serde::Deserialize)]
struct File {
    model: ThrottleParams,
}

fn table1() -> ThrottleParams {
    let text = include_str!("../../config/throttle.toml");
    toml::from_str::<File>(text)
        .expect("config/throttle.toml")
        .model
}

/// Table I with every identified value moved by up to `rel` (a stable draw).
fn perturbed(rel: f64, seed: u64) -> ThrottleParams {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    loop {
        let mut p = table1();
        for m in &mut p.modes {
            for v in [
                &mut m.a21, &mut m.a22, &mut m.a23, &mut m.a32, &mut m.a33, &mut m.b, &mut m.c1,
                &mut m.c2, &mut m.c3,
            ] {
                *v *= 1.0 + rng.random_range(-rel..rel);
            }
        }
        if spectral_radii(&p).iter().all(|r| *r < 0.999) {
            return p;
        }
    }
}

const Q: [f64; 3] = [3.15e-4, 0.0, 1.62e-4];
const TPS_STD_V: f64 = 0.005;
const WATT_STD_W: f64 = 0.3;

/// `n` steps of the plant under a low-passed random pulse train of voltages in [0, 1.3] V.
fn simulate(p: &ThrottleParams, n: usize, seed: u64) -> Vec<IdSample> {
    let model = ThrottleModel::new(*p).expect("valid plant");
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut gauss = || -> f64 { StandardNormal.sample(&mut rng) };
    let mut levels = Pcg64Mcg::seed_from_u64(seed + 1);
    let c = 5.0 / 90.0 / p.angle_scale;
    let mut x = Vector3::zeros();
    let (mut level, mut hold, mut u) = (0.5, 0usize, 0.5);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        if hold == 0 {
            level = levels.random_range(0.0..1.3);
            hold = levels.random_range(100..1500);
        }
        hold -= 1;
        u += (level - u) * (1e-3 / 0.02);
        out.push(IdSample {
            u_v: u,
            tps_v: c * x[0] + TPS_STD_V * gauss(),
            watt_w: x[2] * x[2] + WATT_STD_W * gauss(),
        });
        let mut next = model.transition(&x, &Vector1::new(u));
        for (k, q) in Q.iter().enumerate() {
            next[k] += q.sqrt() * gauss();
        }
        model.constrain(&mut next);
        x = next;
    }
    out
}

fn settings() -> IdentifySettings {
    IdentifySettings {
        tps_var_v2: TPS_STD_V * TPS_STD_V,
        watt_var_w2: WATT_STD_W * WATT_STD_W,
        q_diag: [Q[0], 1e-2, Q[2]],
        ..IdentifySettings::default()
    }
}

#[test]
fn a_plant_twenty_percent_off_table1_is_identified_to_its_noise_floor() {
    let truth = perturbed(0.2, 7);
    let records = [simulate(&truth, 150_000, 11), simulate(&truth, 150_000, 12)];
    let slices: Vec<&[IdSample]> = records.iter().map(Vec::as_slice).collect();
    let id = identify(&slices, &table1(), &settings()).expect("identifies");
    // The true model's own figure on these records: what a perfect identification reaches.
    let floor = identify(
        &slices,
        &truth,
        &IdentifySettings {
            max_iterations: 0,
            ..settings()
        },
    )
    .expect("runs");
    println!(
        "start {:.3} identified {:.3} truth {:.3}; wattmeter rms {:.4} -> {:.4} (truth {:.4}); {} iterations",
        id.cost_start,
        id.cost_end,
        floor.cost_start,
        id.rms_start[1],
        id.rms_end[1],
        floor.rms_start[1],
        id.iterations
    );
    assert!(
        id.cost_start > floor.cost_start * 1.2,
        "Table I should not fit this plant"
    );
    // Most of the gap to the true model is closed.
    let closed = (id.cost_start - id.cost_end) / (id.cost_start - floor.cost_start);
    assert!(closed > 0.8, "closed {closed:.3} of the gap");
    assert!(id.spectral_radius.iter().all(|r| *r < 1.0));
}

#[test]
fn too_few_or_non_finite_samples_are_refused() {
    let p = table1();
    let short = simulate(&p, 5_000, 1);
    assert!(matches!(
        identify(&[&short], &p, &settings()),
        Err(IdentifyError::TooFew(_))
    ));
    let mut bad = simulate(&p, 20_000, 2);
    bad[123].watt_w = f64::NAN;
    let e = identify(&[&bad], &p, &settings()).expect_err("NaN refused");
    assert_eq!(
        e,
        IdentifyError::NonFinite {
            index: 123,
            field: "watt_w"
        }
    );
    assert!(e.to_string().contains("sample 123"));
}
