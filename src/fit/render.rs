//! The output of `fdd fit turbo`: the parameter file (every key, each with where its value
//! comes from), the error table and its JSON form.

use std::fmt::Write as _;

use fdd_estimators::models::turbo::fit::check::{MATCHED_QUANTITY, QUANTITIES};
use fdd_estimators::models::turbo::fit::components::Estimate;
use fdd_estimators::models::turbo::fit::{
    CheckReport, FitOptions, FitOutcome, QuantityStats, WastegateSolve,
};
use fdd_estimators::models::turbo::TurboParams;

/// A key's value: a number or an array.
pub(crate) enum Value {
    Num(f64),
    Arr(Vec<f64>),
}

/// Every key of the `[model]` table, in the order of `config/turbo.toml`.
pub(crate) fn entries(p: &TurboParams) -> Vec<(&'static str, Value)> {
    use Value::{Arr, Num};
    vec![
        (
            "air_gas_constant_j_per_kg_k",
            Num(p.air_gas_constant_j_per_kg_k),
        ),
        ("air_heat_capacity_ratio", Num(p.air_heat_capacity_ratio)),
        (
            "exhaust_gas_constant_j_per_kg_k",
            Num(p.exhaust_gas_constant_j_per_kg_k),
        ),
        (
            "exhaust_heat_capacity_ratio",
            Num(p.exhaust_heat_capacity_ratio),
        ),
        (
            "stoichiometric_air_fuel_ratio",
            Num(p.stoichiometric_air_fuel_ratio),
        ),
        ("displacement_m3", Num(p.displacement_m3)),
        ("compression_ratio", Num(p.compression_ratio)),
        ("air_filter_volume_m3", Num(p.air_filter_volume_m3)),
        ("compressor_volume_m3", Num(p.compressor_volume_m3)),
        ("intercooler_volume_m3", Num(p.intercooler_volume_m3)),
        (
            "intake_manifold_volume_m3",
            Num(p.intake_manifold_volume_m3),
        ),
        (
            "exhaust_manifold_volume_m3",
            Num(p.exhaust_manifold_volume_m3),
        ),
        ("exhaust_system_volume_m3", Num(p.exhaust_system_volume_m3)),
        (
            "air_filter_resistance_pa2_s2_per_kg2_k",
            Num(p.air_filter_resistance_pa2_s2_per_kg2_k),
        ),
        ("air_filter_linear_dp_pa", Num(p.air_filter_linear_dp_pa)),
        (
            "intercooler_resistance_pa2_s2_per_kg2_k",
            Num(p.intercooler_resistance_pa2_s2_per_kg2_k),
        ),
        ("intercooler_linear_dp_pa", Num(p.intercooler_linear_dp_pa)),
        (
            "intercooler_effectiveness",
            Num(p.intercooler_effectiveness),
        ),
        (
            "exhaust_resistance_pa2_s2_per_kg2_k",
            Num(p.exhaust_resistance_pa2_s2_per_kg2_k),
        ),
        ("exhaust_linear_dp_pa", Num(p.exhaust_linear_dp_pa)),
        ("compressor_diameter_m", Num(p.compressor_diameter_m)),
        ("compressor_head_max", Num(p.compressor_head_max)),
        ("compressor_flow_max", Num(p.compressor_flow_max)),
        (
            "compressor_head_linear_fraction",
            Num(p.compressor_head_linear_fraction),
        ),
        (
            "compressor_efficiency_max",
            Num(p.compressor_efficiency_max),
        ),
        (
            "compressor_flow_at_efficiency_max",
            Num(p.compressor_flow_at_efficiency_max),
        ),
        (
            "compressor_efficiency_min",
            Num(p.compressor_efficiency_min),
        ),
        (
            "throttle_heat_capacity_ratio",
            Num(p.throttle_heat_capacity_ratio),
        ),
        ("throttle_linear_ratio", Num(p.throttle_linear_ratio)),
        (
            "throttle_angle_gain_deg_per_pct",
            Num(p.throttle_angle_gain_deg_per_pct),
        ),
        (
            "throttle_angle_offset_deg",
            Num(p.throttle_angle_offset_deg),
        ),
        (
            "throttle_area_coeffs_m2_rad",
            Arr(p.throttle_area_coeffs_m2_rad.to_vec()),
        ),
        ("vol_eff_factor", Num(p.vol_eff_factor)),
        ("vol_eff_poly_kpa", Arr(p.vol_eff_poly_kpa.to_vec())),
        ("vol_eff_poly_min_kpa", Num(p.vol_eff_poly_min_kpa)),
        ("vol_eff_poly_max_kpa", Num(p.vol_eff_poly_max_kpa)),
        (
            "vol_eff_speed_coeffs_krpm",
            Arr(p.vol_eff_speed_coeffs_krpm.to_vec()),
        ),
        ("vol_eff_speed_min_krpm", Num(p.vol_eff_speed_min_krpm)),
        ("vol_eff_speed_max_krpm", Num(p.vol_eff_speed_max_krpm)),
        ("exhaust_temp_zero_flow_k", Num(p.exhaust_temp_zero_flow_k)),
        (
            "exhaust_temp_flow_gain_k_s_per_kg",
            Num(p.exhaust_temp_flow_gain_k_s_per_kg),
        ),
        ("exhaust_pipe_diameter_m", Num(p.exhaust_pipe_diameter_m)),
        ("exhaust_pipe_length_m", Num(p.exhaust_pipe_length_m)),
        ("exhaust_pipe_count", Num(p.exhaust_pipe_count)),
        (
            "exhaust_pipe_h_ext_w_per_m2_k",
            Num(p.exhaust_pipe_h_ext_w_per_m2_k),
        ),
        (
            "exhaust_pipe_nusselt_coeff",
            Num(p.exhaust_pipe_nusselt_coeff),
        ),
        (
            "exhaust_pipe_nusselt_exponent",
            Num(p.exhaust_pipe_nusselt_exponent),
        ),
        (
            "exhaust_gas_viscosity_pa_s",
            Num(p.exhaust_gas_viscosity_pa_s),
        ),
        (
            "exhaust_gas_conductivity_w_per_m_k",
            Num(p.exhaust_gas_conductivity_w_per_m_k),
        ),
        (
            "wastegate_effective_area_m2",
            Num(p.wastegate_effective_area_m2),
        ),
        ("wastegate_linear_ratio", Num(p.wastegate_linear_ratio)),
        ("turbine_diameter_m", Num(p.turbine_diameter_m)),
        (
            "turbine_flow_k1_kg_k05_per_s_kpa",
            Num(p.turbine_flow_k1_kg_k05_per_s_kpa),
        ),
        ("turbine_flow_k2", Num(p.turbine_flow_k2)),
        ("turbine_linear_ratio", Num(p.turbine_linear_ratio)),
        ("turbine_efficiency_max", Num(p.turbine_efficiency_max)),
        (
            "turbine_bsr_at_efficiency_max",
            Num(p.turbine_bsr_at_efficiency_max),
        ),
        ("turbine_efficiency_min", Num(p.turbine_efficiency_min)),
        ("turbo_inertia_kg_m2", Num(p.turbo_inertia_kg_m2)),
        (
            "turbo_friction_n_m_s_per_rad",
            Num(p.turbo_friction_n_m_s_per_rad),
        ),
        (
            "turbo_friction_torque_n_m",
            Num(p.turbo_friction_torque_n_m),
        ),
        ("turbo_speed_min_rad_s", Num(p.turbo_speed_min_rad_s)),
        ("turbo_speed_max_rad_s", Num(p.turbo_speed_max_rad_s)),
    ]
}

