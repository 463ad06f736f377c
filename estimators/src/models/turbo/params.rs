//! Parameters of the turbocharged air-path model (the `[model]` table of `config/turbo.toml`
//! or `config/turbo_vep4.toml`), their admissible ranges and the constants derived from them.
//!
//! Units are in the key names. Specific heats are not keys: `cp = R k / (k - 1)` and
//! `cv = R / (k - 1)` follow from the gas constant and the ratio of specific heats, so the three
//! cannot disagree (REFERENCE's `cp` 1005.2 and 1256.7 are exactly these for R 287.2 / k 1.4 and
//! R 290 / k 1.3).

use std::f64::consts::PI;

use serde::Deserialize;

use crate::param::{show, ParamError};

/// Model parameters. Every key is required; see `config/turbo.toml` for the source of each value.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TurboParams {
    /// Specific gas constant of air (J/(kg K)).
    pub air_gas_constant_j_per_kg_k: f64,
    /// Ratio of specific heats of air (-).
    pub air_heat_capacity_ratio: f64,
    /// Specific gas constant of the exhaust gas (J/(kg K)).
    pub exhaust_gas_constant_j_per_kg_k: f64,
    /// Ratio of specific heats of the exhaust gas `k_e` (-); also the exponent of the
    /// residual-gas term of the volumetric efficiency.
    pub exhaust_heat_capacity_ratio: f64,
    /// Stoichiometric air/fuel ratio `AFs` (-).
    pub stoichiometric_air_fuel_ratio: f64,

    /// Displacement `V_d` (m^3), all cylinders.
    pub displacement_m3: f64,
    /// Compression ratio `r_c` (-).
    pub compression_ratio: f64,

    /// Air filter volume (m^3).
    pub air_filter_volume_m3: f64,
    /// Compressor outlet volume, up to the intercooler (m^3).
    pub compressor_volume_m3: f64,
    /// Intercooler and throttle inlet volume (m^3).
    pub intercooler_volume_m3: f64,
    /// Intake manifold volume (m^3).
    pub intake_manifold_volume_m3: f64,
    /// Exhaust manifold volume, up to the turbine (m^3).
    pub exhaust_manifold_volume_m3: f64,
    /// Exhaust system volume after the turbine (m^3).
    pub exhaust_system_volume_m3: f64,

    /// Air filter flow resistance `H` in `W = sqrt(p_us dp / (H T_us))` (Pa^2 s^2 / (kg^2 K)).
    pub air_filter_resistance_pa2_s2_per_kg2_k: f64,
    /// Pressure drop below which the air filter flow is linear in `dp` (Pa).
    pub air_filter_linear_dp_pa: f64,
    /// Intercooler flow resistance `H` (Pa^2 s^2 / (kg^2 K)).
    pub intercooler_resistance_pa2_s2_per_kg2_k: f64,
    /// Pressure drop below which the intercooler flow is linear in `dp` (Pa).
    pub intercooler_linear_dp_pa: f64,
    /// Intercooler effectiveness `eps`: outlet `T_us - eps (T_us - T_amb)` (-).
    pub intercooler_effectiveness: f64,
    /// Exhaust system flow resistance `H` (Pa^2 s^2 / (kg^2 K)).
    pub exhaust_resistance_pa2_s2_per_kg2_k: f64,
    /// Pressure drop below which the exhaust system flow is linear in `dp` (Pa).
    pub exhaust_linear_dp_pa: f64,

    /// Compressor wheel diameter `D_c` (m); tip speed `U_c = omega_t D_c / 2`.
    pub compressor_diameter_m: f64,
    /// Largest head parameter `Psi_max` of the ellipse (-).
    pub compressor_head_max: f64,
    /// Largest flow parameter `Phi_max` of the ellipse (-).
    pub compressor_flow_max: f64,
    /// Fraction of `Psi_max` above which the ellipse is continued linearly (its slope is
    /// infinite at `Psi_max`); beyond about `Psi_max` the flow reverses (surge) (-).
    pub compressor_head_linear_fraction: f64,
    /// Peak isentropic efficiency `eta_max` (-).
    pub compressor_efficiency_max: f64,
    /// Flow parameter at the peak efficiency `Phi_opt` (-).
    pub compressor_flow_at_efficiency_max: f64,
    /// Lower clamp of the efficiency parabola (-); the upper clamp is 1.
    pub compressor_efficiency_min: f64,

    /// Ratio of specific heats in the throttle flow function, a tuned value (2 fits better
    /// than 1.4) (-).
    pub throttle_heat_capacity_ratio: f64,
    /// Pressure ratio above which the throttle flow function is continued linearly to zero at
    /// 1 (its slope is infinite at 1) (-).
    pub throttle_linear_ratio: f64,
    /// Plate angle per percent of throttle input (deg/%): `th = gain alpha + offset`.
    pub throttle_angle_gain_deg_per_pct: f64,
    /// Plate angle at 0 % (deg).
    pub throttle_angle_offset_deg: f64,
    /// Effective area `a0 + a1 th + a2 th^2`, `th` in rad: `[a0 m^2, a1 m^2/rad, a2 m^2/rad^2]`.
    #[serde(deserialize_with = "crate::param::exact_array")]
    pub throttle_area_coeffs_m2_rad: [f64; 3],

    /// Volumetric-efficiency factor `C_eta_vol` (-).
    pub vol_eff_factor: f64,
    /// Polynomial in `p_im` (kPa) multiplying `C_eta_vol`, highest power first (4th order,
    /// five coefficients); `[0, 0, 0, 0, 1]` is no polynomial.
    #[serde(deserialize_with = "crate::param::exact_array")]
    pub vol_eff_poly_kpa: [f64; 5],
    /// The polynomial is evaluated at `p_im` clamped to `[min, max]` (kPa): it is a fit over
    /// the mapped range and grows fast outside it.
    pub vol_eff_poly_min_kpa: f64,
    /// Upper end of the polynomial's argument (kPa).
    pub vol_eff_poly_max_kpa: f64,
    /// Engine-speed terms added to the polynomial, `s1 n + s2 n^2` with `n` the engine speed
    /// in 1000 rpm (clamped to the speed range below): `[s1 /krpm, s2 /krpm^2]`. The additive
    /// form of Eriksson and Nielsen (2014, eq. 7.12: `c0 + c1 sqrt(p_im) + c2 sqrt(N)`), with the
    /// speed term a quadratic as in Guzzella and Onder (2010, `eta_omega`): the breathing
    /// losses grow with the flow velocity (valve-flow friction, about quadratic in speed) while
    /// intake tuning raises the filling at mid speeds. Optional: the default `[0, 0]` is no
    /// speed dependence (the generic and VEP4 sets have none).
    #[serde(
        default = "zero_speed_coeffs",
        deserialize_with = "crate::param::exact_array"
    )]
    pub vol_eff_speed_coeffs_krpm: [f64; 2],
    /// The speed terms are evaluated at the engine speed clamped to `[min, max]` (1000 rpm):
    /// a fit over the mapped speeds, not to be extrapolated. Optional, default 0.
    #[serde(default)]
    pub vol_eff_speed_min_krpm: f64,
    /// Upper end of the speed terms' argument (1000 rpm). Optional, default 15 (above the
    /// model's accepted range of 14.3).
    #[serde(default = "default_speed_max_krpm")]
    pub vol_eff_speed_max_krpm: f64,

    /// Engine-out exhaust temperature at zero flow `T_0` (K): `T_eo = T_0 + C_eo W_eo`.
    pub exhaust_temp_zero_flow_k: f64,
    /// Rise of the engine-out temperature with the exhaust flow `C_eo` (K s/kg).
    pub exhaust_temp_flow_gain_k_s_per_kg: f64,
    /// Exhaust manifold pipe inner diameter (m).
    pub exhaust_pipe_diameter_m: f64,
    /// Exhaust manifold pipe length (m).
    pub exhaust_pipe_length_m: f64,
    /// Number of parallel exhaust manifold pipes (-); the flow is shared equally.
    pub exhaust_pipe_count: f64,
    /// External heat transfer coefficient of the pipes `h_ext` (W/(m^2 K)).
    pub exhaust_pipe_h_ext_w_per_m2_k: f64,
    /// Nusselt correlation `Nu = c Re^n` inside the pipes: `c` (-).
    pub exhaust_pipe_nusselt_coeff: f64,
    /// Nusselt correlation exponent `n` (-).
    pub exhaust_pipe_nusselt_exponent: f64,
    /// Dynamic viscosity of the exhaust gas `mu` (Pa s).
    pub exhaust_gas_viscosity_pa_s: f64,
    /// Thermal conductivity of the exhaust gas (W/(m K)).
    pub exhaust_gas_conductivity_w_per_m_k: f64,

    /// Wastegate effective area when fully open, `Cd A_max` (m^2).
    pub wastegate_effective_area_m2: f64,
    /// Pressure ratio above which the wastegate flow function is continued linearly to zero
    /// at 1 (-).
    pub wastegate_linear_ratio: f64,

    /// Turbine wheel diameter `D_t` (m); blade tip radius `D_t / 2` in the blade speed ratio.
    pub turbine_diameter_m: f64,
    /// Turbine flow `W_t = k1 p_em / sqrt(T_em) sqrt(1 - Pi_t^k2)` with `p_em` in kPa:
    /// `k1` (kg K^0.5 / (s kPa)).
    pub turbine_flow_k1_kg_k05_per_s_kpa: f64,
    /// Turbine flow exponent `k2` (-).
    pub turbine_flow_k2: f64,
    /// Pressure ratio `Pi_t` above which `sqrt(1 - Pi_t^k2)` is continued linearly to zero at
    /// 1 (its slope is infinite at 1) (-).
    pub turbine_linear_ratio: f64,
    /// Peak turbine efficiency (-).
    pub turbine_efficiency_max: f64,
    /// Blade speed ratio at the peak efficiency (-).
    pub turbine_bsr_at_efficiency_max: f64,
    /// Lower clamp of the turbine efficiency parabola (-); the upper clamp is 1.
    pub turbine_efficiency_min: f64,

    /// Turbo shaft inertia `J` (kg m^2).
    pub turbo_inertia_kg_m2: f64,
    /// Turbo shaft viscous friction `d`: torque `d omega_t` (N m s/rad).
    pub turbo_friction_n_m_s_per_rad: f64,
    /// Turbo shaft loss torque independent of the speed `tau_0` (N m): bearing and seal
    /// friction that does not scale with the speed, and whatever else the turbine loses at
    /// part load that the gas-stand efficiency map does not show (heat). It decides where the
    /// shaft settles at part load, where the turbine delivers a few hundred watts, and costs
    /// little at full load (`tau_0 omega_t` against the compressor's kilowatts). Optional,
    /// default 0 (the generic and VEP4 sets have only the viscous term); `fdd fit turbo` fits
    /// it to a measured turbo speed.
    #[serde(default)]
    pub turbo_friction_torque_n_m: f64,
    /// Lowest turbo speed (rad/s): the state is held at or above it.
    pub turbo_speed_min_rad_s: f64,
    /// Highest turbo speed (rad/s).
    pub turbo_speed_max_rad_s: f64,
}

