//! The discrete step at the monitor's rate (20 Hz on the LiU-ICE logs, about 100 Hz
//! elsewhere): the two-stage, second-order, L-stable SDIRK method with Newton's method on its
//! stages, in substeps of at most [`DEFAULT_MAX_SUBSTEP_S`] (5 ms), and the exact derivative of
//! the step, `F = dx+/dx`, for the EKF.
//!
//! ```text
//! Y1 = x + g h f(Y1)
//! Y2 = x + (1 - g) h f(Y1) + g h f(Y2),   x+ = Y2,   g = 1 - 1/sqrt(2)
//! F  = (I - g h J2)^-1 (I + (1 - g) h J1 (I - g h J1)^-1),   Ji = df/dx at Yi (exact, by AD)
//! ```
//!
//! # Why this step (figures from `tests/turbo_model.rs`, `--nocapture`)
//!
//! The model is stiff: at idle, part load and full load the Jacobian's eigenvalues lie between
//! -4200 and -0.18 rad/s (REFERENCE: -4500 .. -0.2). The fast ones are the small volumes
//! behind restrictions in their linear regions and the throttle near pressure ratio 1; the slow
//! ones are the turbo shaft and the exhaust temperatures. `h |lambda_max|` is 42 at 10 ms and
//! 210 at 50 ms.
//!
//! - Explicit steps (RK4) are stable only for `h |lambda| < 2.8`, i.e. `h < 0.7 ms`: 15 to 75
//!   substeps of 4 evaluations, and no transition matrix for the EKF.
//! - Linearized one-step methods are stable but fail on the transients that matter. After a
//!   throttle step from 10 to 80 % the Jacobian at the start of the step has the throttle choked
//!   (its flow independent of `p_im`) and the compressor at the flat top of its ellipse: the
//!   linearization has no restoring term for the manifold filling, which in truth is over
//!   within a few milliseconds. Exponential Rosenbrock-Euler (`x + h phi1(hJ) f`, exact for linear dynamics)
//!   overshoots `p_im` past the boost pressure and rings: 31 % RMS error on `p_im` over the
//!   transient at 10 ms and 50 ms; linearly implicit Euler (`(I - hJ) dx = h f`) 4.6 % at 10 ms,
//!   23 % at 50 ms.
//! - The fully implicit step evaluates the nonlinear flows where the state ends up (Newton on
//!   the stage equations, with the exact Jacobian refreshed at every iteration), so crossing
//!   the choked/unchoked boundary or a flow reversal within a step is handled. SDIRK2 is second
//!   order on the slow modes and L-stable (`R(z) -> 0` as `z -> -inf`). Its RMS error over that
//!   throttle step: `p_im` 0.34 % at 10 ms in one step (the sample after the step is off by
//!   6.7 %: at `z = h lambda` of about -4 the stability function is still -0.14), 0.072 % in two
//!   5 ms substeps (worst sample 1 %), 0.067 % at 50 ms in one step, 0.051 % in ten 5 ms
//!   substeps (worst sample 0.1 %); turbo speed 0.11 % .. 0.27 %. On a speed ramp
//!   1500 -> 4500 rpm in 3 s, `p_im` and the turbo speed are within 0.03 % and every state
//!   within 0.06 %. A fully implicit method of higher
//!   order (Radau IIA) damps better at moderate `z` but couples its stages into a 26x26 Newton
//!   system; the 5 ms substeps are cheaper for the same effect.
//!
//! # Cost
//!
//! Per substep two Newton solves of a few iterations, each iteration one exact Jacobian (one
//! evaluation with 13 or 14 dual seeds: 2 us, against 0.34 us for `f` alone) and one 13x13
//! elimination, plus two eliminations for `F`: 15-18 us per substep in `--release` (fastest of
//! five batches on the shared development machine), so 36 us per 10 ms step and 170 us per
//! 50 ms step with the default substeps: 0.4 % and 0.3 % of a core. Everything is on
//! fixed-size matrices: no heap (tested with a counting allocator).
//!
//! # Turbo speed limits
//!
//! The stages integrate the unsaturated shaft acceleration and hold the speed on a limit as an
//! active set (in the stage solver; see [`super::shaft`]); a speed held on its limit at the end
//! of the step has a zero row in `F`.
//!
//! # Also here
//!
//! [`expm`] (scaling and squaring, degree-13 Padé) and [`exp_euler_step`]: the exponential
//! step measured above, and the matrix exponential a later step needs to discretize the model
//! linearized at engine-map points (`A_d = e^(J dt)`) for the paper's stationary Kalman gains.
//! [`TurboModel::integrate_rk4`] is the fine explicit reference.

