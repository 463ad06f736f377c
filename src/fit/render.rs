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
enum Value {
    Num(f64),
    Arr(Vec<f64>),
}

/// Every key of the `[model]` table, in the order of `config/turbo.toml`.
fn entries(p: &TurboParams) -> Vec<(&'static str, Value)> {
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
        ("turbo_speed_min_rad_s", Num(p.turbo_speed_min_rad_s)),
        ("turbo_speed_max_rad_s", Num(p.turbo_speed_max_rad_s)),
    ]
}

/// A number in Rust's shortest round-trip form, which TOML reads back to the same `f64`
/// (always with a `.` or an exponent, so it stays a float).
fn num(v: f64) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
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
        "compressor_head_linear_fraction" | "compressor_efficiency_min" | "throttle_linear_ratio"
        | "turbine_linear_ratio" | "wastegate_linear_ratio" | "turbine_efficiency_min" => {
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
        "throttle_angle_gain_deg_per_pct" => kept(
            "the map's alpha is a fraction, given in % (x 100); 0.9 deg/% makes 100 % a 90 deg plate.",
        ),
        "throttle_angle_offset_deg" => vec![],
        "throttle_area_coeffs_m2_rad" => vec![format!(
            "Fitted: the area each point implies (W_air over the flow function at p_bef_thr, T_bef_thr, p_im), {} points with p_im/p_bef_thr < 0.95, relative weights; relative RMS {:.3}.",
            r.throttle.points, r.throttle.rms_rel
        )],
        "vol_eff_factor" => vec![
            "Fitted: the polynomial in p_im is the whole factor (C_eta_vol 1), linear least squares on the air".into(),
            format!(
                "flow with T_bef_thr (the model's T_im), {} points; W_air RMS {:.2} g/s, relative {:.3}. Range: the points' p_im.",
                r.vol_eff.points,
                r.vol_eff.rms_kg_s * 1000.0,
                r.vol_eff.rms_rel
            ),
        ],
        "vol_eff_poly_kpa" | "vol_eff_poly_min_kpa" | "vol_eff_poly_max_kpa" => vec![],
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
            "undetermined (the map has no wastegate position); the check solves the position per point.",
        ),
        "turbine_diameter_m" => kept("undetermined (only scales the fitted BSR_opt)."),
        "turbine_flow_k1_kg_k05_per_s_kpa" => vec![
            format!(
                "Fitted to the engine map where the wastegate is taken as closed (p_bef_thr/p_af >= {}, {} points):",
                opts.closed_wastegate_boost_ratio, r.turbine.points
            ),
            format!(
                "the exhaust flow at p_em, T_em, p_t: k1 {}; relative RMS {:.3}. turb_map.csv",
                est(&r.turbine.k1),
                r.turbine.rms_flow_rel
            ),
            format!(
                "gives k1 {:.4e}, k2 {:.3}: {:.2} times less flow than the engine passes (not used).",
                r.turbine_map.k1, r.turbine_map.k2, r.turbine_map.engine_to_map_flow_ratio
            ),
        ],
        "turbine_flow_k2" => kept(
            "undetermined: the measured flow parameter rises more steeply with the expansion ratio than the form allows for any k2 (a free k2 runs to 0).",
        ),
        "turbine_efficiency_max" => vec![
            format!(
                "Fitted at the same points: the torque the compressor model needs (plus friction) at its speed;"
            ),
            format!(
                "eta_max {}; relative RMS {:.3}. turb_map.csv: {:.3} at BSR {:.3} (not used).",
                est(&r.turbine.efficiency_max),
                r.turbine.rms_torque_rel,
                r.turbine_map.efficiency_max,
                r.turbine_map.bsr_at_efficiency_max
            ),
        ],
        "turbine_bsr_at_efficiency_max" => vec![format!(
            "Kept from the start file: undetermined (the points span BSR {:.3} to {:.3} only).",
            r.turbine.bsr_range.0, r.turbine.bsr_range.1
        )],
        "turbo_inertia_kg_m2" => kept("the shaft's inertia, friction and limits are not determined by stationary data."),
        "turbo_friction_n_m_s_per_rad" | "turbo_speed_min_rad_s" | "turbo_speed_max_rad_s" => vec![],
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
Wastegate: the map has no position; the turbine is fitted where the boost ratio is at least
{} (wastegate taken as closed), and the check below solves the position per point to match
the measured p_bef_thr (so p_ic is matched, not predicted, except where it saturates).
Undetermined by these data and kept from the start file: the volumes, the compressor and
turbine diameters, the intercooler resistance, the wastegate area, the pipe geometry other than
its length, the shaft, the numerical continuations and clamps.

",
        r.training_points,
        r.held_out_points,
        r.air_filter.ambient_pressure_pa.value,
        opts.closed_wastegate_boost_ratio
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
        let text = match value {
            Value::Num(v) => num(v),
            Value::Arr(a) => format!(
                "[{}]",
                a.iter().map(|v| num(*v)).collect::<Vec<_>>().join(", ")
            ),
        };
        let _ = writeln!(s, "{key} = {text}");
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
    })
}
