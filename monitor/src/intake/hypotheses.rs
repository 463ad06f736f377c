//! Fault isolation for the intake monitor: a bank of single-fault hypotheses fitted by least
//! squares to the residuals since the estimated fault onset (a generalized likelihood ratio
//! test with an unknown fault size and a known onset).
//!
//! Two residual channels per crank segment, both normalized by their predicted standard
//! deviation:
//!
//! - **pressure** `z_p = (MAP - MAP predicted by the MAF-only local filter) / sqrt(S_p)`. The
//!   MAF-local filter never sees the MAP: its manifold pressure is the model driven by the
//!   metered air. Any unmetered or mis-metered air makes the true pressure drift away from it
//!   along the manifold's own dynamics, and a MAP sensor error shows directly;
//! - **throttle flow** `z_w = (MAF - throttle nozzle flow at the commanded opening and the MAP
//!   reading, lagged like the MAF) / sqrt(S_w)`: sensitive to the MAF sensor, and to the MAP
//!   sensor through the flow's pressure slope `dW/dp` (zero while the throttle is choked), but
//!   not to the EGR or a leak, which move the true pressure and the true throttle flow
//!   together. `S_w` includes `(dW/dp sigma_MAP)^2`, so near ambient, where the slope is steep,
//!   the channel weighs nothing.
//!
//! How each fault moves them (`delta` = the pressure error's response through the linearized
//! manifold dynamics, `d delta/dt = j delta + R T / V u`, discretized per segment as
//! `delta+ = e^{j dt} delta + R T / V dt phi1(j dt) u`, started at 0 at the onset):
//!
//! | hypothesis | parameter | `z_p * sqrt(S_p)` | `z_w * sqrt(S_w)` |
//! |---|---|---|---|
//! | MAP sensor error | offset `b` (Pa) and gain `c` | `b + c p_ref` (immediately, no dynamics) | `-dW/dp (b + c p_ref)` |
//! | MAF sensor gain | `g - 1` | `delta` of `u = -MAF` (the filter's air is `g` times too much) | `(g - 1) MAF` |
//! | EGR valve stuck at `s` | `s` in `[0, 1]` | `delta` of `u = W_egr1 (s - e_cmd)` | 0 |
//! | EGR valve lagging its command by `tau` ([`EGR_LAGS_S`]) | scale `k` in `(0, 2]` | `k delta` of `u = W_egr1 (y - e_cmd)`, `dy/dt = (e_cmd - y) / tau` from `y = e_cmd` at the onset | 0 |
//! | leak | area `A >= 0` (m^2) | `delta` of `u = W_orifice1 A` | 0 |
//!
//! with `W_egr1` the EGR flow of a fully open valve and `W_orifice1` the flow of a unit-area
//! hole from ambient, both at the current manifold pressure. The statistic of hypothesis `i` is
//! the drop in the sum of squared normalized residuals its best-fitting parameter achieves,
//! `T_i = sum z^2 - min_theta sum (z - theta g_i)^2` (twice the log-likelihood ratio against
//! "no fault" for white unit-variance residuals); the hypotheses are ranked by `T_i`. The EGR
//! hypothesis is affine in `s` (`z = s g_1 - g_2`), so its "no fault" point is `s = e_cmd`,
//! which it only matches while the command is steady.
//!
//! Everything here is pure arithmetic on fixed-size state: no allocation, no I/O.

/// The faults the bank tells apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IntakeFault {
    /// MAP sensor range/performance (bias).
    MapSensor,
    /// MAF sensor range/performance (gain).
    MafSensor,
    /// EGR valve stuck (insufficient or excessive flow).
    EgrValve,
    /// Unmetered air leaking into the manifold.
    Leak,
}

/// Number of hypotheses.
pub const HYPOTHESES: usize = 4;

/// The hypotheses in bank order.
pub const ALL_FAULTS: [IntakeFault; HYPOTHESES] = [
    IntakeFault::MapSensor,
    IntakeFault::MafSensor,
    IntakeFault::EgrValve,
    IntakeFault::Leak,
];

impl IntakeFault {
    /// Candidate name in events.
    pub fn name(self) -> &'static str {
        match self {
            IntakeFault::MapSensor => "map_sensor",
            IntakeFault::MafSensor => "maf_sensor",
            IntakeFault::EgrValve => "egr_valve",
            IntakeFault::Leak => "manifold_leak",
        }
    }

    /// Position in [`ALL_FAULTS`] (the bank's order and the order of the diagnosis scores).
    pub fn index(self) -> usize {
        match self {
            IntakeFault::MapSensor => 0,
            IntakeFault::MafSensor => 1,
            IntakeFault::EgrValve => 2,
            IntakeFault::Leak => 3,
        }
    }
}

/// What the bank needs of one segment.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SegmentRecord {
    /// Normalized pressure residual (-), NaN when the segment has none.
    pub z_p: f64,
    /// Its standard deviation `sqrt(S_p)` (Pa).
    pub s_p: f64,
    /// Normalized throttle-flow residual (-): MAF against the throttle flow at the MAP reading,
    /// NaN when there is none.
    pub z_w: f64,
    /// Its standard deviation (kg/s).
    pub s_w: f64,
    /// Throttle flow change per Pa of MAP error, lagged like the MAF (kg/s/Pa): the MAP bias's
    /// signature in the flow residual.
    pub map_flow_gain: f64,
    /// Manifold pressure-error decay over the segment, `e^{j dt}` (-).
    pub decay: f64,
    /// Pressure change per unit inflow over the segment, `R T / V dt phi1(j dt)` (Pa s/kg).
    pub input_gain: f64,
    /// MAF reading (kg/s).
    pub maf: f64,
    /// EGR flow of the fully open valve at the current pressure (kg/s).
    pub egr_full: f64,
    /// EGR command (0..1).
    pub egr_cmd: f64,
    /// Flow through a 1 m^2 hole from ambient at the current pressure (kg/s/m^2).
    pub leak_unit: f64,
    /// Manifold pressure independent of the MAP sensor (the MAF-only filter's), Pa: what a MAP
    /// gain error multiplies.
    pub p_ref: f64,
    /// Segment length (s): the time a drifting sensor's error grows with.
    pub dt: f64,
}