use nalgebra::{SMatrix, SVector};

use super::{
    TurboError, TurboInput, TurboModel, TurboState, TurboStateAugmented, N_INPUTS, N_STATES,
    N_STATES_AUGMENTED, X_DC_ETA_VOL, X_OMEGA_T,
};
use crate::model::TransitionModel;
use crate::param::{ParamError, Range};

/// The default longest substep (s). See the module docs for the figures behind it.
pub const DEFAULT_MAX_SUBSTEP_S: f64 = 0.005;
/// Accepted step lengths: 0.1 ms to 1 s.
pub const DT_RANGE: Range = Range::closed(1e-4, 1.0, "s");
/// `gamma = 1 - 1/sqrt(2)` of the two-stage L-stable SDIRK method.
pub const SDIRK_GAMMA: f64 = 1.0 - std::f64::consts::FRAC_1_SQRT_2;
/// Newton converges when its update is below this, relative to the state scales.
pub const NEWTON_TOL: f64 = 1e-10;
/// Accepted Newton tolerances ([`TurboDiscrete::with_newton_tolerance`]).
pub const NEWTON_TOL_RANGE: Range = Range::closed(1e-14, 1e-3, "1 (relative to the state scales)");
/// Most Newton iterations per stage before the step is halved.
pub const MAX_NEWTON_ITERATIONS: usize = 10;
/// Most halvings of a step whose Newton iterations do not converge (2^8 = 256 pieces).
pub const MAX_HALVINGS: u32 = 8;

/// Padé coefficients of degree 13 (Higham 2005, Table 10.4 of *Functions of Matrices*).
const PADE13: [f64; 14] = [
    64_764_752_532_480_000.0,
    32_382_376_266_240_000.0,
    7_771_770_303_897_600.0,
    1_187_353_796_428_800.0,
    129_060_195_264_000.0,
    10_559_470_521_600.0,
    670_442_572_800.0,
    33_522_128_640.0,
    1_323_241_920.0,
    40_840_800.0,
    960_960.0,
    16_380.0,
    182.0,
    1.0,
];
/// Largest 1-norm for which the unscaled degree-13 approximant is accurate to double precision.
const THETA13: f64 = 5.371_920_351_148_152;

/// `e^A` by scaling and squaring with the degree-13 Padé approximant. `None` if `A` is not
/// finite or the Padé denominator is singular (it is not for finite `A`: its eigenvalues are
/// bounded away from the poles after scaling).
pub fn expm<const K: usize>(a: &SMatrix<f64, K, K>) -> Option<SMatrix<f64, K, K>> {
    let norm = a
        .column_iter()
        .map(|c| c.iter().map(|v| v.abs()).sum::<f64>())
        .fold(0.0f64, f64::max);
    if !norm.is_finite() {
        return None;
    }
    let s = if norm > THETA13 {
        (norm / THETA13).log2().ceil().max(0.0) as i32
    } else {
        0
    };
    let a = a * 2f64.powi(-s);
    let id = SMatrix::<f64, K, K>::identity();
    let b = &PADE13;
    let a2 = a * a;
    let a4 = a2 * a2;
    let a6 = a4 * a2;
    let u = a
        * (a6 * (a6 * b[13] + a4 * b[11] + a2 * b[9])
            + a6 * b[7]
            + a4 * b[5]
            + a2 * b[3]
            + id * b[1]);
    let v =
        a6 * (a6 * b[12] + a4 * b[10] + a2 * b[8]) + a6 * b[6] + a4 * b[4] + a2 * b[2] + id * b[0];
    let mut r = solve(v - u, v + u)?;
    for _ in 0..s {
        r = r * r;
    }
    Some(r)
}

