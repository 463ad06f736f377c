//! Cost of one update of the gain-scheduled air-path observer (one SDIRK2 step of the
//! 14-state model, the sensors' prediction, the bilinear gain lookup and the correction), at
//! the LiU-ICE logs' 20 Hz and the TSFS09 transients' 80 Hz, over a throttle tip-in and
//! tip-out at 2000 rpm on the TCSI parameter set. `cargo bench -p fdd-estimators --bench
//! turbo_observer`.

use std::f64::consts::PI;

use divan::Bencher;
use fdd_estimators::models::turbo::discrete::TurboDiscrete;
use fdd_estimators::models::turbo::observer::design::{
    design_gains, Conditions, DesignOptions, NoiseSample,
};
use fdd_estimators::models::turbo::observer::{Interpolation, Sensor, TurboObserver};
use fdd_estimators::models::turbo::*;
use nalgebra::SVector;

fn main() {
    divan::main();
}

#[derive(serde::Deserialize)]
struct File {
    model: TurboParams,
}

fn model() -> TurboModel {
    let f: File = toml::from_str(include_str!("../../config/turbo.toml")).expect("parses");
    TurboModel::new(f.model).expect("valid")
}

fn input(throttle_pct: f64) -> TurboInput {
    TurboInput {
        throttle_pct,
        engine_speed_rad_s: 2000.0 * PI / 30.0,
        wastegate_frac: 1.0,
        lambda: 1.0,
        ambient_pressure_pa: 101_300.0,
        ambient_temperature_k: 298.0,
    }
}

/// An observer at `dt` and 10 s of inputs and noiseless sensors from the model itself.
fn setup(dt: f64) -> (TurboObserver<2>, Vec<(TurboInput, SVector<f64, 2>)>) {
    let m = model();
    let s = m.state_scales();
    let q = std::array::from_fn(|i| (0.02 * s[i]).powi(2));
    let noise: Vec<NoiseSample> = [(100.0, 30e3), (500.0, 30e3), (100.0, 150e3), (500.0, 150e3)]
        .map(|(speed_rad_s, p_im_pa)| NoiseSample {
            speed_rad_s,
            p_im_pa,
            q,
        })
        .to_vec();
    let opts = DesignOptions {
        dt_s: dt,
        sensors: [Sensor::PIm, Sensor::Maf],
        r: [1500.0f64.powi(2), 4e-4f64.powi(2)],
        speeds_rad_s: vec![150.0, 300.0],
        pressures_pa: vec![40e3, 70e3, 95e3],
        conditions: Conditions {
            ambient_pressure_pa: 101_300.0,
            ambient_temperature_k: 298.0,
            lambda: 1.0,
        },
    };
    let table = design_gains(&m, &opts, &noise).expect("design").table;
    let truth = TurboDiscrete::new(m.clone(), dt, 1e-3).expect("step");
    let throttle = |t: f64| if (3.0..6.0).contains(&t) { 40.0 } else { 18.0 };
    let mut x = m
        .stationary_point(&input(18.0), None)
        .expect("stationary")
        .state;
    let mut data = Vec::new();
    for k in 0..(10.0 / dt) as usize {
        let u = input(throttle(k as f64 * dt));
        let s = m.signals(&x, &u);
        data.push((u, SVector::<f64, 2>::new(s.p_im_pa, s.w_af_kg_s)));
        x = truth.step(&x, &u).expect("truth");
    }
    let mut obs = TurboObserver::new(
        m,
        dt,
        [Sensor::PIm, Sensor::Maf],
        table,
        Interpolation::Bilinear,
        true,
    )
    .expect("observer");
    obs.reset_stationary(&input(18.0)).expect("stationary");
    (obs, data)
}

fn bench_at(bencher: Bencher, dt: f64) {
    let (mut obs, data) = setup(dt);
    let mut k = 0usize;
    bencher.bench_local(|| {
        let (u, y) = &data[k % data.len()];
        k += 1;
        divan::black_box(obs.update(u, y).ok());
    });
}

/// One update at 20 Hz (50 ms step).
#[divan::bench(sample_count = 200, sample_size = 50)]
fn observer_update_20hz(bencher: Bencher) {
    bench_at(bencher, 0.05);
}

/// One update at 80 Hz (12.5 ms step).
#[divan::bench(sample_count = 200, sample_size = 50)]
fn observer_update_80hz(bencher: Bencher) {
    bench_at(bencher, 0.0125);
}