/// Pressure scale of the MAP gain regressor (Pa), for conditioning.
const P_SCALE: f64 = 1e5;
/// Smallest weighted spread of the manifold pressure (Pa) over a fit for the MAP hypothesis to
/// fit a gain besides its offset.
const MAP_GAIN_MIN_SPREAD_PA: f64 = 10_000.0;
/// Statistic charged for the MAP hypothesis's second parameter, on the scale of the isolation
/// threshold (60): the gain must explain the data clearly better than an offset. A smaller
/// charge (10, the 99.8 % point of a one-dof chi-square) let the pressure-dependent signature of
/// an EGR valve stuck open pass for a MAP gain error long enough to delay its isolation by 2 s.
const MAP_GAIN_PENALTY: f64 = 60.0;
/// Smallest weighted spread of the MAF reading over a fit, relative to its mean, for the MAF
/// hypothesis to fit an offset besides its gain (the same penalty as the MAP gain applies).
const MAF_OFFSET_MIN_SPREAD_REL: f64 = 0.3;

/// Time constants (s) of the sluggish-EGR-valve hypotheses: a healthy valve follows its
/// command within about 0.1 s; these span a valve slowed five to eighty times, log-spaced so
/// that the nearest is within a factor sqrt(2) of any lag in the range (a lag off by that
/// much still explains most of the signature).
pub const EGR_LAGS_S: [f64; 9] = [0.5, 0.71, 1.0, 1.41, 2.0, 2.83, 4.0, 5.66, 8.0];
/// Number of sluggish-valve hypotheses.
const LAGS: usize = EGR_LAGS_S.len();
/// Largest scale of a sluggish valve's signature (-): the fit explains the residual as `k`
/// times the flow error of a valve lagging its command, `k` in `(0, EGR_LAG_MAX_SCALE]`
/// (about 1 when the valve's full-open flow is right; the bound keeps a signature of the right
/// shape but the wrong size from passing for a slow valve).
const EGR_LAG_MAX_SCALE: f64 = 2.0;
/// A lag is fitted only once the fit has run for `lag / EGR_LAG_SEEN` (s).
const EGR_LAG_SEEN: f64 = 0.5;

/// A valve lagging its command: the position `y` (0..1) after `dt` (s) of first-order lag
/// `tau` (s) behind the command `cmd` (exact for a command held over the step).
fn lag_step(y: f64, cmd: f64, dt: f64, tau: f64) -> f64 {
    cmd + (y - cmd) * (-dt / tau).exp()
}

/// Adds one regressor sample `h` (and the residual `z`) to a single-parameter fit's sums.
fn add_ramp(sums: &mut [f64; 2], h: f64, z: f64) {
    sums[0] += h * h;
    sums[1] += h * z;
}

/// The single-parameter fit of `sums`: `(T, theta)`.
fn ramp_fit(sums: &[f64; 2]) -> (f64, f64) {
    if sums[0] > 0.0 {
        let theta = sums[1] / sums[0];
        (theta * sums[1], theta)
    } else {
        (0.0, 0.0)
    }
}

/// The two-parameter least-squares fit of regressors with sums `[sum g^2, sum g z]`,
/// `[sum h^2, sum h z]` and `sum g h`: `(T, a, b)` for `z ~ a g + b h`, `None` when they cannot
/// be told apart.
fn two_fit(a: [f64; 2], b: [f64; 2], ab: f64) -> Option<(f64, f64, f64)> {
    let det = a[0] * b[0] - ab * ab;
    // Nearly collinear regressors (less than 1 % of independent information) say nothing.
    if !(det > 1e-2 * a[0] * b[0]) {
        return None;
    }
    let x = (b[0] * a[1] - ab * b[1]) / det;
    let y = (a[0] * b[1] - ab * a[1]) / det;
    Some((x * a[1] + y * b[1], x, y))
}

/// Steps the signature responses of a bank or a compensation through segment `r`, `tau`
/// (s) after the onset.
fn step_deltas(delta: &mut [f64; 6], r: &SegmentRecord, tau: f64) {
    let inflows = [
        -r.maf,
        r.egr_full,
        r.egr_full * r.egr_cmd,
        r.leak_unit,
        -1.0,
        -tau,
    ];
    for (d, u) in delta.iter_mut().zip(inflows) {
        *d = r.decay * *d + r.input_gain * u;
    }
}

/// Fitted size of a hypothesis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    pub fault: IntakeFault,
    /// GLR statistic `T` (-).
    pub glr: f64,
    /// Best parameter: MAP offset (Pa), MAF gain error `g - 1` (-), stuck position (0..1),
    /// hole area (m^2).
    pub parameter: f64,
    /// MAP hypothesis only: the gain error of the MAP reading (-), which adds `gain p_m` to the
    /// offset; 0 for the others.
    pub gain: f64,
    /// MAF hypothesis only: the offset of the MAF reading (kg/s), besides its gain error; 0 for
    /// the others.
    pub offset: f64,
    /// MAP and MAF hypotheses: the error's growth since the onset (Pa/s, kg/s per s) when the
    /// sensor drifts (then the other sizes are 0); 0 for the others.
    pub rate: f64,
    /// EGR hypothesis only: the time constant (s) of a sluggish valve, which then lags its
    /// command (and `parameter` is the signature's fitted scale, about 1); 0 for a valve stuck
    /// at `parameter`, and for the others.
    pub lag_s: f64,
}

