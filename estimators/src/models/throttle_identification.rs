//! Re-identification of the throttle model (Table I) from fault-free records of one plant.
//!
//! A throttle whose plate, spring or motor differs from the paper's by tens of percent breaks
//! every residual the monitor forms: with Table I 20 % off, the current the model predicts is
//! off by about as much, the wattmeter residual fails within seconds on a healthy plant, and no
//! threshold both ignores that and still sees a wattmeter fault. A diagnosis engineer would
//! re-identify the model from the vehicle's own fault-free data before setting thresholds; this
//! module does that.
//!
//! **Method: prediction-error identification** (Ljung, *System Identification*, ch. 7): the
//! parameters minimize the sum of squared *normalized innovations* of a Kalman filter run on the
//! records (the TPS and the wattmeter, updated one after the other, then the prediction with the
//! motor voltage, as the monitor does). The dynamics are linear in the state within a mode and
//! linear in the parameters, so the innovations' parameter sensitivities follow from
//! propagating `dx/dtheta` alongside the filter with its gains held fixed (the usual
//! Gauss-Newton approximation of the prediction-error gradient); Levenberg-Marquardt steps on
//! the relative parameter changes. The sign terms (`sgn(rho)`, `sgn(theta - 1)`) are piecewise
//! constant, so, as in the model's Jacobian, their state derivative is taken as zero.
//!
//! **What is identified**: per mode `a21 a22 a23 a32 a33 b c1 c2 c3` (27 values). `a12` stays:
//! the velocity state is only defined up to a scale (scaling `rho` by `s` and `a12` by `1/s`,
//! the velocity row's inputs by `s` and `a32` by `1/s` gives the same angle and current), so one
//! value per mode has to be fixed, and `a12` is the one the angle sees directly. The current's
//! scale is fixed by the wattmeter (`y = i^2`).
//!
//! **Prior**: a Gaussian prior on the relative change of each value (standard deviation
//! [`IdentifySettings::prior_rel_std`], centred on the starting model) makes the problem well
//! posed where the data do not separate two values: `c2` and `c3` of modes 2 and 3 act alike
//! (the angle is always above the 1 deg switch there), and a mode the records barely visit
//! keeps its starting values. A step that would make a mode unstable (spectral radius of
//! `A_s` at or above 1) is refused like a step that raises the cost.
//!
//! Pure math: no I/O; the caller gathers the samples.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::throttle::{mode_index, sgn, ThrottleModel, ThrottleParams};

/// Number of identified values (9 per mode).
pub const IDENTIFIED: usize = 27;
/// Names of the nine identified values of a mode, in the order of the parameter vector.
pub const IDENTIFIED_KEYS: [&str; 9] = ["a21", "a22", "a23", "a32", "a33", "b", "c1", "c2", "c3"];

type Vec27 = SVector<f64, IDENTIFIED>;
type Mat27 = SMatrix<f64, IDENTIFIED, IDENTIFIED>;
type Sens = SMatrix<f64, 3, IDENTIFIED>;

/// One step of a fault-free record: the motor voltage applied after the step's measurements,
/// the TPS output and the wattmeter reading at the step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdSample {
    /// Motor voltage (V).
    pub u_v: f64,
    /// Position sensor output (V).
    pub tps_v: f64,
    /// Wattmeter reading (W, i.e. A^2 into the unit resistance of the model).
    pub watt_w: f64,
}

/// Settings of [`identify`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IdentifySettings {
    /// TPS noise variance (V^2).
    pub tps_var_v2: f64,
    /// Wattmeter noise variance (W^2).
    pub watt_var_w2: f64,
    /// Process noise variances per step on `[0.1 theta, rho, i]` (state units).
    pub q_diag: [f64; 3],
    /// Initial covariance of each record's filter.
    pub p0_diag: [f64; 3],
    /// Volts of the TPS per degree (5 V / 90 deg for the paper's sensor).
    pub tps_v_per_deg: f64,
    /// Standard deviation of the prior on each value's relative change (0.5: a value is
    /// expected within about +-50 % of the starting model).
    pub prior_rel_std: f64,
    /// Steps at the start of each record whose innovations are left out (the filter settles).
    pub burn_in: usize,
    /// Levenberg-Marquardt iterations at most.
    pub max_iterations: usize,
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self {
            tps_var_v2: 0.005f64.powi(2),
            watt_var_w2: 0.1f64.powi(2),
            q_diag: [3.15e-4, 1e-2, 1.62e-4],
            p0_diag: [1.0, 1.0, 1.0],
            tps_v_per_deg: 5.0 / 90.0,
            prior_rel_std: 0.5,
            burn_in: 200,
            max_iterations: 40,
        }
    }
}