/// `A^-1 B` by Gaussian elimination with partial pivoting on fixed-size matrices (nalgebra's
/// LU needs type-level dimension bounds a const-generic caller cannot state). `None` if a pivot
/// is zero or not finite.
pub fn solve<const K: usize, const C: usize>(
    mut a: SMatrix<f64, K, K>,
    mut b: SMatrix<f64, K, C>,
) -> Option<SMatrix<f64, K, C>> {
    for c in 0..K {
        let mut piv = c;
        for r in c + 1..K {
            if a[(r, c)].abs() > a[(piv, c)].abs() {
                piv = r;
            }
        }
        let p = a[(piv, c)];
        if !(p.abs() > 0.0) || !p.is_finite() {
            return None;
        }
        if piv != c {
            a.swap_rows(piv, c);
            b.swap_rows(piv, c);
        }
        for r in c + 1..K {
            let m = a[(r, c)] / p;
            if m != 0.0 {
                for k in c..K {
                    a[(r, k)] -= m * a[(c, k)];
                }
                for k in 0..C {
                    b[(r, k)] -= m * b[(c, k)];
                }
            }
        }
    }
    for c in (0..K).rev() {
        let p = a[(c, c)];
        for k in 0..C {
            let mut v = b[(c, k)];
            for j in c + 1..K {
                v -= a[(c, j)] * b[(j, k)];
            }
            b[(c, k)] = v / p;
        }
    }
    Some(b)
}

/// One exponential Rosenbrock-Euler step of length `h` from `x` with `f = f(x)` and
/// `jac = df/dx`, balanced by `scales`: returns `(x + h phi1(hJ) f, e^(hJ))`. `K` must be
/// `N + 1` (checked at compile time).
pub fn exp_euler_step<const N: usize, const K: usize>(
    x: &SVector<f64, N>,
    f: &SVector<f64, N>,
    jac: &SMatrix<f64, N, N>,
    scales: &[f64],
    h: f64,
) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>)> {
    const {
        assert!(
            K == N + 1,
            "the augmented matrix has one more row than the state"
        )
    };
    let mut a = SMatrix::<f64, K, K>::zeros();
    for i in 0..N {
        let si = scales[i];
        for j in 0..N {
            a[(i, j)] = h * jac[(i, j)] * scales[j] / si;
        }
        a[(i, N)] = h * f[i] / si;
    }
    let e = expm(&a)?;
    let next = SVector::<f64, N>::from_fn(|i, _| x[i] + scales[i] * e[(i, N)]);
    let phi = SMatrix::<f64, N, N>::from_fn(|i, j| e[(i, j)] * scales[i] / scales[j]);
    Some((next, phi))
}

/// The continuous dynamics a step needs: `f` and `J` at a state, the projection onto the
/// physical set, and the state scales for the Newton tolerance.
pub(crate) trait Dynamics<const N: usize> {
    /// `f` and `J` with the turbo speed's derivative unsaturated (the projection holds it).
    fn f_and_jac(&self, x: &SVector<f64, N>) -> (SVector<f64, N>, SMatrix<f64, N, N>);
    /// Moves `x` onto the physical set.
    fn project(&self, x: &mut SVector<f64, N>);
    /// State scales.
    fn scales(&self) -> &[f64];
    /// The one state with box limits the stage solver enforces as an active set (the turbo
    /// speed) and its limits.
    fn boxed(&self) -> (usize, f64, f64);
}