/// Running least-squares sums since the onset.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HypothesisBank {
    /// Pressure responses: MAF (u = -MAF), EGR full-open (u = W_egr1), EGR command
    /// (u = W_egr1 e_cmd), leak (u = W_orifice1), MAF offset (u = -1), MAF drift (u = -tau,
    /// with tau the time since the onset).
    delta: [f64; 6],
    /// Time since the onset (s), at the end of the last segment.
    elapsed: f64,
    /// Drift regressors (an error growing linearly from the onset): MAP (`tau g_map`) and MAF
    /// (pressure: the response to `-tau`; flow: `tau / s_w`): sum h^2 and sum h z each.
    map_ramp: [f64; 2],
    maf_ramp: [f64; 2],
    /// Cross sums of each drift regressor with its sensor's offset regressor.
    map_ramp_x: f64,
    maf_ramp_x: f64,
    /// sum z^2 over both channels.
    szz: f64,
    /// Single-parameter hypotheses (MAP, MAF, leak): sum g^2 and sum g z.
    sgg: [f64; 3],
    sgz: [f64; 3],
    /// EGR: sum g1^2, sum g1 v, sum v^2 with v = z_p + g2.
    e11: f64,
    e1v: f64,
    evv: f64,
    /// Pressure-channel sum z^2 (the EGR hypothesis leaves the flow channel unexplained).
    szz_p: f64,
    /// MAP gain regressor `h = (p_ref / P_SCALE) g_map`: sum h^2, sum g_map h, sum h z.
    m22: f64,
    m12: f64,
    m2z: f64,
    /// MAF offset regressor `h` (pressure: the response to a unit inflow error, flow: 1 / s_w):
    /// sum h^2, sum g_maf h, sum h z.
    f22: f64,
    f12: f64,
    f2z: f64,
    segments: usize,
    /// The leak area may be negative: a refit on residuals from which a leak already
    /// decided is taken out (too large a compensation leaves a negative leak).
    signed_leak: bool,
    /// The EGR hypothesis is a change of the stuck position from one already taken out of
    /// the residuals (a refit while a decided EGR fault is compensated): `z = ds g1`, any sign.
    egr_relative: bool,
    /// Sluggish valve, one per [`EGR_LAGS_S`]: the lagged command (from the command at the
    /// onset), the pressure response of its flow error `u = W_egr1 (y - e_cmd)`, and the
    /// single-parameter sums (sum g^2, sum g z). Not fitted when `egr_relative`.
    lag_cmd: [f64; LAGS],
    lag_delta: [f64; LAGS],
    lag_sums: [[f64; 2]; LAGS],
}

impl HypothesisBank {
    /// A bank with nothing accumulated (onset now).
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets everything: the fault is taken to start with the next segment.
    pub fn reset(&mut self) {
        *self = Self {
            signed_leak: self.signed_leak,
            egr_relative: self.egr_relative,
            ..Self::default()
        };
    }

    /// Segments accumulated.
    pub fn segments(&self) -> usize {
        self.segments
    }

    /// Adds one segment. Residuals are not clipped: a fault's residual is large by nature, and
    /// clipping it would bias every fit towards the hypotheses with the flattest signature.
    pub fn push(&mut self, r: &SegmentRecord) {
        self.elapsed += r.dt;
        step_deltas(&mut self.delta, r, self.elapsed);
        if self.segments == 0 {
            self.lag_cmd = [r.egr_cmd; LAGS];
        }
        for ((y, d), lag) in self
            .lag_cmd
            .iter_mut()
            .zip(self.lag_delta.iter_mut())
            .zip(EGR_LAGS_S)
        {
            *y = lag_step(*y, r.egr_cmd, r.dt, lag);
            *d = r.decay * *d + r.input_gain * r.egr_full * (*y - r.egr_cmd);
        }
        self.segments += 1;
        let tau = self.elapsed;
        if r.z_p.is_finite() && r.s_p > 0.0 {
            let z = r.z_p;
            let g = [1.0 / r.s_p, self.delta[0] / r.s_p, self.delta[3] / r.s_p];
            self.szz += z * z;
            self.szz_p += z * z;
            for ((gg, gz), gi) in self.sgg.iter_mut().zip(self.sgz.iter_mut()).zip(g) {
                *gg += gi * gi;
                *gz += gi * z;
            }
            self.add_map_gain(g[0], r.p_ref, z);
            self.add_maf_offset(g[1], self.delta[4] / r.s_p, z);
            add_ramp(&mut self.map_ramp, tau * g[0], z);
            add_ramp(&mut self.maf_ramp, self.delta[5] / r.s_p, z);
            self.map_ramp_x += g[0] * tau * g[0];
            self.maf_ramp_x += self.delta[4] / r.s_p * self.delta[5] / r.s_p;
            let g1 = self.delta[1] / r.s_p;
            let v = if self.egr_relative {
                z
            } else {
                z + self.delta[2] / r.s_p
            };
            self.e11 += g1 * g1;
            self.e1v += g1 * v;
            self.evv += v * v;
            for (sums, d) in self.lag_sums.iter_mut().zip(self.lag_delta) {
                add_ramp(sums, d / r.s_p, z);
            }
        }
        if r.z_w.is_finite() && r.s_w > 0.0 {
            let z = r.z_w;
            let g_map = -r.map_flow_gain / r.s_w;
            let g_maf = r.maf / r.s_w;
            self.szz += z * z;
            self.sgg[0] += g_map * g_map;
            self.sgz[0] += g_map * z;
            self.add_map_gain(g_map, r.p_ref, z);
            self.sgg[1] += g_maf * g_maf;
            self.sgz[1] += g_maf * z;
            self.add_maf_offset(g_maf, 1.0 / r.s_w, z);
            add_ramp(&mut self.map_ramp, tau * g_map, z);
            add_ramp(&mut self.maf_ramp, tau / r.s_w, z);
            self.map_ramp_x += g_map * tau * g_map;
            self.maf_ramp_x += 1.0 / r.s_w * tau / r.s_w;
        }
    }

    /// The MAF offset regressor's sums.
    fn add_maf_offset(&mut self, g: f64, h: f64, z: f64) {
        self.f22 += h * h;
        self.f12 += g * h;
        self.f2z += h * z;
    }

    /// The MAF hypothesis: reading error `(g - 1) MAF + b` fitted by least squares (gain only
    /// when the flow has not moved enough to tell an offset from a gain). Returns
    /// `(T, g - 1, b)`.
    fn maf_fit(&self) -> (f64, f64, f64) {
        let (s11, s1z) = (self.sgg[1], self.sgz[1]);
        if !(s11 > 0.0) {
            return (0.0, 0.0, 0.0);
        }
        let g0 = s1z / s11;
        let gain_only = (g0 * s1z, g0, 0.0);
        // The gain regressor is about MAF times the offset regressor: the flow's weighted
        // spread relative to its mean tells them apart.
        if !(self.f22 > 0.0) {
            return gain_only;
        }
        let mean = self.f12 / self.f22;
        let spread = (s11 / self.f22 - mean * mean).max(0.0).sqrt();
        if !(mean > 0.0) || spread < MAF_OFFSET_MIN_SPREAD_REL * mean {
            return gain_only;
        }
        let det = s11 * self.f22 - self.f12 * self.f12;
        if !(det > 0.0) {
            return gain_only;
        }
        let g = (self.f22 * s1z - self.f12 * self.f2z) / det;
        let b = (s11 * self.f2z - self.f12 * s1z) / det;
        let t = g * s1z + b * self.f2z - MAP_GAIN_PENALTY;
        if t > gain_only.0 {
            (t, g, b)
        } else {
            gain_only
        }
    }