/// A number in Rust's shortest round-trip form, which TOML reads back to the same `f64`
/// (always with a `.` or an exponent, so it stays a float).
pub(crate) fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

/// A value as TOML text.
pub(crate) fn value_text(v: &Value) -> String {
    match v {
        Value::Num(v) => num(*v),
        Value::Arr(a) => format!(
            "[{}]",
            a.iter().map(|v| num(*v)).collect::<Vec<_>>().join(", ")
        ),
    }
}

fn est(e: &Estimate) -> String {
    if e.std_error.is_finite() {
        format!("{:.4e} +- {:.1e}", e.value, e.std_error)
    } else {
        format!("{:.4e}", e.value)
    }
}

/// Where a key's value comes from (comment lines, without the `# `).
fn note(key: &str, o: &FitOutcome, opts: &FitOptions) -> Vec<String> {
    let r = &o.report;
    let kept = |why: &str| vec![format!("Kept from the start file: {why}")];
    match key {
        "air_gas_constant_j_per_kg_k" => vec![
            "Gas properties kept from the start file (the data's own constants, R 280 and gamma 1.3,"
                .into(),
            "are course values; every fit below uses these, so the fitted values go with them)."
                .into(),
        ],
        "air_heat_capacity_ratio" | "exhaust_gas_constant_j_per_kg_k" | "exhaust_heat_capacity_ratio" => {
            vec![]
        }
        "stoichiometric_air_fuel_ratio" => vec![format!(
            "Engine constants of the data (README): AFs {}, V_D {} m^3, r_c {}.",
            opts.stoichiometric_air_fuel_ratio, opts.displacement_m3, opts.compression_ratio
        )],
        "displacement_m3" | "compression_ratio" => vec![],
        "air_filter_volume_m3" => vec![
            "Volumes kept from the start file: stationary data do not determine them (they only set"
                .into(),
            "the time constants).".into(),
        ],
        "compressor_volume_m3" | "intercooler_volume_m3" | "intake_manifold_volume_m3"
        | "exhaust_manifold_volume_m3" | "exhaust_system_volume_m3" => vec![],
        "air_filter_resistance_pa2_s2_per_kg2_k" => vec![
            format!(
                "Fitted with one ambient pressure for the whole map (the map has no barometer column):"
            ),
            format!(
                "p_af = p_amb - dp(W_air) at T_af, {} points: H {}, p_amb {} Pa; p_af RMS {:.0} Pa.",
                r.air_filter.points,
                est(&r.air_filter.resistance),
                est(&r.air_filter.ambient_pressure_pa),
                r.air_filter.rms_pa
            ),
        ],
        "air_filter_linear_dp_pa" | "intercooler_linear_dp_pa" | "exhaust_linear_dp_pa" => {
            kept("a numerical choice (linear below it), not a property the map measures.")
        }
        "intercooler_resistance_pa2_s2_per_kg2_k" => kept(
            "undetermined (the map has no compressor-outlet pressure); it sets the compressor outlet pressure the compressor and turbine fits assume.",
        ),
        "intercooler_effectiveness" => vec![format!(
            "Fitted: T_bef_thr = T_c - eps (T_c - T_af) with the compressor model's T_c, {} points; T_bef_thr RMS {:.2} K.",
            r.intercooler.points, r.intercooler.rms_k
        )],
        "exhaust_resistance_pa2_s2_per_kg2_k" => vec![format!(
            "Fitted: p_t upstream of the restriction into p_amb, exhaust flow W_air (1 + 1/(AFs lambda)) at T_t, {} points: H {}; p_t RMS {:.0} Pa.",
            r.exhaust.points,
            est(&r.exhaust.resistance),
            r.exhaust.rms_pa
        )],
        "compressor_diameter_m" => kept(
            "undetermined by a map in corrected quantities (the fitted Psi_max, Phi_max, Phi_opt scale with it).",
        ),
        "compressor_head_max" => vec![format!(
            "Fitted to comp_map.csv ({} points, corrected quantities read at {} K, {} Pa): Psi_max {}, Phi_max {}; Phi RMS {:.4}.",
            r.compressor.points,
            opts.compressor_reference_temperature_k,
            opts.compressor_reference_pressure_pa,
            est(&r.compressor.head_max),
            est(&r.compressor.flow_max),
            r.compressor.rms_phi
        )],
        "compressor_flow_max" => vec![],
        "compressor_head_linear_fraction" | "compressor_efficiency_min"
        | "wastegate_linear_ratio" | "turbine_efficiency_min" => {
            kept("a numerical choice of the model (continuation or clamp), not fitted.")
        }
        "compressor_efficiency_max" => vec![format!(
            "Fitted to comp_map.csv: eta_max {}, Phi_opt {}; efficiency RMS {:.4}.",
            est(&r.compressor.efficiency_max),
            est(&r.compressor.flow_at_efficiency_max),
            r.compressor.rms_eta
        )],
        "compressor_flow_at_efficiency_max" => vec![],
        "throttle_heat_capacity_ratio" => kept("the tuned k_th of the model's flow function."),
        "throttle_linear_ratio" => vec![format!(
            "Set by the fit (not the start file's): {}, as the wastegate's and turbine's; it decides the flow of a nearly",
            opts.throttle_linear_ratio
        ), "wide-open throttle (0.9 would make it proportional to a 1 % pressure drop instead of its square root).".into()],
        "throttle_angle_gain_deg_per_pct" => kept(
            "the map's alpha is a fraction, given in % (x 100); 0.9 deg/% makes 100 % a 90 deg plate.",
        ),
        "throttle_angle_offset_deg" => vec![],
        "throttle_area_coeffs_m2_rad" => vec![
            format!(
                "Fitted in two steps: the area each point implies (W_air over the flow function at p_bef_thr, T_bef_thr, p_im),"
            ),
            format!(
                "{} points with p_im/p_bef_thr < 0.95, relative weights (relative RMS {:.3}); then on the p_im the throttle gives",
                r.throttle.area_points, r.throttle.area_rms_rel
            ),
            format!(
                "at the measured p_bef_thr, T_bef_thr and flow, all {} points (wide open included); p_im RMS {:.0} Pa.",
                r.throttle.points, r.throttle.rms_p_im_pa
            ),
        ],
        "vol_eff_factor" => vec![
            "Fitted: the factor is poly4(p_im) + s1 n + s2 n^2 (C_eta_vol 1, n in 1000 rpm; the additive speed term of Eriksson".into(),
            "and Nielsen, quadratic as Guzzella and Onder's eta_omega), linear least squares on the air flow with T_bef_thr (the".into(),
            format!(
                "model's T_im), {} points; W_air RMS {:.2} g/s, relative {:.3}. Ranges: the points' p_im and speed.",
                r.vol_eff.points,
                r.vol_eff.rms_kg_s * 1000.0,
                r.vol_eff.rms_rel
            ),
        ],
        "vol_eff_poly_kpa"
        | "vol_eff_poly_min_kpa"
        | "vol_eff_poly_max_kpa"
        | "vol_eff_speed_coeffs_krpm"
        | "vol_eff_speed_min_krpm"
        | "vol_eff_speed_max_krpm" => vec![],
        "exhaust_temp_zero_flow_k" => vec![format!(
            "Fitted with the pipe length (T_em at the measured exhaust flow, {} points): T_0 {} K, C_eo {} K s/kg, length {} m; T_em RMS {:.1} K.",
            r.exhaust_temp.points,
            est(&r.exhaust_temp.t0_k),
            est(&r.exhaust_temp.c_eo),
            est(&r.exhaust_temp.pipe_length_m),
            r.exhaust_temp.rms_k
        )],
        "exhaust_temp_flow_gain_k_s_per_kg" => vec![],
        "exhaust_pipe_diameter_m" => kept(
            "with the fitted length these pipe and gas properties are not separately determined by a temperature.",
        ),
        "exhaust_pipe_length_m" | "exhaust_pipe_count" | "exhaust_pipe_h_ext_w_per_m2_k"
        | "exhaust_pipe_nusselt_coeff" | "exhaust_pipe_nusselt_exponent"
        | "exhaust_gas_viscosity_pa_s" | "exhaust_gas_conductivity_w_per_m_k" => vec![],
        "wastegate_effective_area_m2" => kept(
            "undetermined (the map has no wastegate position); the check solves the position per point, and only position x area enters the model.",
        ),
        "turbine_diameter_m" => kept("undetermined (only scales the fitted BSR_opt)."),
        "turbine_flow_k1_kg_k05_per_s_kpa" => vec![
            "Fitted to the turbine flow the power balance implies, whatever the wastegate passed: the compressor".into(),
            "model's power plus friction over the turbine's work per kg at the measured p_em, T_em, p_t with the".into(),
            format!(
                "map's efficiency; {} of {} training points where the compressor works; k1 {}, flow RMS {:.2} g/s.",
                r.turbine.points,
                r.turbine.working_points,
                est(&r.turbine.k1),
                r.turbine.rms_kg_s * 1000.0
            ),
            format!(
                "The flow is linear in p_em - p_t over the mapped ratios: the square-root form with k1, k2 free fits {:.2} g/s",
                r.turbine.sqrt_form_rms_kg_s * 1000.0
            ),
            format!(
                "with k2 running to {:.1e}. The wastegate then passes {:.1} % of the exhaust on average there (at most {:.1} %).",
                r.turbine.sqrt_form_k2,
                100.0 * r.turbine.bypass_share.0,
                100.0 * r.turbine.bypass_share.1
            ),
            format!(
                "turb_map.csv's flow parameter fits k1 {:.4e}, k2 {:.3}: 4 to 5 times less flow, not used (unit or reference unclear).",
                r.turbine_map.k1, r.turbine_map.k2
            ),
        ],
        "turbine_flow_k2" => kept(
            "only shapes the flow beyond the linear continuation's start, at expansion ratios no map point reaches.",
        ),
        "turbine_linear_ratio" => vec![format!(
            "Set by the fit: the smallest Pi_t = p_t/p_em of the points used, rounded down to 0.05 ({}), so that the flow is",
            r.turbine.linear_ratio
        ), "linear in 1 - Pi_t over the whole mapped range.".into()],
        "turbine_efficiency_max" => vec![format!(
            "From turb_map.csv ({} points; BSR at T03 {} K with the turbine diameter): eta_max {:.4}, BSR_opt {:.4}; RMS {:.4}.",
            r.turbine_map.points,
            opts.turbine_reference_temperature_k,
            r.turbine_map.efficiency_max,
            r.turbine_map.bsr_at_efficiency_max,
            r.turbine_map.rms_eta
        )],
        "turbine_bsr_at_efficiency_max" => vec![format!(
            "(the engine's working points span BSR {:.3} to {:.3} with the model's turbo speed)",
            r.turbine.bsr_range.0, r.turbine.bsr_range.1
        )],
        "turbo_inertia_kg_m2" => kept("the shaft's inertia, viscous friction and speed limits are not determined by stationary data."),
        "turbo_friction_n_m_s_per_rad" | "turbo_speed_min_rad_s" | "turbo_speed_max_rad_s" => vec![],
        "turbo_friction_torque_n_m" => match &r.shaft {
            Some(f) => vec![
                format!(
                    "Fitted to a measured turbo speed (the map has none): the model's stationary speed at the start of {}",
                    crate::reproduce::turbo::TUNING_LOG
                ),
                format!(
                    "(throttle {:.2} %, engine speed {:.0} rpm read off the map, the wastegate the map needs there {:.3}, lambda {})",
                    f.anchor.throttle_pct,
                    f.anchor.engine_speed_rad_s * 60.0 / std::f64::consts::TAU,
                    f.wastegate_frac,
                    f.anchor.lambda
                ),
                format!(
                    "equals the measured {:.0} rad/s ({:.0} rad/s without it); the turbine flow above is refitted with it. A loss",
                    f.anchor.turbo_speed_rad_s, f.start_speed_rad_s
                ),
                "independent of the speed, not more viscous friction: that one costs kilowatts at full load (fit::shaft).".into(),
            ],
            None => kept("no log with a measured turbo speed: not determined by stationary data."),
        },
        _ => kept("not fitted."),
    }
}