/// The plain model at a held input.
pub(crate) struct Plain<'a> {
    pub model: &'a TurboModel,
    pub input: &'a TurboInput,
}

impl Dynamics<N_STATES> for Plain<'_> {
    fn f_and_jac(&self, x: &TurboState) -> (TurboState, SMatrix<f64, N_STATES, N_STATES>) {
        self.model.jacobian13(x, self.input, false)
    }
    fn project(&self, x: &mut TurboState) {
        self.model.constrain(x);
    }
    fn scales(&self) -> &[f64] {
        &self.model.state_scales()[..N_STATES]
    }
    fn boxed(&self) -> (usize, f64, f64) {
        let p = self.model.params();
        (X_OMEGA_T, p.turbo_speed_min_rad_s, p.turbo_speed_max_rad_s)
    }
}

/// The augmented model at a held input.
struct Augmented<'a> {
    model: &'a TurboModel,
    input: &'a TurboInput,
}

impl Dynamics<N_STATES_AUGMENTED> for Augmented<'_> {
    fn f_and_jac(
        &self,
        x: &TurboStateAugmented,
    ) -> (
        TurboStateAugmented,
        SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>,
    ) {
        self.model.jacobian14(x, self.input, false)
    }
    fn project(&self, x: &mut TurboStateAugmented) {
        constrain14(self.model, x);
    }
    fn scales(&self) -> &[f64] {
        &self.model.state_scales()[..]
    }
    fn boxed(&self) -> (usize, f64, f64) {
        let p = self.model.params();
        (X_OMEGA_T, p.turbo_speed_min_rad_s, p.turbo_speed_max_rad_s)
    }
}

/// `max_i |v_i| / s_i`, infinite for a non-finite component.
fn scaled_max<const N: usize>(v: &SVector<f64, N>, s: &[f64]) -> f64 {
    let mut r = 0.0f64;
    for i in 0..N {
        let a = (v[i] / s[i]).abs();
        if !a.is_finite() {
            return f64::INFINITY;
        }
        r = r.max(a);
    }
    r
}

/// Solves the implicit stage equation `Y = c + hg f(Y)` by Newton's method (exact Jacobian,
/// refreshed every iteration: the flow functions' kinks make a frozen one stall) from `y0`.
/// The turbo speed is kept within its limits as an active set: where a Newton update would
/// carry it across a limit, the update is solved again with the speed held on that limit (its
/// equation replaced by `dy = limit - y`), so that the other states converge to the solution
/// with the speed saturated. Returns `Y` with `f(Y)` and `J(Y)` (the speed's row zeroed when it
/// is held), or `None` if Newton does not converge within [`MAX_NEWTON_ITERATIONS`] (the caller
/// halves the step).
pub(crate) fn stage<const N: usize, D: Dynamics<N>>(
    d: &D,
    c: &SVector<f64, N>,
    hg: f64,
    y0: SVector<f64, N>,
    tol: f64,
) -> Option<(SVector<f64, N>, SVector<f64, N>, SMatrix<f64, N, N>)> {
    let id = SMatrix::<f64, N, N>::identity();
    let (k, lo, hi) = d.boxed();
    let mut y = y0;
    d.project(&mut y);
    let (mut f, mut j) = d.f_and_jac(&y);
    for _ in 0..MAX_NEWTON_ITERATIONS {
        let g = y - c - f * hg;
        let m = id - j * hg;
        let mut dy = solve(m, -g)?;
        let target = y[k] + dy[k];
        let held = !(lo..=hi).contains(&target);
        if held {
            let bound = if target < lo { lo } else { hi };
            let mut m = m;
            let mut rhs = -g;
            m.row_mut(k).fill(0.0);
            m[(k, k)] = 1.0;
            rhs[k] = bound - y[k];
            dy = solve(m, rhs)?;
        }
        let last = y;
        y += dy;
        d.project(&mut y);
        (f, j) = d.f_and_jac(&y);
        let step = scaled_max(&(y - last), d.scales());
        if !step.is_finite() || !f.iter().all(|v| v.is_finite()) {
            return None;
        }
        if step < tol {
            if held {
                j.row_mut(k).fill(0.0);
            }
            return Some((y, f, j));
        }
    }
    None
}

