//! The cylinders: air flow from the intake manifold (volumetric efficiency), fuel, and the
//! temperature of the exhaust reaching the exhaust manifold (REFERENCE §4).
//!
//! - `W_ei = (C_eta_vol p(p_im) + dC_eta_vol) (r_c - (p_em/p_im)^(1/k_e)) / (r_c - 1)
//!   p_im V_d omega_e / (4 pi R T_im)` (four-stroke, `omega_e` in rad/s). `p(p_im)` is the VEP4
//!   4th-order polynomial in `p_im` (kPa), evaluated at `p_im` clamped to its fitted range
//!   (`[0, 0, 0, 0, 1]`, i.e. 1, for the generic set), plus the optional speed terms
//!   `s1 n + s2 n^2` (`n` engine speed in 1000 rpm, clamped to its fitted range; 0 unless a
//!   parameter file sets them, see `TurboParams::vol_eff_speed_coeffs_krpm`). `dC_eta_vol` is the augmented 14th
//!   state of the paper (§4.2): it is added to the whole factor, which for the generic set is the
//!   paper's `C_eta_vol + dC_eta_vol` exactly.
//! - The residual-gas term is floored at 0 (no flow from the cylinders into the intake; it
//!   would need `p_em / p_im > r_c^k_e`, 19 at `r_c` 9.5) and so is the whole flow (a
//!   negative `dC_eta_vol` estimate cannot pump air backwards).
//! - Fuel `W_f = W_ei / (AFs lambda)`: the input is lambda, not the fuel flow (see the module
//!   docs of `turbo`). `W_eo = W_ei + W_f`.
//! - Engine-out temperature `T_eo = T_0 + C_eo W_eo`, then the heat lost in the exhaust pipes:
//!   `T_em,in = T_amb + (T_eo - T_amb) exp(-h_tot pi D L / (W_pipe cp_e))` with
//!   `W_pipe = W_eo / n_pipes`, `h_tot = 1 / (1/h_ext + 1/h_int)`, `h_int = Nu lambda_gas / D`,
//!   `Nu = 0.26 Re^0.6`, `Re = 4 W_pipe / (pi D mu)`. The pipe flow is floored at 1 mg/s per
//!   pipe: at zero flow `h_int` and the exponent are 0/0; the floor leaves `T_em,in` at
//!   ambient to within far less than a kelvin, as the limit is.

use std::f64::consts::PI;

use super::ad::Scalar;

/// 1000 rpm per rad/s: `60 / (2 pi 1000)`.
pub const KRPM_PER_RAD_S: f64 = 60.0 / (2.0 * PI * 1000.0);

/// Smallest exhaust flow per pipe in the heat-loss model (kg/s).
pub const MIN_PIPE_FLOW_KG_S: f64 = 1e-6;

/// The cylinders' and exhaust pipes' constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cylinders {
    /// `V_d / (4 pi R_air)` (m^3 kg K / J).
    pub flow_gain: f64,
    /// `C_eta_vol`.
    pub c_eta_vol: f64,
    /// The VEP4 polynomial in kPa, highest power first.
    pub poly: [f64; 5],
    /// Polynomial argument range (kPa).
    pub poly_min_kpa: f64,
    /// Upper end (kPa).
    pub poly_max_kpa: f64,
    /// Speed terms `[s1, s2]` per 1000 rpm (`[0, 0]`: none).
    pub speed_coeffs: [f64; 2],
    /// Speed terms' argument range (1000 rpm).
    pub speed_min_krpm: f64,
    /// Upper end (1000 rpm).
    pub speed_max_krpm: f64,
    /// `r_c`.
    pub r_c: f64,
    /// `1 / k_e`.
    pub inv_ke: f64,
    /// `AFs`.
    pub afs: f64,
    /// `T_0` (K).
    pub t0: f64,
    /// `C_eo` (K s/kg).
    pub c_eo: f64,
    /// Number of pipes.
    pub n_pipes: f64,
    /// `4 / (pi D mu)` (s/kg): Reynolds number per pipe flow.
    pub re_per_flow: f64,
    /// `c lambda_gas / D` (W/(m^2 K)).
    pub nu_gain: f64,
    /// Nusselt exponent.
    pub nu_exp: f64,
    /// `1 / h_ext` (m^2 K / W).
    pub inv_h_ext: f64,
    /// `pi D L / cp_e` (m^2 kg K / J).
    pub area_per_cp: f64,
}