/// What [`identify`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct Identified {
    /// The identified model (the starting model with the 27 values replaced).
    pub params: ThrottleParams,
    /// Mean squared normalized innovation (over the TPS and the wattmeter innovations) of the
    /// starting model.
    pub cost_start: f64,
    /// The same of the identified model (about 1 for a model that predicts as well as the
    /// noise levels and the process noise say).
    pub cost_end: f64,
    /// Root mean square of the TPS and wattmeter innovations (V, W) with the starting model.
    pub rms_start: [f64; 2],
    /// The same with the identified model.
    pub rms_end: [f64; 2],
    /// Levenberg-Marquardt iterations made.
    pub iterations: usize,
    /// Whether the relative decrease of the cost fell below 1e-6 before `max_iterations`.
    pub converged: bool,
    /// Samples used (after the burn-in), per mode in which they were predicted.
    pub samples_per_mode: [usize; 3],
    /// Largest spectral radius of each identified mode.
    pub spectral_radius: [f64; 3],
}

/// Why identification could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IdentifyError {
    #[error("{0} samples after the burn-in: too few to identify 27 values (need 10000)")]
    TooFew(usize),
    #[error("`{name}` = {value} must be finite and positive")]
    Setting { name: &'static str, value: f64 },
    #[error("sample {index}: a non-finite value ({field})")]
    NonFinite { index: usize, field: &'static str },
    #[error("the starting model has an unstable mode {mode} (spectral radius {radius:.4})")]
    UnstableStart { mode: usize, radius: f64 },
    #[error("the filter diverged with the starting model (non-finite innovations)")]
    Diverged,
}

/// The 27 values of `p` in the order of the parameter vector.
fn values(p: &ThrottleParams) -> Vec27 {
    let mut v = Vec27::zeros();
    for (s, m) in p.modes.iter().enumerate() {
        let row = [m.a21, m.a22, m.a23, m.a32, m.a33, m.b, m.c1, m.c2, m.c3];
        for (j, x) in row.into_iter().enumerate() {
            v[9 * s + j] = x;
        }
    }
    v
}

/// `p` with its 27 values set from `v`.
fn with_values(p: &ThrottleParams, v: &Vec27) -> ThrottleParams {
    let mut q = *p;
    for (s, m) in q.modes.iter_mut().enumerate() {
        let r = |j: usize| v[9 * s + j];
        (m.a21, m.a22, m.a23, m.a32, m.a33, m.b) = (r(0), r(1), r(2), r(3), r(4), r(5));
        (m.c1, m.c2, m.c3) = (r(6), r(7), r(8));
    }
    q
}

/// Largest eigenvalue modulus of each mode's `A_s`.
pub fn spectral_radii(p: &ThrottleParams) -> [f64; 3] {
    let mut r = [0.0; 3];
    for (s, m) in p.modes.iter().enumerate() {
        r[s] = m
            .a()
            .complex_eigenvalues()
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max);
    }
    r
}

/// One pass of the filter over every record: the cost and, with `normal`, the Gauss-Newton
/// normal equations (`J'J`, `J'r`) in the relative parameters.
struct Pass {
    sum_sq: f64,
    sum_sq_tps: f64,
    sum_sq_watt: f64,
    n: usize,
    per_mode: [usize; 3],
    jtj: Mat27,
    jtr: Vec27,
}