    /// The MAP gain regressor's sums, for one channel's offset regressor `g`.
    fn add_map_gain(&mut self, g: f64, p_ref: f64, z: f64) {
        if !p_ref.is_finite() {
            return;
        }
        let h = p_ref / P_SCALE * g;
        self.m22 += h * h;
        self.m12 += g * h;
        self.m2z += h * z;
    }

    /// The MAP hypothesis: reading error `b + gain p_ref` fitted by least squares (offset only
    /// when the pressure has not moved enough to tell a gain from an offset). Returns
    /// `(T, b, gain)`.
    fn map_fit(&self) -> (f64, f64, f64) {
        let (s11, s1z) = (self.sgg[0], self.sgz[0]);
        if !(s11 > 0.0) {
            return (0.0, 0.0, 0.0);
        }
        let b0 = s1z / s11;
        let offset_only = (b0 * s1z, b0, 0.0);
        // A gain is told from an offset only by pressures that differ: the weighted spread of
        // p_ref over the fit must reach MAP_GAIN_MIN_SPREAD_PA.
        let mean = self.m12 / s11;
        let spread = (self.m22 / s11 - mean * mean).max(0.0).sqrt() * P_SCALE;
        if spread < MAP_GAIN_MIN_SPREAD_PA {
            return offset_only;
        }
        let det = s11 * self.m22 - self.m12 * self.m12;
        if !(det > 0.0) {
            return offset_only;
        }
        let b = (self.m22 * s1z - self.m12 * self.m2z) / det;
        let c = (s11 * self.m2z - self.m12 * s1z) / det;
        // The extra parameter costs MAP_GAIN_PENALTY (it would otherwise always fit better).
        let t = b * s1z + c * self.m2z - MAP_GAIN_PENALTY;
        if t > offset_only.0 {
            (t, b, c / P_SCALE)
        } else {
            offset_only
        }
    }

    /// Best fit of every hypothesis, in bank order ([`ALL_FAULTS`]).
    pub fn fits(&self) -> [Fit; HYPOTHESES] {
        self.fits_with(true)
    }

    /// The fit of one sensor's error without its drift forms (a step: offset and gain only),
    /// or with them (`drift`). A refit of a decided sensor fault over all the data since its
    /// onset takes a drift only where the evidence asked for one: under a slow sweep of the
    /// operating point a gain error also looks like a drift, and a drift extrapolated past the
    /// sweep's turn leaves an error growing in the wrong direction.
    pub fn fit_form(&self, fault: IntakeFault, drift: bool) -> Fit {
        self.fits_with(drift)[fault.index()]
    }

    fn fits_with(&self, drift: bool) -> [Fit; HYPOTHESES] {
        let one = |i: usize, nonneg: bool| -> (f64, f64) {
            if !(self.sgg[i] > 0.0) {
                return (0.0, 0.0);
            }
            let theta = self.sgz[i] / self.sgg[i];
            if nonneg && theta < 0.0 {
                return (0.0, 0.0);
            }
            (self.sgz[i] * theta, theta)
        };
        // Each sensor's error as a step (offset and gain) or as a drift from the onset,
        // whichever explains more.
        let (mut t_map, mut b, mut map_gain, mut map_rate) = {
            let (t, b, c) = self.map_fit();
            (t, b, c, 0.0)
        };
        let (t_r, r) = ramp_fit(&self.map_ramp);
        if drift && t_r > t_map {
            (t_map, b, map_gain, map_rate) = (t_r, 0.0, 0.0, r);
        }
        if let Some((t, b2, r2)) =
            two_fit([self.sgg[0], self.sgz[0]], self.map_ramp, self.map_ramp_x).filter(|_| drift)
        {
            if t - MAP_GAIN_PENALTY > t_map {
                (t_map, b, map_gain, map_rate) = (t - MAP_GAIN_PENALTY, b2, 0.0, r2);
            }
        }
        let (mut t_maf, mut g, mut maf_offset, mut maf_rate) = {
            let (t, g, b) = self.maf_fit();
            (t, g, b, 0.0)
        };
        let (t_r, r) = ramp_fit(&self.maf_ramp);
        if drift && t_r > t_maf {
            (t_maf, g, maf_offset, maf_rate) = (t_r, 0.0, 0.0, r);
        }
        let (t_b, b_off) = ramp_fit(&[self.f22, self.f2z]);
        if t_b > t_maf {
            (t_maf, g, maf_offset, maf_rate) = (t_b, 0.0, b_off, 0.0);
        }
        if let Some((t, b2, r2)) =
            two_fit([self.f22, self.f2z], self.maf_ramp, self.maf_ramp_x).filter(|_| drift)
        {
            if t - MAP_GAIN_PENALTY > t_maf {
                (t_maf, g, maf_offset, maf_rate) = (t - MAP_GAIN_PENALTY, 0.0, b2, r2);
            }
        }
        let (t_leak, a) = one(2, !self.signed_leak);
        // EGR: minimize sum (v - s g1)^2 over s in [0, 1]; the statistic is the drop from the
        // no-fault sum z_p^2 (can be negative when the command moved: then it explains nothing).
        let (t_egr, s) = if self.e11 > 0.0 {
            let (lo, hi) = if self.egr_relative {
                (-1.0, 1.0)
            } else {
                (0.0, 1.0)
            };
            let s = (self.e1v / self.e11).clamp(lo, hi);
            let rss = self.evv - 2.0 * s * self.e1v + s * s * self.e11;
            ((self.szz_p - rss).max(0.0), s)
        } else {
            (0.0, 0.0)
        };
        let (t_egr, s, egr_lag) = match self.sluggish_fit() {
            Some((t, k, lag)) if t > t_egr => (t, k, lag),
            _ => (t_egr, s, 0.0),
        };
        [
            Fit {
                fault: IntakeFault::MapSensor,
                glr: t_map,
                parameter: b,
                gain: map_gain,
                offset: 0.0,
                rate: map_rate,
                lag_s: 0.0,
            },
            Fit {
                fault: IntakeFault::MafSensor,
                glr: t_maf,
                parameter: g,
                gain: 0.0,
                offset: maf_offset,
                rate: maf_rate,
                lag_s: 0.0,
            },
            Fit {
                fault: IntakeFault::EgrValve,
                glr: t_egr,
                parameter: s,
                gain: 0.0,
                offset: 0.0,
                rate: 0.0,
                lag_s: egr_lag,
            },
            Fit {
                fault: IntakeFault::Leak,
                glr: t_leak,
                parameter: a,
                gain: 0.0,
                offset: 0.0,
                rate: 0.0,
                lag_s: 0.0,
            },
        ]
    }