fn zero_speed_coeffs() -> [f64; 2] {
    [0.0, 0.0]
}

fn default_speed_max_krpm() -> f64 {
    15.0
}

/// Admissible ranges: physical bounds generous enough for any passenger-car engine, tight
/// enough to catch a unit slip (kPa for Pa, mm for m, percent for a fraction).
pub mod ranges {
    use crate::param::Range;

    /// Specific gas constants.
    pub const GAS_CONSTANT: Range = Range::closed(100.0, 1000.0, "J/(kg K)");
    /// Ratios of specific heats (the throttle's tuned one may reach 3).
    pub const HEAT_CAPACITY_RATIO: Range = Range::open(1.0, 3.0, "");
    /// Stoichiometric air/fuel ratio (gasoline 14.6, E85 9.8, methane 17.2).
    pub const AIR_FUEL_RATIO: Range = Range::closed(5.0, 25.0, "");
    /// Displacement: 0.1 to 10 L.
    pub const DISPLACEMENT_M3: Range = Range::closed(1e-4, 1e-2, "m^3");
    /// Compression ratio.
    pub const COMPRESSION_RATIO: Range = Range::open(1.0, 30.0, "");
    /// Control volumes: 0.1 to 100 L.
    pub const VOLUME_M3: Range = Range::closed(1e-4, 0.1, "m^3");
    /// Restriction resistances `H`.
    pub const RESISTANCE: Range = Range::closed(1e5, 1e12, "Pa^2 s^2/(kg^2 K)");
    /// Linearization pressure drops: 1 Pa to 20 kPa.
    pub const LINEAR_DP_PA: Range = Range::closed(1.0, 2e4, "Pa");
    /// Intercooler effectiveness.
    pub const EFFECTIVENESS: Range = Range::closed(0.0, 1.0, "");
    /// Wheel diameters: 1 to 30 cm.
    pub const WHEEL_DIAMETER_M: Range = Range::closed(0.01, 0.3, "m");
    /// Compressor head parameter.
    pub const HEAD_MAX: Range = Range::above(0.0, 10.0, "");
    /// Compressor flow parameter.
    pub const FLOW_MAX: Range = Range::above(0.0, 1.0, "");
    /// Fraction of the ellipse kept before the linear continuation.
    pub const HEAD_LINEAR_FRACTION: Range = Range::closed(0.5, 0.999, "");
    /// Efficiencies.
    pub const EFFICIENCY: Range = Range::above(0.0, 1.0, "");
    /// Pressure ratio where a flow function turns linear (checked against the critical ratio).
    pub const LINEAR_RATIO: Range = Range::open(0.0, 1.0, "");
    /// Throttle angle gain: 100 % is 10 to 180 deg.
    pub const THROTTLE_GAIN: Range = Range::closed(0.1, 1.8, "deg/%");
    /// Throttle angle offset.
    pub const THROTTLE_OFFSET: Range = Range::closed(-45.0, 45.0, "deg");
    /// Area polynomial coefficients (signed; the area itself is checked over the input range).
    pub const AREA_COEFF: Range = Range::closed(-1.0, 1.0, "m^2/rad^k");
    /// Volumetric-efficiency factor.
    pub const VOL_EFF_FACTOR: Range = Range::above(0.0, 2.0, "");
    /// Volumetric-efficiency polynomial coefficients (signed).
    pub const VOL_EFF_COEFF: Range = Range::closed(-100.0, 100.0, "kPa^-k");
    /// Volumetric-efficiency speed coefficients (signed).
    pub const VOL_EFF_SPEED_COEFF: Range = Range::closed(-10.0, 10.0, "krpm^-k");
    /// Speed terms' argument range.
    pub const VOL_EFF_KRPM: Range = Range::closed(0.0, 20.0, "krpm");
    /// Polynomial argument range.
    pub const VOL_EFF_KPA: Range = Range::closed(1.0, 1000.0, "kPa");
    /// Zero-flow engine-out temperature.
    pub const EXHAUST_TEMP_K: Range = Range::closed(400.0, 2000.0, "K");
    /// Its rise with flow.
    pub const EXHAUST_TEMP_GAIN: Range = Range::closed(-2e4, 2e4, "K s/kg");
    /// Pipe diameter.
    pub const PIPE_DIAMETER_M: Range = Range::above(0.0, 0.3, "m");
    /// Pipe length.
    pub const PIPE_LENGTH_M: Range = Range::above(0.0, 5.0, "m");
    /// Number of pipes.
    pub const PIPE_COUNT: Range = Range::closed(1.0, 16.0, "");
    /// External heat transfer coefficient.
    pub const H_EXT: Range = Range::above(0.0, 1e4, "W/(m^2 K)");
    /// Nusselt coefficient.
    pub const NUSSELT_COEFF: Range = Range::above(0.0, 10.0, "");
    /// Nusselt exponent.
    pub const NUSSELT_EXPONENT: Range = Range::above(0.0, 1.0, "");
    /// Viscosity.
    pub const VISCOSITY: Range = Range::above(0.0, 1e-3, "Pa s");
    /// Conductivity.
    pub const CONDUCTIVITY: Range = Range::above(0.0, 10.0, "W/(m K)");
    /// Wastegate area: up to 10 cm^2 (a 36 mm port).
    pub const WASTEGATE_AREA_M2: Range = Range::above(0.0, 1e-3, "m^2");
    /// Turbine flow constant.
    pub const TURBINE_K1: Range = Range::above(0.0, 1.0, "kg K^0.5/(s kPa)");
    /// Turbine flow exponent.
    pub const TURBINE_K2: Range = Range::above(0.0, 10.0, "");
    /// Blade speed ratio at the peak efficiency.
    pub const BSR: Range = Range::above(0.0, 2.0, "");
    /// Shaft inertia.
    pub const INERTIA: Range = Range::above(0.0, 1e-2, "kg m^2");
    /// Shaft friction.
    pub const FRICTION: Range = Range::closed(0.0, 1e-3, "N m s/rad");
    /// Speed-independent shaft loss torque: up to 1 N m (tens of kW at full speed, far beyond
    /// any bearing).
    pub const FRICTION_TORQUE: Range = Range::closed(0.0, 1.0, "N m");
    /// Turbo speed limits: the minimum must be positive (torques divide by the speed).
    pub const TURBO_SPEED: Range = Range::closed(100.0, 5e4, "rad/s");
}