/// One step of the two-stage, second-order, L-stable, stiffly accurate SDIRK method
/// (Alexander 1977; `gamma = 1 - 1/sqrt(2)`):
///
/// ```text
/// Y1 = x + gamma h f(Y1)
/// Y2 = x + (1 - gamma) h f(Y1) + gamma h f(Y2),   x+ = Y2
/// ```
///
/// and, if `want_phi`, its exact derivative `dx+/dx` at the converged stages (implicit
/// function theorem): `(I - gamma h J2)^-1 (I + (1 - gamma) h J1 (I - gamma h J1)^-1)`.
fn sdirk2<const N: usize, D: Dynamics<N>>(
    d: &D,
    x: &SVector<f64, N>,
    h: f64,
    want_phi: bool,
    tol: f64,
) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>)> {
    let id = SMatrix::<f64, N, N>::identity();
    let hg = h * SDIRK_GAMMA;
    let (_, f1, j1) = stage(d, x, hg, *x, tol)?;
    let c2 = x + f1 * (h * (1.0 - SDIRK_GAMMA));
    let (y2, _, j2) = stage(d, &c2, hg, c2 + f1 * hg, tol)?;
    let phi = if want_phi {
        let a1 = solve(id - j1 * hg, id)?;
        let b = id + j1 * a1 * (h * (1.0 - SDIRK_GAMMA));
        let mut phi = solve(id - j2 * hg, b)?;
        // A speed held on its limit at the end of the step does not depend on the start.
        let (k, lo, hi) = d.boxed();
        if y2[k] <= lo || y2[k] >= hi {
            phi.row_mut(k).fill(0.0);
        }
        phi
    } else {
        id
    };
    Some((y2, phi))
}

/// A step of length `h`, halved (recursively, at most `depth` times) where Newton does not
/// converge. Returns the new state and `dx+/dx`.
fn advance<const N: usize, D: Dynamics<N>>(
    d: &D,
    x: &SVector<f64, N>,
    h: f64,
    depth: u32,
    want_phi: bool,
    tol: f64,
) -> Option<(SVector<f64, N>, SMatrix<f64, N, N>)> {
    if let Some(r) = sdirk2(d, x, h, want_phi, tol) {
        return Some(r);
    }
    if depth == 0 {
        return None;
    }
    let (xm, p1) = advance(d, x, h / 2.0, depth - 1, want_phi, tol)?;
    let (xe, p2) = advance(d, &xm, h / 2.0, depth - 1, want_phi, tol)?;
    Some((xe, if want_phi { p2 * p1 } else { p2 }))
}

/// Runs `substeps` steps of length `h` from `x`.
fn run<const N: usize, D: Dynamics<N>>(
    d: &D,
    x: &SVector<f64, N>,
    h: f64,
    substeps: usize,
    want_phi: bool,
    tol: f64,
) -> Result<(SVector<f64, N>, SMatrix<f64, N, N>), TurboError> {
    let mut x = *x;
    d.project(&mut x);
    let mut phi = SMatrix::<f64, N, N>::identity();
    for k in 0..substeps {
        let (next, p) =
            advance(d, &x, h, MAX_HALVINGS, want_phi, tol).ok_or(TurboError::NotConverged {
                iterations: MAX_NEWTON_ITERATIONS,
                residual: f64::NAN,
            })?;
        x = next;
        if want_phi {
            phi = if k == 0 { p } else { p * phi };
        }
    }
    if !x.iter().chain(phi.iter()).all(|v| v.is_finite()) {
        return Err(TurboError::NonFinite { what: "turbo step" });
    }
    Ok((x, phi))
}