    /// The best sluggish-valve hypothesis: `(T, k, lag_s)` for the residual fitted as `k` times
    /// the signature of a valve lagging its command by `lag_s`, `k` in `(0, EGR_LAG_MAX_SCALE]`;
    /// `None` in a refit relative to a decided EGR fault, or when no lag explains anything.
    fn sluggish_fit(&self) -> Option<(f64, f64, f64)> {
        if self.egr_relative {
            return None;
        }
        let mut best: Option<(f64, f64, f64)> = None;
        for (sums, lag) in self.lag_sums.iter().zip(EGR_LAGS_S) {
            // Within its first time constants a slow valve has hardly moved: its signature is
            // a stuck valve's (closed, or at the command at the onset). Only lags the fit has
            // seen twice over (the valve 86 % of the way) tell it.
            if !(sums[0] > 0.0 && sums[1] > 0.0) || lag > EGR_LAG_SEEN * self.elapsed {
                continue;
            }
            let k = (sums[1] / sums[0]).min(EGR_LAG_MAX_SCALE);
            let t = 2.0 * k * sums[1] - k * k * sums[0];
            if best.is_none_or(|b| t > b.0) {
                best = Some((t, k, lag));
            }
        }
        // A best lag at the longest time constant is a valve slower than any the bank
        // describes: under a command that has not moved much it is told from a valve stuck
        // closed only by its size, so it is left to the stuck hypothesis (named sluggish first,
        // such a valve would be named again as stuck).
        best.filter(|b| b.2 < EGR_LAGS_S[LAGS - 1])
    }

    /// The sluggish valve of time constant `lag_s` (one of [`EGR_LAGS_S`]): its lagged command
    /// and pressure response now, for a compensation to continue from.
    fn lag_state(&self, lag_s: f64) -> (f64, f64) {
        EGR_LAGS_S
            .iter()
            .position(|&l| l == lag_s)
            .map_or((f64::NAN, 0.0), |j| (self.lag_cmd[j], self.lag_delta[j]))
    }

    /// Hypotheses sorted by decreasing statistic.
    pub fn ranked(&self) -> [Fit; HYPOTHESES] {
        let mut f = self.fits();
        f.sort_unstable_by(|a, b| b.glr.total_cmp(&a.glr));
        f
    }

    /// The fit of one hypothesis.
    pub fn fit(&self, fault: IntakeFault) -> Fit {
        self.fits()[fault.index()]
    }

    /// The pressure responses since the onset (MAF, EGR full-open, EGR command, leak, MAF
    /// offset): the
    /// state a [`Compensation`] of a fault fitted from this bank continues from.
    pub fn deltas(&self) -> [f64; 6] {
        self.delta
    }

    /// Time since the onset (s).
    pub fn elapsed(&self) -> f64 {
        self.elapsed
    }
}

/// A decided fault's fitted size, and its effect on the residuals predicted forward. The
/// monitor takes the fault out of its inputs (a sensor's reading corrected by
/// [`Compensation::correct`], the decided EGR position or the leak's flow given to the model),
/// so the residuals test the rest for new faults; the predicted effect ([`Compensation::step`])
/// tells the fault's disappearance from its persistence (healing).
///
/// It runs the signature recursions of [`HypothesisBank`] for one hypothesis with the size
/// fixed, starting from the responses of the bank it was fitted in ([`HypothesisBank::deltas`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Compensation {
    pub fault: IntakeFault,
    /// Fitted size (see [`Fit::parameter`]) and, for the MAP, the gain error.
    pub parameter: f64,
    pub gain: f64,
    /// MAF only: the offset (kg/s).
    pub offset: f64,
    /// MAP and MAF: the drift rate (Pa/s, kg/s per s).
    pub rate: f64,
    /// EGR: the time constant (s) of a sluggish valve (then `parameter` is the signature's
    /// scale), 0 for a stuck one.
    pub lag_s: f64,
    delta: [f64; 6],
    /// Sluggish valve: the lagged command (0..1) and the pressure response of its flow error.
    lag_cmd: f64,
    lag_delta: f64,
    /// Time since the fault's onset (s).
    elapsed: f64,
}

impl Compensation {
    /// The compensation of `fit`, fitted in `bank`.
    pub fn new(fit: &Fit, bank: &HypothesisBank) -> Self {
        let (lag_cmd, lag_delta) = bank.lag_state(fit.lag_s);
        Self {
            fault: fit.fault,
            parameter: fit.parameter,
            gain: fit.gain,
            offset: fit.offset,
            rate: fit.rate,
            lag_s: fit.lag_s,
            delta: bank.deltas(),
            lag_cmd,
            lag_delta,
            elapsed: bank.elapsed(),
        }
    }

    /// The EGR position the model should be given for the command `cmd` held for the next
    /// `dt` (s): the stuck position, or the sluggish valve's lagged command (scaled like its
    /// fitted signature); `None` for the other faults.
    pub fn egr_position(&self, cmd: f64, dt: f64) -> Option<f64> {
        match self.fault {
            IntakeFault::EgrValve if self.lag_s > 0.0 && self.lag_cmd.is_finite() => {
                let y = lag_step(self.lag_cmd, cmd, dt, self.lag_s);
                Some((cmd + self.parameter * (y - cmd)).clamp(0.0, 1.0))
            }
            IntakeFault::EgrValve => Some(self.parameter),
            _ => None,
        }
    }

