//! The right-hand side `dx/dt = f(x, u)`: every component evaluated once at the state and
//! input, and the balances of the six volumes and the shaft.

use super::ad::Scalar;
use super::compressor::Compressor;
use super::cylinder::Cylinders;
use super::restriction::Restriction;
use super::shaft::Shaft;
use super::throttle::Throttle;
use super::turbine::Turbine;
use super::volumes::{Balance, Gas};
use super::wastegate::Wastegate;
use super::*;

/// Lowest gas density the evaluation uses (kg/m^3): a mass below `V` times this (a state a
/// filter's sigma point or a Newton iterate pushed out of the physical set) is evaluated as
/// this mass, about 100 Pa at 300 K, so that no flow divides by zero.
pub const MIN_DENSITY_KG_M3: f64 = 1e-3;
/// Temperatures are evaluated clamped to this range (K).
pub const TEMPERATURE_RANGE_K: (f64, f64) = (150.0, 3000.0);

/// Everything the model computes at one state and input, generic over the scalar so that the
/// same evaluation gives gradients (with [`super::ad::Dual`]). Pressures in Pa, temperatures
/// in K, flows in kg/s, torques in N m. Flow signs: positive in the direction of the air path
/// (ambient, air filter, compressor, intercooler, throttle, manifold, cylinders, exhaust
/// manifold, turbine or wastegate, exhaust system, ambient).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurboSignals<S = f64> {
    /// Air filter volume pressure (compressor inlet).
    pub p_af_pa: S,
    /// Compressor outlet volume pressure.
    pub p_c_pa: S,
    /// Intercooler / throttle inlet pressure (boost pressure).
    pub p_ic_pa: S,
    /// Intake manifold pressure.
    pub p_im_pa: S,
    /// Exhaust manifold pressure.
    pub p_em_pa: S,
    /// Exhaust system pressure after the turbine.
    pub p_es_pa: S,
    /// Air filter volume temperature.
    pub t_af_k: S,
    /// Compressor outlet volume temperature.
    pub t_c_k: S,
    /// Intercooler volume temperature (throttle inlet).
    pub t_ic_k: S,
    /// Intake manifold temperature.
    pub t_im_k: S,
    /// Exhaust manifold temperature.
    pub t_em_k: S,
    /// Exhaust system temperature.
    pub t_es_k: S,
    /// Turbo speed as the components see it (the state limited to its range) (rad/s).
    pub omega_t_rad_s: S,
    /// Air filter flow (the MAF sensor's flow).
    pub w_af_kg_s: S,
    /// Compressor flow.
    pub w_c_kg_s: S,
    /// Intercooler flow.
    pub w_ic_kg_s: S,
    /// Throttle flow.
    pub w_thr_kg_s: S,
    /// Air flow into the cylinders.
    pub w_ei_kg_s: S,
    /// Fuel flow.
    pub w_f_kg_s: S,
    /// Exhaust flow out of the cylinders.
    pub w_eo_kg_s: S,
    /// Turbine flow.
    pub w_t_kg_s: S,
    /// Wastegate flow.
    pub w_wg_kg_s: S,
    /// Exhaust system flow to ambient.
    pub w_es_kg_s: S,
    /// Compressor outlet temperature of a forward flow.
    pub t_c_out_k: S,
    /// Intercooler outlet temperature of a forward flow.
    pub t_ic_out_k: S,
    /// Engine-out exhaust temperature.
    pub t_eo_k: S,
    /// Exhaust temperature entering the exhaust manifold, after the pipe heat loss.
    pub t_em_in_k: S,
    /// Temperature of the turbine flow entering the exhaust system.
    pub t_t_out_k: S,
    /// Compressor pressure ratio `p_c / p_af`.
    pub pi_c: S,
    /// Compressor head parameter.
    pub psi_c: S,
    /// Compressor flow parameter.
    pub phi_c: S,
    /// Compressor efficiency.
    pub eta_c: S,
    /// Compressor torque.
    pub tq_c_nm: S,
    /// Turbine efficiency.
    pub eta_t: S,
    /// Turbine blade speed ratio.
    pub bsr_t: S,
    /// Turbine torque.
    pub tq_t_nm: S,
    /// Volumetric-efficiency factor `C_eta_vol p(p_im) + dC_eta_vol`.
    pub eta_vol_factor: S,
    /// The state derivative (13 states, [`X_M_AF`] ..).
    pub dxdt: [S; N_STATES],
}

/// The component constants, built once from the parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Consts {
    pub air: Gas,
    pub exh: Gas,
    /// Volumes (m^3) in state order.
    pub volume: [f64; 6],
    pub air_filter: Restriction,
    pub intercooler: Restriction,
    pub ic_eps: f64,
    pub exhaust: Restriction,
    pub compressor: Compressor,
    pub throttle: Throttle,
    pub cylinders: Cylinders,
    pub wastegate: Wastegate,
    pub turbine: Turbine,
    pub shaft: Shaft,
}