/// Critical pressure ratio `(2/(k+1))^(k/(k-1))` of the compressible flow function.
pub fn critical_ratio(k: f64) -> f64 {
    (2.0 / (k + 1.0)).powf(k / (k - 1.0))
}

impl TurboParams {
    /// Checks every key against its range ([`ranges`]) and the relations between keys, naming
    /// the offending key relative to the `[model]` table (`throttle_area_coeffs_m2_rad[1]`).
    pub fn validate(&self) -> Result<(), ParamError> {
        use ranges as r;
        let checks = [
            (
                "air_gas_constant_j_per_kg_k",
                self.air_gas_constant_j_per_kg_k,
                r::GAS_CONSTANT,
            ),
            (
                "air_heat_capacity_ratio",
                self.air_heat_capacity_ratio,
                r::HEAT_CAPACITY_RATIO,
            ),
            (
                "exhaust_gas_constant_j_per_kg_k",
                self.exhaust_gas_constant_j_per_kg_k,
                r::GAS_CONSTANT,
            ),
            (
                "exhaust_heat_capacity_ratio",
                self.exhaust_heat_capacity_ratio,
                r::HEAT_CAPACITY_RATIO,
            ),
            (
                "stoichiometric_air_fuel_ratio",
                self.stoichiometric_air_fuel_ratio,
                r::AIR_FUEL_RATIO,
            ),
            ("displacement_m3", self.displacement_m3, r::DISPLACEMENT_M3),
            (
                "compression_ratio",
                self.compression_ratio,
                r::COMPRESSION_RATIO,
            ),
            (
                "air_filter_volume_m3",
                self.air_filter_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "compressor_volume_m3",
                self.compressor_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "intercooler_volume_m3",
                self.intercooler_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "intake_manifold_volume_m3",
                self.intake_manifold_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "exhaust_manifold_volume_m3",
                self.exhaust_manifold_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "exhaust_system_volume_m3",
                self.exhaust_system_volume_m3,
                r::VOLUME_M3,
            ),
            (
                "air_filter_resistance_pa2_s2_per_kg2_k",
                self.air_filter_resistance_pa2_s2_per_kg2_k,
                r::RESISTANCE,
            ),
            (
                "air_filter_linear_dp_pa",
                self.air_filter_linear_dp_pa,
                r::LINEAR_DP_PA,
            ),
            (
                "intercooler_resistance_pa2_s2_per_kg2_k",
                self.intercooler_resistance_pa2_s2_per_kg2_k,
                r::RESISTANCE,
            ),
            (
                "intercooler_linear_dp_pa",
                self.intercooler_linear_dp_pa,
                r::LINEAR_DP_PA,
            ),
            (
                "intercooler_effectiveness",
                self.intercooler_effectiveness,
                r::EFFECTIVENESS,
            ),
            (
                "exhaust_resistance_pa2_s2_per_kg2_k",
                self.exhaust_resistance_pa2_s2_per_kg2_k,
                r::RESISTANCE,
            ),
            (
                "exhaust_linear_dp_pa",
                self.exhaust_linear_dp_pa,
                r::LINEAR_DP_PA,
            ),
            (
                "compressor_diameter_m",
                self.compressor_diameter_m,
                r::WHEEL_DIAMETER_M,
            ),
            ("compressor_head_max", self.compressor_head_max, r::HEAD_MAX),
            ("compressor_flow_max", self.compressor_flow_max, r::FLOW_MAX),
            (
                "compressor_head_linear_fraction",
                self.compressor_head_linear_fraction,
                r::HEAD_LINEAR_FRACTION,
            ),
            (
                "compressor_efficiency_max",
                self.compressor_efficiency_max,
                r::EFFICIENCY,
            ),
            (
                "compressor_flow_at_efficiency_max",
                self.compressor_flow_at_efficiency_max,
                r::FLOW_MAX,
            ),
            (
                "compressor_efficiency_min",
                self.compressor_efficiency_min,
                r::EFFICIENCY,
            ),
            (
                "throttle_heat_capacity_ratio",
                self.throttle_heat_capacity_ratio,
                r::HEAT_CAPACITY_RATIO,
            ),
            (
                "throttle_linear_ratio",
                self.throttle_linear_ratio,
                r::LINEAR_RATIO,
            ),
            (
                "throttle_angle_gain_deg_per_pct",
                self.throttle_angle_gain_deg_per_pct,
                r::THROTTLE_GAIN,
            ),
            (
                "throttle_angle_offset_deg",
                self.throttle_angle_offset_deg,
                r::THROTTLE_OFFSET,
            ),
            ("vol_eff_factor", self.vol_eff_factor, r::VOL_EFF_FACTOR),
            (
                "vol_eff_poly_min_kpa",
                self.vol_eff_poly_min_kpa,
                r::VOL_EFF_KPA,
            ),
            (
                "vol_eff_poly_max_kpa",
                self.vol_eff_poly_max_kpa,
                r::VOL_EFF_KPA,
            ),
            (
                "exhaust_temp_zero_flow_k",
                self.exhaust_temp_zero_flow_k,
                r::EXHAUST_TEMP_K,
            ),
            (
                "exhaust_temp_flow_gain_k_s_per_kg",
                self.exhaust_temp_flow_gain_k_s_per_kg,
                r::EXHAUST_TEMP_GAIN,
            ),
            (
                "exhaust_pipe_diameter_m",
                self.exhaust_pipe_diameter_m,
                r::PIPE_DIAMETER_M,
            ),
            (
                "exhaust_pipe_length_m",
                self.exhaust_pipe_length_m,
                r::PIPE_LENGTH_M,
            ),
            ("exhaust_pipe_count", self.exhaust_pipe_count, r::PIPE_COUNT),
            (
                "exhaust_pipe_h_ext_w_per_m2_k",
                self.exhaust_pipe_h_ext_w_per_m2_k,
                r::H_EXT,
            ),
            (
                "exhaust_pipe_nusselt_coeff",
                self.exhaust_pipe_nusselt_coeff,
                r::NUSSELT_COEFF,
            ),
            (
                "exhaust_pipe_nusselt_exponent",
                self.exhaust_pipe_nusselt_exponent,
                r::NUSSELT_EXPONENT,
            ),
            (
                "exhaust_gas_viscosity_pa_s",
                self.exhaust_gas_viscosity_pa_s,
                r::VISCOSITY,
            ),
            (
                "exhaust_gas_conductivity_w_per_m_k",
                self.exhaust_gas_conductivity_w_per_m_k,
                r::CONDUCTIVITY,
            ),
            (
                "wastegate_effective_area_m2",
                self.wastegate_effective_area_m2,
                r::WASTEGATE_AREA_M2,
            ),
            (
                "wastegate_linear_ratio",
                self.wastegate_linear_ratio,
                r::LINEAR_RATIO,
            ),
            (
                "turbine_diameter_m",
                self.turbine_diameter_m,
                r::WHEEL_DIAMETER_M,
            ),
            (
                "turbine_flow_k1_kg_k05_per_s_kpa",
                self.turbine_flow_k1_kg_k05_per_s_kpa,
                r::TURBINE_K1,
            ),
            ("turbine_flow_k2", self.turbine_flow_k2, r::TURBINE_K2),
            (
                "turbine_linear_ratio",
                self.turbine_linear_ratio,
                r::LINEAR_RATIO,
            ),
            (
                "turbine_efficiency_max",
                self.turbine_efficiency_max,
                r::EFFICIENCY,
            ),
            (
                "turbine_bsr_at_efficiency_max",
                self.turbine_bsr_at_efficiency_max,
                r::BSR,
            ),
            (
                "turbine_efficiency_min",
                self.turbine_efficiency_min,
                r::EFFICIENCY,
            ),
            ("turbo_inertia_kg_m2", self.turbo_inertia_kg_m2, r::INERTIA),
            (
                "turbo_friction_n_m_s_per_rad",
                self.turbo_friction_n_m_s_per_rad,
                r::FRICTION,
            ),
            (
                "turbo_friction_torque_n_m",
                self.turbo_friction_torque_n_m,
                r::FRICTION_TORQUE,
            ),
        ];
        for (key, v, range) in checks {
            range.check(key, v)?;
        }
        r::TURBO_SPEED.check("turbo_speed_min_rad_s", self.turbo_speed_min_rad_s)?;
        r::TURBO_SPEED.check("turbo_speed_max_rad_s", self.turbo_speed_max_rad_s)?;
        for (i, &c) in self.throttle_area_coeffs_m2_rad.iter().enumerate() {
            r::AREA_COEFF.check(&format!("throttle_area_coeffs_m2_rad[{i}]"), c)?;
        }
        for (i, &c) in self.vol_eff_poly_kpa.iter().enumerate() {
            r::VOL_EFF_COEFF.check(&format!("vol_eff_poly_kpa[{i}]"), c)?;
        }
        for (i, &c) in self.vol_eff_speed_coeffs_krpm.iter().enumerate() {
            r::VOL_EFF_SPEED_COEFF.check(&format!("vol_eff_speed_coeffs_krpm[{i}]"), c)?;
        }
        r::VOL_EFF_KRPM.check("vol_eff_speed_min_krpm", self.vol_eff_speed_min_krpm)?;
        r::VOL_EFF_KRPM.check("vol_eff_speed_max_krpm", self.vol_eff_speed_max_krpm)?;
        let above = |key: &str, v: f64, lo_key: &str, lo: f64| {
            if v > lo {
                Ok(())
            } else {
                Err(ParamError::new(
                    key,
                    show(v),
                    format!("must be above `{lo_key}` = {}", show(lo)),
                ))
            }
        };
        above(
            "turbo_speed_max_rad_s",
            self.turbo_speed_max_rad_s,
            "turbo_speed_min_rad_s",
            self.turbo_speed_min_rad_s,
        )?;
        above(
            "vol_eff_poly_max_kpa",
            self.vol_eff_poly_max_kpa,
            "vol_eff_poly_min_kpa",
            self.vol_eff_poly_min_kpa,
        )?;
        above(
            "vol_eff_speed_max_krpm",
            self.vol_eff_speed_max_krpm,
            "vol_eff_speed_min_krpm",
            self.vol_eff_speed_min_krpm,
        )?;
        if !(self.compressor_flow_at_efficiency_max < self.compressor_flow_max) {
            return Err(ParamError::new(
                "compressor_flow_at_efficiency_max",
                show(self.compressor_flow_at_efficiency_max),
                format!(
                    "must be below `compressor_flow_max` = {}",
                    show(self.compressor_flow_max)
                ),
            ));
        }
        for (key, ratio, k_key, k) in [
            (
                "throttle_linear_ratio",
                self.throttle_linear_ratio,
                "throttle_heat_capacity_ratio",
                self.throttle_heat_capacity_ratio,
            ),
            (
                "wastegate_linear_ratio",
                self.wastegate_linear_ratio,
                "exhaust_heat_capacity_ratio",
                self.exhaust_heat_capacity_ratio,
            ),
        ] {
            let crit = critical_ratio(k);
            if !(ratio > crit) {
                return Err(ParamError::new(
                    key,
                    show(ratio),
                    format!("must lie above the critical ratio {crit:.4} of `{k_key}` and below 1"),
                ));
            }
        }
        for (key, eff, min) in [
            (
                "compressor_efficiency_min",
                self.compressor_efficiency_max,
                self.compressor_efficiency_min,
            ),
            (
                "turbine_efficiency_min",
                self.turbine_efficiency_max,
                self.turbine_efficiency_min,
            ),
        ] {
            if !(min <= eff) {
                return Err(ParamError::new(
                    key,
                    show(min),
                    format!("must be at most the peak efficiency {}", show(eff)),
                ));
            }
        }
        // The throttle area must be positive over the whole input range 0..100 %: a negative
        // area is a sign error in the coefficients (the model would clamp it to no flow).
        for pct in (0..=100).map(f64::from) {
            let a = self.throttle_area_m2(pct);
            if !(a > 0.0) {
                return Err(ParamError::new(
                    "throttle_area_coeffs_m2_rad",
                    format!("{:?}", self.throttle_area_coeffs_m2_rad),
                    format!(
                        "give a non-positive area {} m^2 at {pct} % throttle",
                        show(a)
                    ),
                ));
            }
        }
        // The volumetric-efficiency factor must stay positive over the polynomial's range (and
        // the speed terms' range: the terms are a quadratic, so its extremes are at the ends or
        // at the vertex, all checked).
        let (lo, hi) = (self.vol_eff_poly_min_kpa, self.vol_eff_poly_max_kpa);
        let (n_lo, n_hi) = (self.vol_eff_speed_min_krpm, self.vol_eff_speed_max_krpm);
        let [s1, s2] = self.vol_eff_speed_coeffs_krpm;
        let mut speeds = vec![n_lo, n_hi];
        if s2 != 0.0 {
            let vertex = -s1 / (2.0 * s2);
            if vertex > n_lo && vertex < n_hi {
                speeds.push(vertex);
            }
        }
        for i in 0..=100 {
            let p = lo + (hi - lo) * f64::from(i) / 100.0;
            for &n in &speeds {
                let v = self.vol_eff_factor
                    * (poly4(&self.vol_eff_poly_kpa, p) + vol_eff_speed_terms(self, n));
                if !(v > 0.0 && v < 3.0) {
                    return Err(ParamError::new(
                        "vol_eff_poly_kpa",
                        format!(
                            "{:?} with speed terms {:?}",
                            self.vol_eff_poly_kpa, self.vol_eff_speed_coeffs_krpm
                        ),
                        format!(
                            "give a volumetric-efficiency factor {} at {p:.1} kPa and {n:.2} krpm \
                             (must be in (0, 3))",
                            show(v)
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Throttle effective area (m^2) at an input in percent (clamped to 0..100), floored at 0.
    pub fn throttle_area_m2(&self, throttle_pct: f64) -> f64 {
        let th = throttle_angle_rad(self, throttle_pct.clamp(0.0, 100.0));
        let [a0, a1, a2] = self.throttle_area_coeffs_m2_rad;
        (a0 + th * (a1 + th * a2)).max(0.0)
    }
}

/// Plate angle (rad) of a throttle input (%).
pub(crate) fn throttle_angle_rad(p: &TurboParams, pct: f64) -> f64 {
    (p.throttle_angle_gain_deg_per_pct * pct + p.throttle_angle_offset_deg) * PI / 180.0
}

/// The volumetric efficiency's speed terms `s1 n + s2 n^2` at `n` (1000 rpm, clamped).
pub(crate) fn vol_eff_speed_terms(p: &TurboParams, krpm: f64) -> f64 {
    let n = krpm.clamp(p.vol_eff_speed_min_krpm, p.vol_eff_speed_max_krpm);
    let [s1, s2] = p.vol_eff_speed_coeffs_krpm;
    n * (s1 + n * s2)
}

/// `c[0] x^4 + c[1] x^3 + ... + c[4]` (Horner).
pub(crate) fn poly4(c: &[f64; 5], x: f64) -> f64 {
    c.iter().fold(0.0, |acc, &k| acc * x + k)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize)]
    struct File {
        model: TurboParams,
    }

    fn load(text: &str) -> TurboParams {
        let file: File = toml::from_str(text).expect("parses");
        file.model
    }

    #[test]
    fn committed_parameter_files_parse_and_validate() {
        for text in [
            include_str!("../../../../config/turbo.toml"),
            include_str!("../../../../config/turbo_vep4.toml"),
            include_str!("../../../../config/turbo_tsfs09.toml"),
            include_str!("../../../../config/turbo_liu_ice.toml"),
        ] {
            let p = load(text);
            p.validate().expect("validates");
        }
    }

    #[test]
    fn errors_name_the_key() {
        let mut p = load(include_str!("../../../../config/turbo.toml"));
        p.compressor_diameter_m = 60.0; // mm for m
        let e = p.validate().unwrap_err();
        assert_eq!(e.key, "compressor_diameter_m", "{e}");
        let mut p = load(include_str!("../../../../config/turbo.toml"));
        p.throttle_linear_ratio = 0.3; // below the critical ratio 0.444 of k = 2
        assert_eq!(p.validate().unwrap_err().key, "throttle_linear_ratio");
        let mut p = load(include_str!("../../../../config/turbo.toml"));
        p.throttle_area_coeffs_m2_rad[0] = -1e-3;
        assert_eq!(p.validate().unwrap_err().key, "throttle_area_coeffs_m2_rad");
        let mut p = load(include_str!("../../../../config/turbo.toml"));
        p.turbo_speed_max_rad_s = 1000.0;
        assert_eq!(p.validate().unwrap_err().key, "turbo_speed_max_rad_s");
        let text = include_str!("../../../../config/turbo.toml")
            .replace("[model]", "[model]\ncompressor_radius_m = 0.03");
        let e = toml::from_str::<File>(&text)
            .err()
            .expect("unknown key refused");
        assert!(
            e.message().contains("compressor_radius_m"),
            "{}",
            e.message()
        );
    }
}