/// The error table (plain text): all points, then the held-out ones.
pub fn table(check: &CheckReport) -> String {
    let mut s = String::new();
    let (closed, open) = check.saturated();
    let n_all = check.points.len();
    let n_held = check.points.iter().filter(|p| p.held_out).count();
    let _ = writeln!(
        s,
        "Whole-model stationary check: {n_all} points; wastegate solved per point to match p_ic \
         (saturated closed at {closed}, open at {open} points)"
    );
    for (title, stats, n) in [
        ("all points", &check.all, n_all),
        ("held-out points (every 5th)", &check.held_out, n_held),
    ] {
        let _ = writeln!(s, "{title} ({n}):");
        let _ = writeln!(
            s,
            "  {:<9} {:>5} {:>12} {:>12} {:>8} {:>11} {:>12}",
            "quantity", "unit", "mean", "RMSE", "RMSE %", "worst line", "worst error"
        );
        for (q, (name, unit)) in QUANTITIES.iter().enumerate() {
            let st: &QuantityStats = &stats[q];
            let (scale, unit) = match *unit {
                "Pa" => (1e-3, "kPa"),
                "kg/s" => (1e3, "g/s"),
                u => (1.0, u),
            };
            let mark = if q == MATCHED_QUANTITY {
                " (matched)"
            } else {
                ""
            };
            let _ = writeln!(
                s,
                "  {:<9} {:>5} {:>12.3} {:>12.3} {:>8.2} {:>11} {:>12.3}{mark}",
                name,
                unit,
                st.mean * scale,
                st.rmse * scale,
                st.rmse_pct,
                st.worst_index + 2,
                st.worst_error * scale
            );
        }
    }
    s
}