impl Consts {
    pub fn new(p: &TurboParams) -> Self {
        use super::nozzle::Nozzle;
        use std::f64::consts::PI;
        let air = Gas {
            r: p.air_gas_constant_j_per_kg_k,
            k: p.air_heat_capacity_ratio,
        };
        let exh = Gas {
            r: p.exhaust_gas_constant_j_per_kg_k,
            k: p.exhaust_heat_capacity_ratio,
        };
        Self {
            air,
            exh,
            volume: [
                p.air_filter_volume_m3,
                p.compressor_volume_m3,
                p.intercooler_volume_m3,
                p.intake_manifold_volume_m3,
                p.exhaust_manifold_volume_m3,
                p.exhaust_system_volume_m3,
            ],
            air_filter: Restriction {
                h: p.air_filter_resistance_pa2_s2_per_kg2_k,
                dp_lin: p.air_filter_linear_dp_pa,
            },
            intercooler: Restriction {
                h: p.intercooler_resistance_pa2_s2_per_kg2_k,
                dp_lin: p.intercooler_linear_dp_pa,
            },
            ic_eps: p.intercooler_effectiveness,
            exhaust: Restriction {
                h: p.exhaust_resistance_pa2_s2_per_kg2_k,
                dp_lin: p.exhaust_linear_dp_pa,
            },
            compressor: Compressor::new(
                p.compressor_diameter_m,
                p.compressor_head_max,
                p.compressor_flow_max,
                p.compressor_head_linear_fraction,
                p.compressor_efficiency_max,
                p.compressor_flow_at_efficiency_max,
                p.compressor_efficiency_min,
                air.r,
                air.k,
            ),
            throttle: Throttle {
                nozzle: Nozzle::new(
                    p.throttle_heat_capacity_ratio,
                    p.throttle_linear_ratio,
                    air.r,
                ),
                gain_rad: p.throttle_angle_gain_deg_per_pct * PI / 180.0,
                offset_rad: p.throttle_angle_offset_deg * PI / 180.0,
                coeffs: p.throttle_area_coeffs_m2_rad,
            },
            cylinders: super::cylinder::cylinders(p, air.r, exh.cp()),
            wastegate: Wastegate {
                nozzle: Nozzle::new(exh.k, p.wastegate_linear_ratio, exh.r),
                area_max: p.wastegate_effective_area_m2,
            },
            turbine: Turbine::new(
                p.turbine_flow_k1_kg_k05_per_s_kpa,
                p.turbine_flow_k2,
                p.turbine_linear_ratio,
                p.turbine_diameter_m,
                p.turbine_efficiency_max,
                p.turbine_bsr_at_efficiency_max,
                p.turbine_efficiency_min,
                exh.r,
                exh.k,
            ),
            shaft: Shaft {
                inv_inertia: 1.0 / p.turbo_inertia_kg_m2,
                friction: p.turbo_friction_n_m_s_per_rad,
                friction_torque: p.turbo_friction_torque_n_m,
                omega_min: p.turbo_speed_min_rad_s,
                omega_max: p.turbo_speed_max_rad_s,
            },
        }
    }

    /// Gas of volume `i` (0..6): air for the first four, exhaust for the last two.
    #[inline]
    pub fn gas(&self, i: usize) -> Gas {
        if i < 4 {
            self.air
        } else {
            self.exh
        }
    }