    /// Adds a refinement fitted on the residuals this compensation leaves (the same hypothesis,
    /// from a later onset, in `bank`): the sizes add (the signatures are linear in the sizes
    /// and, once the manifold has settled, the same from either onset; a drift fitted from the
    /// later onset is a drift from the first onset less the offset it had reached then). The
    /// EGR position's refit, made with the decided position as the model's input, is the
    /// position itself.
    pub fn refine(&mut self, fit: &Fit, bank: &HypothesisBank) {
        if fit.fault != self.fault {
            return;
        }
        let lag = self.elapsed - bank.elapsed();
        match self.fault {
            IntakeFault::MapSensor => {
                self.parameter += fit.parameter - fit.rate * lag;
                self.gain += fit.gain;
                self.rate += fit.rate;
            }
            IntakeFault::MafSensor => {
                self.parameter += fit.parameter;
                self.offset += fit.offset - fit.rate * lag;
                self.rate += fit.rate;
            }
            // The filters are given the decided position as the EGR input, so a refit is the
            // position itself. A sluggish valve's refit (a stuck position relative to the
            // lagged command it is compensated with) does not describe a lag: it stays.
            IntakeFault::EgrValve if self.lag_s > 0.0 => {}
            IntakeFault::EgrValve => self.parameter = fit.parameter,
            IntakeFault::Leak => self.parameter += fit.parameter,
        }
    }

    /// The reading with the decided sensor error taken out, `tau_ahead` (s) after the last
    /// segment stepped: MAP `(y - b - r tau) / (1 + c)`, MAF `(y - b - r tau) / (1 + g)`; other
    /// faults leave it as it is.
    pub fn correct(&self, y: f64, tau_ahead: f64) -> f64 {
        let tau = self.elapsed + tau_ahead;
        match self.fault {
            IntakeFault::MapSensor => (y - self.parameter - self.rate * tau) / (1.0 + self.gain),
            IntakeFault::MafSensor => (y - self.offset - self.rate * tau) / (1.0 + self.parameter),
            IntakeFault::EgrValve | IntakeFault::Leak => y,
        }
    }

    /// The size of the error this compensation removes now, at the reading `y` of its sensor
    /// (MAP in Pa, MAF in kg/s; the leak's area), comparable across its refinements; `None`
    /// for the EGR valve, whose "no fault" is not a size.
    pub fn magnitude(&self, y: f64) -> Option<f64> {
        match self.fault {
            IntakeFault::MapSensor => {
                Some((self.parameter + self.gain * y + self.rate * self.elapsed).abs())
            }
            IntakeFault::MafSensor => {
                Some((self.parameter * y + self.offset + self.rate * self.elapsed).abs())
            }
            IntakeFault::EgrValve => None,
            IntakeFault::Leak => Some(self.parameter.abs()),
        }
    }

    /// Steps the responses with segment `r` and returns the fault's predicted effect on the
    /// pressure residual (Pa) and on the throttle-flow residual (kg/s).
    pub fn step(&mut self, r: &SegmentRecord) -> (f64, f64) {
        self.elapsed += r.dt;
        step_deltas(&mut self.delta, r, self.elapsed);
        if self.lag_s > 0.0 && self.lag_cmd.is_finite() {
            self.lag_cmd = lag_step(self.lag_cmd, r.egr_cmd, r.dt, self.lag_s);
            self.lag_delta =
                r.decay * self.lag_delta + r.input_gain * r.egr_full * (self.lag_cmd - r.egr_cmd);
        }
        match self.fault {
            IntakeFault::MapSensor => {
                let e = self.parameter
                    + self.rate * self.elapsed
                    + if r.p_ref.is_finite() {
                        self.gain * r.p_ref
                    } else {
                        0.0
                    };
                (e, -r.map_flow_gain * e)
            }
            IntakeFault::MafSensor => (
                self.parameter * self.delta[0]
                    + self.offset * self.delta[4]
                    + self.rate * self.delta[5],
                self.parameter * r.maf + self.offset + self.rate * self.elapsed,
            ),
            IntakeFault::EgrValve if self.lag_s > 0.0 => (self.parameter * self.lag_delta, 0.0),
            IntakeFault::EgrValve => (self.parameter * self.delta[1] - self.delta[2], 0.0),
            IntakeFault::Leak => (self.parameter * self.delta[3], 0.0),
        }
    }
}

/// Candidate onsets scanned by [`OnsetScan`].
pub const ONSETS: usize = 16;

/// The bank fitted from several candidate onsets at once (the generalized likelihood ratio with
/// an unknown change time). The test that raised the alarm bounds the onset: it is before the
/// alarm, and after the last time the test's CUSUM was zero, less a few segments. That bound is
/// loose (a CUSUM fed with slightly biased residuals can stay above zero for a long time), and a
/// bank started at the wrong time misreads the fault: started late, on a fault that builds up
/// along the manifold dynamics, it takes the rise already present for a step (a MAP bias). The
/// scan starts one bank at each of [`ONSETS`] onsets spread evenly over the bounds and takes,
/// for each hypothesis, its best statistic over the onsets.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OnsetScan {
    banks: [HypothesisBank; ONSETS],
    onsets: [u64; ONSETS],
}

impl OnsetScan {
    /// A scan over onsets from `earliest` to `latest` (segment indices, inclusive).
    pub fn new(earliest: u64, latest: u64) -> Self {
        Self::with_modes(earliest, latest, false, false)
    }

    /// [`OnsetScan::new`] for a refit on residuals from which decided faults are taken out:
    /// with a leak area of either sign when `signed_leak` (a decided leak's compensation may
    /// be too large), and the EGR hypothesis as a change of the stuck position, of either sign,
    /// when `egr_relative` (a decided EGR fault is compensated).
    pub fn with_modes(earliest: u64, latest: u64, signed_leak: bool, egr_relative: bool) -> Self {
        let latest = latest.max(earliest);
        let span = (latest - earliest) as f64;
        let mut onsets = [earliest; ONSETS];
        for (j, o) in onsets.iter_mut().enumerate() {
            *o = earliest + (span * j as f64 / (ONSETS - 1) as f64).round() as u64;
        }
        let bank = HypothesisBank {
            signed_leak,
            egr_relative,
            ..HypothesisBank::new()
        };
        Self {
            banks: [bank; ONSETS],
            onsets,
        }
    }