/// The cylinders at one operating point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CylinderPoint<S> {
    /// Air flow into the cylinders (kg/s).
    pub w_ei: S,
    /// Fuel flow (kg/s).
    pub w_f: S,
    /// Exhaust flow out of the cylinders (kg/s).
    pub w_eo: S,
    /// Volumetric-efficiency factor including the correction (-).
    pub eta_factor: S,
    /// Engine-out temperature (K).
    pub t_eo: S,
    /// Temperature after the pipe heat loss, entering the exhaust manifold (K).
    pub t_em_in: S,
}

impl Cylinders {
    /// Volumetric-efficiency factor `C_eta_vol (p(p_im) + s1 n + s2 n^2) + dc` at `p_im` (Pa)
    /// and engine speed `omega_e` (rad/s; `n` in 1000 rpm). Without speed terms the sum is
    /// skipped, so that such a set evaluates bit for bit as before the terms existed.
    #[inline]
    pub fn eta_factor<S: Scalar>(&self, p_im: S, omega_e: S, dc: S) -> S {
        let x = (p_im / 1000.0).clamp_c(self.poly_min_kpa, self.poly_max_kpa);
        let mut acc = S::cst(self.poly[0]);
        for &c in &self.poly[1..] {
            acc = acc * x + c;
        }
        if self.speed_coeffs != [0.0, 0.0] {
            let n = (omega_e * KRPM_PER_RAD_S).clamp_c(self.speed_min_krpm, self.speed_max_krpm);
            acc = acc + n * (n * self.speed_coeffs[1] + self.speed_coeffs[0]);
        }
        acc * self.c_eta_vol + dc
    }

    /// The cylinders at manifold `(p_im Pa, t_im K)`, exhaust pressure `p_em` (Pa), engine
    /// speed `omega_e` (rad/s), `lambda`, ambient temperature `t_amb` (K) and correction `dc`.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn point<S: Scalar>(
        &self,
        p_im: S,
        t_im: S,
        p_em: S,
        omega_e: S,
        lambda: S,
        t_amb: S,
        dc: S,
    ) -> CylinderPoint<S> {
        let eta_factor = self.eta_factor(p_im, omega_e, dc);
        let residual =
            ((-(p_em / p_im).powf(self.inv_ke) + self.r_c) / (self.r_c - 1.0)).max_c(0.0);
        let w_ei = (eta_factor * residual * p_im * omega_e / t_im * self.flow_gain).max_c(0.0);
        let w_f = w_ei / (lambda * self.afs);
        let w_eo = w_ei + w_f;
        let t_eo = w_eo * self.c_eo + self.t0;
        let w_pipe = (w_eo / self.n_pipes).max_c(MIN_PIPE_FLOW_KG_S);
        let h_int = (w_pipe * self.re_per_flow).powf(self.nu_exp) * self.nu_gain;
        let h_tot = S::cst(1.0) / (S::cst(1.0) / h_int + self.inv_h_ext);
        let decay = (-(h_tot * self.area_per_cp / w_pipe)).exp();
        let t_em_in = (t_eo - t_amb) * decay + t_amb;
        CylinderPoint {
            w_ei,
            w_f,
            w_eo,
            eta_factor,
            t_eo,
            t_em_in,
        }
    }
}

/// Constants from the parameters (`cp_e` of the exhaust gas, `r_air` of air).
pub(crate) fn cylinders(p: &super::TurboParams, r_air: f64, cp_e: f64) -> Cylinders {
    let d = p.exhaust_pipe_diameter_m;
    Cylinders {
        flow_gain: p.displacement_m3 / (4.0 * PI * r_air),
        c_eta_vol: p.vol_eff_factor,
        poly: p.vol_eff_poly_kpa,
        poly_min_kpa: p.vol_eff_poly_min_kpa,
        poly_max_kpa: p.vol_eff_poly_max_kpa,
        speed_coeffs: p.vol_eff_speed_coeffs_krpm,
        speed_min_krpm: p.vol_eff_speed_min_krpm,
        speed_max_krpm: p.vol_eff_speed_max_krpm,
        r_c: p.compression_ratio,
        inv_ke: 1.0 / p.exhaust_heat_capacity_ratio,
        afs: p.stoichiometric_air_fuel_ratio,
        t0: p.exhaust_temp_zero_flow_k,
        c_eo: p.exhaust_temp_flow_gain_k_s_per_kg,
        n_pipes: p.exhaust_pipe_count,
        re_per_flow: 4.0 / (PI * d * p.exhaust_gas_viscosity_pa_s),
        nu_gain: p.exhaust_pipe_nusselt_coeff * p.exhaust_gas_conductivity_w_per_m_k / d,
        nu_exp: p.exhaust_pipe_nusselt_exponent,
        inv_h_ext: 1.0 / p.exhaust_pipe_h_ext_w_per_m2_k,
        area_per_cp: PI * d * p.exhaust_pipe_length_m / cp_e,
    }
}