fn run(
    records: &[&[IdSample]],
    params: &ThrottleParams,
    s: &IdentifySettings,
    normal: bool,
) -> Option<Pass> {
    let model = ThrottleModel::new(*params).ok()?;
    // Scale of each value: derivatives are taken in relative units (d/d(delta) = p0 d/dp).
    let scale = values(params);
    let c = s.tps_v_per_deg / params.angle_scale;
    let q = Matrix3::from_diagonal(&Vector3::from(s.q_diag));
    let p0 = Matrix3::from_diagonal(&Vector3::from(s.p0_diag));
    let mut out = Pass {
        sum_sq: 0.0,
        sum_sq_tps: 0.0,
        sum_sq_watt: 0.0,
        n: 0,
        per_mode: [0; 3],
        jtj: Mat27::zeros(),
        jtr: Vec27::zeros(),
    };
    let [lo, hi] = params.angle_limits_deg;
    let (lo, hi) = (lo * params.angle_scale, hi * params.angle_scale);
    for rec in records {
        let Some(first) = rec.first() else { continue };
        let m0 = &params.modes[mode_index(params, first.tps_v / s.tps_v_per_deg)];
        let mut x = Vector3::new(first.tps_v / c, 0.0, m0.b * first.u_v / (1.0 - m0.a33));
        let mut p = p0;
        let mut psi = Sens::zeros();
        for (k, smp) in rec.iter().enumerate() {
            let counted = k >= s.burn_in;
            // TPS update.
            let s1 = c * c * p[(0, 0)] + s.tps_var_v2;
            let e1 = smp.tps_v - c * x[0];
            let k1 = p.column(0) * (c / s1);
            let sq = 1.0 / s1.sqrt();
            if counted {
                let r = e1 * sq;
                out.sum_sq += r * r;
                out.sum_sq_tps += e1 * e1;
                if normal {
                    let g = psi.row(0).transpose() * (-c * sq);
                    out.jtj.ger(1.0, &g, &g, 1.0);
                    out.jtr.axpy(r, &g, 1.0);
                }
            }
            x += k1 * e1;
            let kh = k1 * SMatrix::<f64, 1, 3>::new(c, 0.0, 0.0);
            p -= kh * p;
            if normal {
                psi -= k1 * (psi.row(0) * c);
            }
            // Wattmeter update (linearized at the predicted current).
            let h2 = 2.0 * x[2];
            let s2 = h2 * h2 * p[(2, 2)] + s.watt_var_w2;
            let e2 = smp.watt_w - x[2] * x[2];
            let k2 = p.column(2) * (h2 / s2);
            let sq2 = 1.0 / s2.sqrt();
            if counted {
                let r = e2 * sq2;
                out.sum_sq += r * r;
                out.sum_sq_watt += e2 * e2;
                out.n += 1;
                if normal {
                    let g = psi.row(2).transpose() * (-h2 * sq2);
                    out.jtj.ger(1.0, &g, &g, 1.0);
                    out.jtr.axpy(r, &g, 1.0);
                }
            }
            x += k2 * e2;
            let kh = k2 * SMatrix::<f64, 1, 3>::new(0.0, 0.0, h2);
            p -= kh * p;
            p = (p + p.transpose()) * 0.5;
            if normal {
                psi -= k2 * (psi.row(2) * h2);
            }
            // Prediction with the voltage applied after the measurements.
            let theta = x[0] / params.angle_scale;
            let mode = mode_index(params, theta);
            if counted {
                out.per_mode[mode] += 1;
            }
            let m = &params.modes[mode];
            let a = m.a();
            if normal {
                let mut dfdp = Sens::zeros();
                let b = 9 * mode;
                let sgn_rho = sgn(x[1]);
                let sgn_sw = sgn(theta - params.friction_switch_deg);
                // Velocity row: a21 x1 + a22 rho + a23 i + c1 sgn(rho) + c2 sgn(theta - 1) + c3.
                for (j, d) in [x[0], x[1], x[2]].into_iter().enumerate() {
                    dfdp[(1, b + j)] = d;
                }
                dfdp[(1, b + 6)] = sgn_rho;
                dfdp[(1, b + 7)] = sgn_sw;
                dfdp[(1, b + 8)] = 1.0;
                // Current row: a32 rho + a33 i + b u.
                dfdp[(2, b + 3)] = x[1];
                dfdp[(2, b + 4)] = x[2];
                dfdp[(2, b + 5)] = smp.u_v;
                for j in b..b + 9 {
                    for i in 0..3 {
                        dfdp[(i, j)] *= scale[j];
                    }
                }
                psi = a * psi + dfdp;
            }
            let mut xn = model.transition_in(&x, smp.u_v, mode);
            if xn[0] < lo || xn[0] > hi {
                xn[0] = xn[0].clamp(lo, hi);
                xn[1] = 0.0;
                if normal {
                    psi.row_mut(0).fill(0.0);
                    psi.row_mut(1).fill(0.0);
                }
            }
            x = xn;
            p = a * p * a.transpose() + q;
            if !(x.iter().all(|v| v.is_finite()) && p.iter().all(|v| v.is_finite())) {
                return None;
            }
        }
    }
    out.sum_sq.is_finite().then_some(out)
}