    /// The earliest candidate onset (segment index).
    pub fn earliest_onset(&self) -> u64 {
        self.onsets[0]
    }

    /// Adds segment `k` to every bank whose onset is at or before it.
    pub fn push(&mut self, k: u64, r: &SegmentRecord) {
        for (bank, &onset) in self.banks.iter_mut().zip(&self.onsets) {
            if k >= onset {
                bank.push(r);
            }
        }
    }

    /// The bank (candidate onset) in which `fault` fits best.
    pub fn best_bank(&self, fault: IntakeFault) -> &HypothesisBank {
        let mut best = &self.banks[0];
        let mut glr = f64::NEG_INFINITY;
        for bank in &self.banks {
            let g = bank.fit(fault).glr;
            if g > glr {
                glr = g;
                best = bank;
            }
        }
        best
    }

    /// For each hypothesis its best fit over the candidate onsets, sorted by decreasing
    /// statistic.
    pub fn ranked(&self) -> [Fit; HYPOTHESES] {
        let mut best = self.banks[0].fits();
        for bank in &self.banks[1..] {
            for (b, f) in best.iter_mut().zip(bank.fits()) {
                if f.glr > b.glr {
                    *b = f;
                }
            }
        }
        best.sort_unstable_by(|a, b| b.glr.total_cmp(&a.glr));
        best
    }
}

/// Fixed-capacity history of segment records, so that a bank can be refitted from an onset
/// estimated after the fact.
#[derive(Debug, Clone)]
pub struct RecordRing {
    buf: Box<[SegmentRecord]>,
    head: usize,
    len: usize,
}

impl RecordRing {
    /// A ring of `capacity` records (allocated once, here).
    pub fn new(capacity: usize) -> Self {
        Self {
            buf: vec![SegmentRecord::default(); capacity.max(1)].into_boxed_slice(),
            head: 0,
            len: 0,
        }
    }

    /// Appends a record, dropping the oldest when full.
    pub fn push(&mut self, r: SegmentRecord) {
        let cap = self.buf.len();
        self.buf[self.head] = r;
        self.head = (self.head + 1) % cap;
        self.len = (self.len + 1).min(cap);
    }