    /// The full evaluation at state `x`, volumetric-efficiency correction `dc` and input `u`
    /// (indices [`U_THROTTLE_PCT`] ..); `saturate` applies the turbo speed limits' rule to its
    /// derivative (see [`super::shaft`]).
    pub fn eval<S: Scalar>(
        &self,
        x: &[S; N_STATES],
        dc: S,
        u: &[S; N_INPUTS],
        saturate: bool,
    ) -> TurboSignals<S> {
        let (t_lo, t_hi) = TEMPERATURE_RANGE_K;
        let mut m = [S::cst(0.0); 6];
        let mut t = [S::cst(0.0); 6];
        let mut p = [S::cst(0.0); 6];
        for i in 0..6 {
            // clamp_c rather than max_c: a NaN mass maps to the floor, not through.
            m[i] = x[2 * i].clamp_c(MIN_DENSITY_KG_M3 * self.volume[i], f64::INFINITY);
            t[i] = x[2 * i + 1].clamp_c(t_lo, t_hi);
            p[i] = m[i] * t[i] * (self.gas(i).r / self.volume[i]);
        }
        let [p_af, p_c, p_ic, p_im, p_em, p_es] = p;
        let [t_af, t_c, t_ic, t_im, t_em, t_es] = t;
        let omega_state = x[X_OMEGA_T];
        let omega = self.shaft.limited(omega_state);
        let alpha = u[U_THROTTLE_PCT];
        let omega_e =
            u[U_ENGINE_SPEED_RAD_S].clamp_c(ENGINE_SPEED_RANGE_RAD_S.0, ENGINE_SPEED_RANGE_RAD_S.1);
        let u_wg = u[U_WASTEGATE];
        let lambda = u[U_LAMBDA].clamp_c(LAMBDA_RANGE.0, LAMBDA_RANGE.1);
        let p_amb = u[U_AMBIENT_PRESSURE_PA]
            .clamp_c(AMBIENT_PRESSURE_RANGE_PA.0, AMBIENT_PRESSURE_RANGE_PA.1);
        let t_amb = u[U_AMBIENT_TEMPERATURE_K]
            .clamp_c(AMBIENT_TEMPERATURE_RANGE_K.0, AMBIENT_TEMPERATURE_RANGE_K.1);

        let (w_af, t_af_in) = self.air_filter.flow(p_amb, t_amb, p_af, t_af);
        let comp = self.compressor.point(p_af, t_af, p_c, t_c, omega);
        let (w_ic, t_ic_us) = self.intercooler.flow(p_c, t_c, p_ic, t_ic);
        let t_ic_out = t_ic_us - (t_ic_us - t_amb) * self.ic_eps;
        let t_ic_in = if w_ic.val() >= 0.0 { t_ic_out } else { t_ic_us };
        let (w_thr, t_thr) = self.throttle.flow(alpha, p_ic, t_ic, p_im, t_im);
        let cyl = self
            .cylinders
            .point(p_im, t_im, p_em, omega_e, lambda, t_amb, dc);
        let turb = self.turbine.point(p_em, t_em, p_es, t_es, omega);
        let (w_wg, t_wg) = self.wastegate.flow(u_wg, p_em, t_em, p_es, t_es);
        let (w_es, t_es_out) = self.exhaust.flow(p_es, t_es, p_amb, t_amb);

        let (ka, ke) = (self.air.k, self.exh.k);
        let mut b_af = Balance::new(t_af, ka);
        b_af.add(w_af, t_af_in);
        b_af.add(-comp.w, comp.t_carried);
        let mut b_c = Balance::new(t_c, ka);
        b_c.add(comp.w, comp.t_carried);
        b_c.add(-w_ic, t_ic_in);
        let mut b_ic = Balance::new(t_ic, ka);
        b_ic.add(w_ic, t_ic_in);
        b_ic.add(-w_thr, t_thr);
        let mut b_im = Balance::new(t_im, ka);
        b_im.add(w_thr, t_thr);
        b_im.add(-cyl.w_ei, t_im);
        let mut b_em = Balance::new(t_em, ke);
        b_em.add(cyl.w_eo, cyl.t_em_in);
        b_em.add(-turb.w, turb.t_carried);
        b_em.add(-w_wg, t_wg);
        let mut b_es = Balance::new(t_es, ke);
        b_es.add(turb.w, turb.t_carried);
        b_es.add(w_wg, t_wg);
        b_es.add(-w_es, t_es_out);

        let mut dxdt = [S::cst(0.0); N_STATES];
        for (i, b) in [b_af, b_c, b_ic, b_im, b_em, b_es].iter().enumerate() {
            let (dm, dt) = b.rates(m[i]);
            dxdt[2 * i] = dm;
            dxdt[2 * i + 1] = dt;
        }
        dxdt[X_OMEGA_T] = self
            .shaft
            .acceleration(omega_state, turb.torque, comp.torque, saturate);

        TurboSignals {
            p_af_pa: p_af,
            p_c_pa: p_c,
            p_ic_pa: p_ic,
            p_im_pa: p_im,
            p_em_pa: p_em,
            p_es_pa: p_es,
            t_af_k: t_af,
            t_c_k: t_c,
            t_ic_k: t_ic,
            t_im_k: t_im,
            t_em_k: t_em,
            t_es_k: t_es,
            omega_t_rad_s: omega,
            w_af_kg_s: w_af,
            w_c_kg_s: comp.w,
            w_ic_kg_s: w_ic,
            w_thr_kg_s: w_thr,
            w_ei_kg_s: cyl.w_ei,
            w_f_kg_s: cyl.w_f,
            w_eo_kg_s: cyl.w_eo,
            w_t_kg_s: turb.w,
            w_wg_kg_s: w_wg,
            w_es_kg_s: w_es,
            t_c_out_k: comp.t_out,
            t_ic_out_k: t_ic_out,
            t_eo_k: cyl.t_eo,
            t_em_in_k: cyl.t_em_in,
            t_t_out_k: turb.t_carried,
            pi_c: comp.pi,
            psi_c: comp.psi,
            phi_c: comp.phi,
            eta_c: comp.eta,
            tq_c_nm: comp.torque,
            eta_t: turb.eta,
            bsr_t: turb.bsr,
            tq_t_nm: turb.torque,
            eta_vol_factor: cyl.eta_factor,
            dxdt,
        }
    }
}