/// Identifies the throttle model from fault-free `records` (each a contiguous run of 1 ms
/// steps of one plant), starting from `start` (see the [module documentation](self)).
pub fn identify(
    records: &[&[IdSample]],
    start: &ThrottleParams,
    s: &IdentifySettings,
) -> Result<Identified, IdentifyError> {
    for (name, value) in [
        ("tps_var_v2", s.tps_var_v2),
        ("watt_var_w2", s.watt_var_w2),
        ("tps_v_per_deg", s.tps_v_per_deg),
        ("prior_rel_std", s.prior_rel_std),
        ("p0_diag[0]", s.p0_diag[0]),
        ("p0_diag[1]", s.p0_diag[1]),
        ("p0_diag[2]", s.p0_diag[2]),
    ] {
        if !(value.is_finite() && value > 0.0) {
            return Err(IdentifyError::Setting { name, value });
        }
    }
    for (i, q) in s.q_diag.iter().enumerate() {
        if !(q.is_finite() && *q >= 0.0) {
            return Err(IdentifyError::Setting {
                name: ["q_diag[0]", "q_diag[1]", "q_diag[2]"][i],
                value: *q,
            });
        }
    }
    let mut index = 0;
    for rec in records {
        for smp in rec.iter() {
            for (field, v) in [
                ("u_v", smp.u_v),
                ("tps_v", smp.tps_v),
                ("watt_w", smp.watt_w),
            ] {
                if !v.is_finite() {
                    return Err(IdentifyError::NonFinite { index, field });
                }
            }
            index += 1;
        }
    }
    let used: usize = records
        .iter()
        .map(|r| r.len().saturating_sub(s.burn_in))
        .sum();
    if used < 10_000 {
        return Err(IdentifyError::TooFew(used));
    }
    let radii = spectral_radii(start);
    if let Some((mode, &radius)) = radii.iter().enumerate().find(|(_, r)| **r >= 1.0) {
        return Err(IdentifyError::UnstableStart { mode, radius });
    }
    let p_start = values(start);
    let prior_w = 1.0 / (s.prior_rel_std * s.prior_rel_std);
    // The parameters as relative changes from the start: p = p_start (1 + delta).
    let params_of =
        |delta: &Vec27| with_values(start, &p_start.component_mul(&delta.add_scalar(1.0)));
    let mut delta = Vec27::zeros();
    let mut current = run(records, start, s, true).ok_or(IdentifyError::Diverged)?;
    let first = (
        current.sum_sq / (2 * current.n) as f64,
        [
            (current.sum_sq_tps / current.n as f64).sqrt(),
            (current.sum_sq_watt / current.n as f64).sqrt(),
        ],
    );
    let total = |pass: &Pass, d: &Vec27| pass.sum_sq + prior_w * d.norm_squared();
    let mut cost = total(&current, &delta);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < s.max_iterations {
        iterations += 1;
        // The normal equations are in the current model's relative units: rescale them to the
        // start's (d/d(delta) = p_start d/dp, and the pass's columns carry p_current d/dp).
        let ratio = delta.add_scalar(1.0);
        let mut jtj = current.jtj;
        let mut jtr = current.jtr;
        for i in 0..IDENTIFIED {
            let ri = if ratio[i] != 0.0 { 1.0 / ratio[i] } else { 0.0 };
            jtr[i] *= ri;
            for j in 0..IDENTIFIED {
                let rj = if ratio[j] != 0.0 { 1.0 / ratio[j] } else { 0.0 };
                jtj[(i, j)] *= ri * rj;
            }
        }
        let grad = jtr + delta * prior_w;
        let mut accepted = false;
        for _ in 0..12 {
            let mut a = jtj;
            for i in 0..IDENTIFIED {
                a[(i, i)] += prior_w + lambda * (jtj[(i, i)] + prior_w);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&(-grad))) else {
                lambda *= 4.0;
                continue;
            };
            let trial = delta + step;
            let p = params_of(&trial);
            let stable = spectral_radii(&p).iter().all(|r| *r < 1.0);
            let pass = if stable {
                run(records, &p, s, true)
            } else {
                None
            };
            match pass {
                Some(pass) if total(&pass, &trial) < cost => {
                    let new_cost = total(&pass, &trial);
                    converged = (cost - new_cost) / cost < 1e-6;
                    cost = new_cost;
                    delta = trial;
                    current = pass;
                    lambda = (lambda / 3.0).max(1e-9);
                    accepted = true;
                    break;
                }
                _ => lambda *= 4.0,
            }
        }
        if !accepted || converged {
            converged = true;
            break;
        }
    }
    let params = params_of(&delta);
    Ok(Identified {
        params,
        cost_start: first.0,
        cost_end: current.sum_sq / (2 * current.n) as f64,
        rms_start: first.1,
        rms_end: [
            (current.sum_sq_tps / current.n as f64).sqrt(),
            (current.sum_sq_watt / current.n as f64).sqrt(),
        ],
        iterations,
        converged,
        samples_per_mode: current.per_mode,
        spectral_radius: spectral_radii(&params),
    })
}