/// The parameter file's text.
pub fn parameter_file(o: &FitOutcome, check: &CheckReport, opts: &FitOptions) -> String {
    let r = &o.report;
    let mut s = String::new();
    let header = format!(
        "Mean value model of the air path of a turbocharged SI engine (13 states), calibrated to the
LiU TSFS09 2.3 L engine (fixtures/data/real/liu-tsfs09: engine_map.csv, comp_map.csv,
turb_map.csv). Generated by `fdd fit turbo` (do not edit; FDD_BLESS=1 cargo test --release
--test fit_turbo regenerates it from config/turbo.toml):

  fdd fit turbo --data fixtures/data/real/liu-tsfs09 --start config/turbo.toml \\
      -o config/turbo_tsfs09.toml

Model: estimators/src/models/turbo/ (fit: its fit/ module). Each component is fitted where the
map measures both its sides, with the model's own component code; every 5th map point (line 6,
11, ...) is held out of these fits ({} training, {} held out). Ambient: one pressure for the
whole map, fitted with the air filter ({:.0} Pa); the ambient temperature is each point's T_af.
Volumetric efficiency: a 4th-order polynomial in p_im plus a quadratic in engine speed.
Throttle: fitted on the p_im it gives (wide-open points included), its linear continuation
from 0.99. Wastegate: the map has no position, and no point is assumed to have it closed: the
turbine's efficiency is the turbine map's, its flow what the power balance with the compressor
model implies it passed (linear in p_em - p_t over the mapped range); the check below solves
the position per point to match the measured p_bef_thr (so p_ic is matched, not predicted,
except where it saturates). Every choice was made on the training points' figures only.
Undetermined by these data and kept from the start file: the volumes, the compressor and
turbine diameters, the intercooler resistance, the wastegate area (only position x area
enters), the turbine's k2 (beyond the mapped ratios), the pipe geometry other than its length,
the shaft, the other numerical continuations and clamps.

",
        r.training_points,
        r.held_out_points,
        r.air_filter.ambient_pressure_pa.value,
    );
    for line in header.lines().chain(table(check).lines()) {
        if line.is_empty() {
            s.push_str("#\n");
        } else {
            let _ = writeln!(s, "# {line}");
        }
    }
    s.push_str("\n[model]\n");
    for (key, value) in entries(&o.params) {
        for line in note(key, o, opts) {
            let _ = writeln!(s, "# {line}");
        }
        let _ = writeln!(s, "{key} = {}", value_text(&value));
    }
    s
}