/// Number of substeps for a step `dt` with longest substep `max_substep`.
fn substeps(dt: f64, max_substep: f64) -> usize {
    // The small tolerance keeps 0.05 / 0.01 at 5 rather than 6 after rounding.
    ((dt / max_substep) * (1.0 - 1e-12)).ceil().max(1.0) as usize
}

fn check_step(dt_s: f64, max_substep_s: f64) -> Result<usize, ParamError> {
    DT_RANGE.check("dt_s", dt_s)?;
    DT_RANGE.check("max_substep_s", max_substep_s)?;
    Ok(substeps(dt_s, max_substep_s))
}

/// The plain 13-state model discretized at a fixed step (SDIRK2, see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct TurboDiscrete {
    model: TurboModel,
    dt_s: f64,
    substeps: usize,
    h: f64,
    newton_tol: f64,
}

impl TurboDiscrete {
    /// The model stepped every `dt_s` seconds, in substeps of at most `max_substep_s`
    /// ([`DEFAULT_MAX_SUBSTEP_S`] unless there is a reason).
    pub fn new(model: TurboModel, dt_s: f64, max_substep_s: f64) -> Result<Self, ParamError> {
        let n = check_step(dt_s, max_substep_s)?;
        Ok(Self {
            model,
            dt_s,
            substeps: n,
            h: dt_s / n as f64,
            newton_tol: NEWTON_TOL,
        })
    }

    /// The same step with Newton's stopping tolerance `tol` (largest update relative to the
    /// state scales, [`NEWTON_TOL_RANGE`]) instead of [`NEWTON_TOL`]. Newton converges
    /// quadratically near the solution, so the error left when an update of size `tol` is
    /// accepted is of the order of `tol^2`: an observer, whose own corrections are of the
    /// order of the sensor noise (1e-3 of the state), loses nothing at `1e-6` and halves the
    /// iterations (figures in [`super::observer`]).
    pub fn with_newton_tolerance(mut self, tol: f64) -> Result<Self, ParamError> {
        NEWTON_TOL_RANGE.check("newton_tolerance", tol)?;
        self.newton_tol = tol;
        Ok(self)
    }

    /// Newton's stopping tolerance (relative to the state scales).
    pub fn newton_tolerance(&self) -> f64 {
        self.newton_tol
    }

    /// The continuous model.
    pub fn model(&self) -> &TurboModel {
        &self.model
    }

    /// The step length (s).
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Substeps per step.
    pub fn substeps(&self) -> usize {
        self.substeps
    }

    /// The state after one step with the input held (zero-order hold), and the transition
    /// matrix `F = dx+/dx` of the step. Refuses a bad input; the result is in the physical set
    /// ([`TurboModel::constrain`]).
    pub fn step_with_jacobian(
        &self,
        x: &TurboState,
        u: &TurboInput,
    ) -> Result<(TurboState, SMatrix<f64, N_STATES, N_STATES>), TurboError> {
        self.model.check_input(u)?;
        let d = Plain {
            model: &self.model,
            input: u,
        };
        run(&d, x, self.h, self.substeps, true, self.newton_tol)
    }

    /// The state after one step (see [`Self::step_with_jacobian`]); skips the transition matrix.
    pub fn step(&self, x: &TurboState, u: &TurboInput) -> Result<TurboState, TurboError> {
        self.model.check_input(u)?;
        let d = Plain {
            model: &self.model,
            input: u,
        };
        run(&d, x, self.h, self.substeps, false, self.newton_tol).map(|(x, _)| x)
    }
}

/// For the generic filters: a step that fails (an input [`TurboModel::check_input`] refuses,
/// which the monitor checks first) returns the state unchanged with `F = I` rather than NaN.
impl TransitionModel<N_STATES, N_INPUTS> for TurboDiscrete {
    fn transition(&self, x: &TurboState, u: &SVector<f64, N_INPUTS>) -> TurboState {
        self.step(x, &TurboInput::from_vector(u)).unwrap_or(*x)
    }