    /// Records held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
    }

    /// The last `n` records (at most all held), oldest first.
    pub fn last(&self, n: usize) -> impl Iterator<Item = &SegmentRecord> {
        let cap = self.buf.len();
        let n = n.min(self.len);
        let start = (self.head + cap - n) % cap;
        (0..n).map(move |i| &self.buf[(start + i) % cap])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(z_p: f64, z_w: f64, maf: f64, egr_cmd: f64) -> SegmentRecord {
        SegmentRecord {
            z_p,
            s_p: 800.0,
            z_w,
            s_w: 3e-4,
            map_flow_gain: -2e-8,
            decay: 0.85,
            input_gain: 3.5e5,
            maf,
            egr_full: 0.011,
            egr_cmd,
            leak_unit: 240.0,
            p_ref: 50_000.0,
            dt: 0.02,
        }
    }

    /// Feeds the bank what a fault of each kind would produce and checks it is ranked first
    /// with the right size.
    fn simulate(fault: IntakeFault, theta: f64) -> HypothesisBank {
        let mut bank = HypothesisBank::new();
        let (mut d_maf, mut d_e, mut d_leak) = (0.0, 0.0, 0.0);
        for k in 0..200 {
            // Operating point and EGR command changing over time.
            let maf = 0.01 + 0.02 * ((k / 40) % 2) as f64;
            let cmd = if (k / 25) % 2 == 0 { 0.0 } else { 0.3 };
            let mut r = record(0.0, f64::NAN, maf, cmd);
            d_maf = r.decay * d_maf + r.input_gain * (-maf);
            d_e = r.decay * d_e + r.input_gain * r.egr_full * (theta - cmd);
            d_leak = r.decay * d_leak + r.input_gain * r.leak_unit;
            let choked = k % 2 == 0;
            let (p, w) = match fault {
                IntakeFault::MapSensor => (theta, -r.map_flow_gain * theta),
                IntakeFault::MafSensor => (theta * d_maf, theta * maf),
                IntakeFault::EgrValve => (d_e, 0.0),
                IntakeFault::Leak => (theta * d_leak, 0.0),
            };
            r.z_p = p / r.s_p;
            r.z_w = if choked { w / r.s_w } else { f64::NAN };
            bank.push(&r);
        }
        bank
    }

    #[test]
    fn each_noise_free_signature_ranks_its_own_hypothesis_first() {
        for (fault, theta) in [
            (IntakeFault::MapSensor, 5000.0),
            (IntakeFault::MafSensor, 0.1),
            (IntakeFault::EgrValve, 0.3),
            (IntakeFault::Leak, 7.07e-6),
        ] {
            let bank = simulate(fault, theta);
            let ranked = bank.ranked();
            assert_eq!(ranked[0].fault, fault, "{fault:?}: {ranked:?}");
            let rel = (ranked[0].parameter - theta).abs() / theta;
            assert!(
                rel < 1e-9,
                "{fault:?}: fitted {} vs {theta}",
                ranked[0].parameter
            );
            assert!(ranked[0].glr > ranked[1].glr + 1.0, "{ranked:?}");
        }
    }

    /// A valve lagging its command by 2 s (one of the bank's time constants), the command
    /// stepping every second and a half: the EGR hypothesis fits it as sluggish, scale 1 and
    /// lag 2 s, better than any stuck position and than every other hypothesis; the
    /// compensation built from the fit predicts the residual it leaves from then on, and hands
    /// the model the lagged position.
    #[test]
    fn a_sluggish_egr_valve_is_fitted_as_one() {
        let lag = 2.0;
        let cmd_at = |k: usize| if (k / 75) % 2 == 0 { 0.1 } else { 0.4 };
        let mut bank = HypothesisBank::new();
        let (mut y, mut d) = (cmd_at(0), 0.0);
        let step = |k: usize, y: &mut f64, d: &mut f64| {
            let cmd = cmd_at(k);
            let mut r = record(0.0, f64::NAN, 0.02, cmd);
            *y = cmd + (*y - cmd) * (-r.dt / lag).exp();
            *d = r.decay * *d + r.input_gain * r.egr_full * (*y - cmd);
            r.z_p = *d / r.s_p;
            r
        };
        for k in 0..600 {
            bank.push(&step(k, &mut y, &mut d));
        }
        let ranked = bank.ranked();
        let egr = ranked[0];
        assert_eq!(egr.fault, IntakeFault::EgrValve, "{ranked:?}");
        assert_eq!(egr.lag_s, lag, "{egr:?}");
        assert!((egr.parameter - 1.0).abs() < 1e-9, "{egr:?}");
        assert!(egr.glr > ranked[1].glr + 100.0, "{ranked:?}");
        let mut comp = Compensation::new(&egr, &bank);
        for k in 600..900 {
            let r = step(k, &mut y, &mut d);
            let pos = comp.egr_position(r.egr_cmd, r.dt).unwrap_or(f64::NAN);
            assert!((pos - y).abs() < 1e-12, "segment {k}: {pos} vs {y}");
            let (p, w) = comp.step(&r);
            assert!(
                (p - d).abs() < 1e-6 * d.abs().max(1.0),
                "segment {k}: {p} vs {d}"
            );
            assert_eq!(w, 0.0);
        }
    }

    /// A MAP gain error (the reading off by 8 % of the pressure) while the pressure moves: the
    /// MAP hypothesis fits offset 0 and gain 0.08 exactly and wins.
    #[test]
    fn map_gain_error_is_fitted_as_a_gain() {
        let mut bank = HypothesisBank::new();
        for k in 0..200 {
            let mut r = record(
                0.0,
                f64::NAN,
                0.02,
                if (k / 25) % 2 == 0 { 0.0 } else { 0.3 },
            );
            r.p_ref = if (k / 40) % 2 == 0 {
                30_000.0
            } else {
                95_000.0
            };
            r.map_flow_gain = if r.p_ref < 50_000.0 { 0.0 } else { -1e-7 };
            let err = 0.08 * r.p_ref;
            r.z_p = err / r.s_p;
            r.z_w = -r.map_flow_gain * err / r.s_w;
            bank.push(&r);
        }
        let ranked = bank.ranked();
        assert_eq!(ranked[0].fault, IntakeFault::MapSensor, "{ranked:?}");
        assert!(ranked[0].parameter.abs() < 1e-6, "{ranked:?}");
        assert!((ranked[0].gain - 0.08).abs() < 1e-12, "{ranked:?}");
    }

    #[test]
    fn no_residual_gives_no_evidence() {
        let mut bank = HypothesisBank::new();
        for k in 0..100 {
            bank.push(&record(0.0, 0.0, 0.02, if k < 50 { 0.0 } else { 0.3 }));
        }
        for f in bank.fits() {
            assert!(f.glr.abs() < 1e-12, "{f:?}");
        }
    }

    #[test]
    fn leak_area_and_egr_position_respect_their_bounds() {
        // A negative pressure residual cannot be a leak (area >= 0).
        let mut bank = HypothesisBank::new();
        for _ in 0..50 {
            bank.push(&record(-3.0, f64::NAN, 0.02, 0.0));
        }
        let leak = bank.fit(IntakeFault::Leak);
        assert_eq!(leak.glr, 0.0);
        assert_eq!(leak.parameter, 0.0);
        let egr = bank.fit(IntakeFault::EgrValve);
        assert!((0.0..=1.0).contains(&egr.parameter));
    }

    /// A fault that builds up along the manifold dynamics, seen from an onset estimate that is
    /// late (partway up the rise): a single bank started there misfits it, the onset scan finds
    /// the true onset, the right hypothesis and its exact size.
    #[test]
    fn onset_scan_recovers_a_late_onset_estimate() {
        let true_onset = 40u64;
        let mut records = Vec::new();
        let mut d_leak = 0.0;
        for k in 0..120u64 {
            // Operating point moving, so the flow hypotheses' shapes differ.
            let mut r = record(0.0, f64::NAN, 0.01 + 0.0005 * (k % 30) as f64, 0.0);
            r.leak_unit = if (k / 15) % 2 == 0 { 240.0 } else { 120.0 };
            if k >= true_onset {
                d_leak = r.decay * d_leak + r.input_gain * r.leak_unit;
            }
            r.z_p = 7.07e-6 * d_leak / r.s_p;
            records.push(r);
        }
        let late = true_onset + 6;
        let mut single = HypothesisBank::new();
        for r in &records[late as usize..] {
            single.push(r);
        }
        // Started late, the bank misreads the rise: the leak's size comes out wrong.
        let single_leak = single.fit(IntakeFault::Leak);
        assert!(
            (single_leak.parameter - 7.07e-6).abs() > 1e-3 * 7.07e-6,
            "{single_leak:?}"
        );
        let mut scan = OnsetScan::new(late - 15, late);
        assert!(scan.earliest_onset() <= true_onset);
        for (k, r) in records.iter().enumerate() {
            scan.push(k as u64, r);
        }
        let ranked = scan.ranked();
        assert_eq!(ranked[0].fault, IntakeFault::Leak, "{ranked:?}");
        assert!((ranked[0].parameter - 7.07e-6).abs() < 1e-9 * 7.07e-6);
        assert!(ranked[0].glr > single_leak.glr);
    }

    #[test]
    fn ring_returns_the_last_records_in_order() {
        let mut ring = RecordRing::new(4);
        for k in 0..6 {
            ring.push(record(k as f64, 0.0, 0.0, 0.0));
        }
        let got: Vec<f64> = ring.last(3).map(|r| r.z_p).collect();
        assert_eq!(got, vec![3.0, 4.0, 5.0]);
        let all: Vec<f64> = ring.last(10).map(|r| r.z_p).collect();
        assert_eq!(all, vec![2.0, 3.0, 4.0, 5.0]);
    }
}