/// The figures as JSON (for machines and the tests).
pub fn json(o: &FitOutcome, check: &CheckReport) -> serde_json::Value {
    let stats = |st: &[QuantityStats; 10]| {
        serde_json::Value::Object(
            QUANTITIES
                .iter()
                .zip(st.iter())
                .map(|((name, unit), q)| {
                    (
                        (*name).to_string(),
                        serde_json::json!({
                            "unit": unit,
                            "mean": q.mean,
                            "rmse": q.rmse,
                            "rmse_pct": q.rmse_pct,
                            "worst_line": q.worst_index + 2,
                            "worst_error": q.worst_error,
                            "points": q.points,
                        }),
                    )
                })
                .collect(),
        )
    };
    let (closed, open) = check.saturated();
    let r = &o.report;
    serde_json::json!({
        "matched_quantity": QUANTITIES[MATCHED_QUANTITY].0,
        "ambient_pressure_pa": r.air_filter.ambient_pressure_pa.value,
        "training_points": r.training_points,
        "held_out_points": r.held_out_points,
        "wastegate_saturated_closed": closed,
        "wastegate_saturated_open": open,
        "wastegate_positions": check.points.iter().map(|p| p.wastegate).collect::<Vec<_>>(),
        "wastegate_matched": check.points.iter().filter(|p| p.solve == WastegateSolve::Matched).count(),
        "all": stats(&check.all),
        "held_out": stats(&check.held_out),
        "points": check.points.iter().map(|p| serde_json::json!({
            "line": p.index + 2,
            "held_out": p.held_out,
            "wastegate": p.wastegate,
            "turbo_speed_rad_s": p.turbo_speed_rad_s,
            "model": QUANTITIES.iter().zip(p.model).map(|((n, _), v)| ((*n).to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
            "measured": QUANTITIES.iter().zip(p.measured).map(|((n, _), v)| ((*n).to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
        })).collect::<Vec<_>>(),
    })
}