    fn transition_jacobian(
        &self,
        x: &TurboState,
        u: &SVector<f64, N_INPUTS>,
    ) -> SMatrix<f64, N_STATES, N_STATES> {
        self.transition_with_jacobian(x, u).1
    }

    fn transition_with_jacobian(
        &self,
        x: &TurboState,
        u: &SVector<f64, N_INPUTS>,
    ) -> (TurboState, SMatrix<f64, N_STATES, N_STATES>) {
        self.step_with_jacobian(x, &TurboInput::from_vector(u))
            .unwrap_or((*x, SMatrix::identity()))
    }

    fn constrain(&self, x: &mut TurboState) {
        self.model.constrain(x);
    }
}

/// The augmented 14-state model (`dC_eta_vol` last, constant) discretized at a fixed step.
#[derive(Debug, Clone, PartialEq)]
pub struct TurboDiscrete14 {
    inner: TurboDiscrete,
}

impl TurboDiscrete14 {
    /// As [`TurboDiscrete::new`].
    pub fn new(model: TurboModel, dt_s: f64, max_substep_s: f64) -> Result<Self, ParamError> {
        Ok(Self {
            inner: TurboDiscrete::new(model, dt_s, max_substep_s)?,
        })
    }

    /// The continuous model.
    pub fn model(&self) -> &TurboModel {
        &self.inner.model
    }

    /// As [`TurboDiscrete::with_newton_tolerance`].
    pub fn with_newton_tolerance(self, tol: f64) -> Result<Self, ParamError> {
        Ok(Self {
            inner: self.inner.with_newton_tolerance(tol)?,
        })
    }

    /// The step length (s).
    pub fn dt_s(&self) -> f64 {
        self.inner.dt_s
    }

    /// One step and its transition matrix (14x14; `dC_eta_vol` is carried unchanged and its
    /// column holds the sensitivity of the step to it).
    #[allow(clippy::type_complexity)]
    pub fn step_with_jacobian(
        &self,
        x: &TurboStateAugmented,
        u: &TurboInput,
    ) -> Result<
        (
            TurboStateAugmented,
            SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>,
        ),
        TurboError,
    > {
        let m = &self.inner.model;
        m.check_input(u)?;
        let d = Augmented { model: m, input: u };
        run(
            &d,
            x,
            self.inner.h,
            self.inner.substeps,
            true,
            self.inner.newton_tol,
        )
    }

    /// One step.
    pub fn step(
        &self,
        x: &TurboStateAugmented,
        u: &TurboInput,
    ) -> Result<TurboStateAugmented, TurboError> {
        let m = &self.inner.model;
        m.check_input(u)?;
        let d = Augmented { model: m, input: u };
        run(
            &d,
            x,
            self.inner.h,
            self.inner.substeps,
            false,
            self.inner.newton_tol,
        )
        .map(|(x, _)| x)
    }
}

fn constrain14(m: &TurboModel, x: &mut TurboStateAugmented) {
    let mut x13 = TurboState::from_fn(|i, _| x[i]);
    m.constrain(&mut x13);
    for i in 0..N_STATES {
        x[i] = x13[i];
    }
    if !x[X_DC_ETA_VOL].is_finite() {
        x[X_DC_ETA_VOL] = 0.0;
    }
}

/// As for [`TurboDiscrete`]: a failed step returns the state unchanged with `F = I`.
impl TransitionModel<N_STATES_AUGMENTED, N_INPUTS> for TurboDiscrete14 {
    fn transition(
        &self,
        x: &TurboStateAugmented,
        u: &SVector<f64, N_INPUTS>,
    ) -> TurboStateAugmented {
        self.step(x, &TurboInput::from_vector(u)).unwrap_or(*x)
    }

    fn transition_jacobian(
        &self,
        x: &TurboStateAugmented,
        u: &SVector<f64, N_INPUTS>,
    ) -> SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED> {
        self.transition_with_jacobian(x, u).1
    }

    fn transition_with_jacobian(
        &self,
        x: &TurboStateAugmented,
        u: &SVector<f64, N_INPUTS>,
    ) -> (
        TurboStateAugmented,
        SMatrix<f64, N_STATES_AUGMENTED, N_STATES_AUGMENTED>,
    ) {
        self.step_with_jacobian(x, &TurboInput::from_vector(u))
            .unwrap_or((*x, SMatrix::identity()))
    }

    fn constrain(&self, x: &mut TurboStateAugmented) {
        constrain14(&self.inner.model, x);
    }
}

impl TurboModel {
    /// Reference integration: classical RK4 with step `h` (s) over `duration` (s) with the
    /// input held, on the continuous model. Explicit, so `h` must resolve the fastest pole
    /// (`h |lambda_max| < 2.8`; 10 us gives 0.06). For tests and offline truth, not for the
    /// monitor.
    pub fn integrate_rk4(
        &self,
        x: &TurboState,
        u: &TurboInput,
        duration: f64,
        h: f64,
    ) -> TurboState {
        let n = substeps(duration, h);
        let h = duration / n as f64;
        let mut x = *x;
        for _ in 0..n {
            let k1 = self.derivative(&x, u);
            let k2 = self.derivative(&(x + k1 * (h / 2.0)), u);
            let k3 = self.derivative(&(x + k2 * (h / 2.0)), u);
            let k4 = self.derivative(&(x + k3 * h), u);
            x += (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0);
            self.constrain(&mut x);
        }
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix2;

    #[test]
    fn expm_matches_closed_forms() {
        // Rotation generator: exp([[0, -w], [w, 0]] t) = rotation by w t, large norm.
        let w = 37.0;
        let e = expm(&Matrix2::new(0.0, -w, w, 0.0)).expect("finite");
        let (s, c) = w.sin_cos();
        assert!((e - Matrix2::new(c, -s, s, c)).abs().max() < 1e-12, "{e}");
        // Stiff diagonal and a Jordan block.
        let e = expm(&Matrix2::new(-300.0, 1.0, 0.0, -300.0)).expect("finite");
        let ex = (-300.0f64).exp();
        assert!((e[(0, 0)] - ex).abs() < 1e-140 && (e[(0, 1)] - ex).abs() < 1e-140);
        let e = expm(&Matrix2::new(0.1, 2.0, 0.0, -0.2)).expect("finite");
        let want = 2.0 * (0.1f64.exp() - (-0.2f64).exp()) / 0.3;
        assert!((e[(0, 1)] - want).abs() < 1e-14);
        assert!(expm(&Matrix2::new(f64::NAN, 0.0, 0.0, 0.0)).is_none());
    }

    #[test]
    fn exponential_step_is_exact_for_linear_systems() {
        // x' = A x + b with A stiff: the step equals the exact solution at any h.
        let a = Matrix2::new(-5000.0, 10.0, 2.0, -0.3);
        let b = nalgebra::Vector2::new(100.0, 1.0);
        let x0 = nalgebra::Vector2::new(1.0, 2.0);
        let h = 0.05;
        let (x1, phi) =
            exp_euler_step::<2, 3>(&x0, &(a * x0 + b), &a, &[1.0, 1.0], h).expect("finite");
        // Exact: x(h) = e^(Ah) x0 + A^-1 (e^(Ah) - I) b.
        let e = expm(&(a * h)).expect("finite");
        let exact = e * x0 + a.try_inverse().expect("regular") * (e - Matrix2::identity()) * b;
        assert!(
            (x1 - exact).abs().max() < 1e-12 * exact.abs().max(),
            "{x1} vs {exact}"
        );
        assert!((phi - e).abs().max() < 1e-12);
        assert_eq!(substeps(0.05, 0.01), 5);
        assert_eq!(substeps(0.01, 0.01), 1);
        assert_eq!(substeps(0.011, 0.01), 2);
    }
}
