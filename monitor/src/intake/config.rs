//! Settings of the intake-manifold monitor (`[monitor]` in `config/intake.toml`). Every key has
//! a default, so the table may be partial or absent. Units are in the key names.

use serde::Deserialize;

/// Which filter's estimate is the monitor's output (`primary_filter`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PrimaryFilter {
    /// The centralized EKF on MAP and MAF.
    #[default]
    Centralized,
    /// The paper's decentralized pair (naive fusion, optimistic covariance).
    Decentralized,
    /// The federated filter (fusion-reset).
    Federated,
}

impl PrimaryFilter {
    /// Name used as the estimate's source.
    pub fn name(self) -> &'static str {
        match self {
            PrimaryFilter::Centralized => "centralized_ekf",
            PrimaryFilter::Decentralized => "decentralized_ekf",
            PrimaryFilter::Federated => "federated_ekf",
        }
    }
}

/// Intake monitor settings.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct IntakeMonitorConfig {
    /// Runtime signal names: engine speed (rpm), throttle opening (deg from closed), EGR
    /// command (0..1), MAP (Pa), MAF (kg/s). One sample of each per 180 deg crank segment.
    pub speed_signal: String,
    pub throttle_signal: String,
    pub egr_signal: String,
    pub map_signal: String,
    pub maf_signal: String,
    /// How often the monitor looks for a new segment (s). The filters step once per segment
    /// (when a MAP and a MAF sample with a newer time stamp are both there); polling at 1 ms
    /// adds at most 1 ms of latency to a 5..100 ms segment.
    pub poll_period_s: f64,
    /// Estimate reported as the monitor's output.
    pub primary_filter: PrimaryFilter,
    /// Process noise standard deviations per segment of `[p_m (Pa), p_mes (Pa), W_thr (kg/s),
    /// W_mes (kg/s), q1 (Pa), q2 (Pa/s)]` of the paper's filter model (throttle flow a random
    /// walk). The same values as `fdd reproduce intake`, where they give a mean NIS within 10 %
    /// of 2 on the transient profile.
    pub q_std: [f64; 6],
    /// Initial standard deviations: pressures (Pa), flows relative to the initial flow (-),
    /// pulsation (Pa) and its rate (Pa/s), in state order.
    pub p0_std: [f64; 6],
    /// MAP noise standard deviation used as R (Pa).
    pub map_noise_pa: f64,
    /// MAF noise standard deviation used as R (kg/s): 1.5 % of a 20 g/s mid-load flow (a
    /// constant R cannot follow the sensor's relative noise).
    pub maf_noise_kg_s: f64,
    /// MAF relative noise (-), used for the throttle-model flow residual's variance.
    pub maf_noise_rel: f64,
    /// Information-sharing factors of the federated filter (MAP local, MAF local).
    pub federated_shares: [f64; 2],
    /// Circuit range checks: a MAP reading below `map_low_pa` or above `map_high_ratio * p_a`
    /// (no naturally aspirated manifold gets there), a MAF reading below `maf_low_kg_s` or above
    /// `maf_high_kg_s`, for `circuit_persist_segments` segments in a row, is a circuit fault.
    /// Such readings never reach the filters.
    pub map_low_pa: f64,
    /// A MAP reading below `map_low_pa` is a circuit fault only while the filter's estimate
    /// of the sensor's pressure, less three standard deviations, stays above `map_low_pa +
    /// map_low_margin_pa` (Pa): a manifold really that low (a closed-throttle tip-out from high
    /// speed reaches 10 kPa) is what a healthy sensor reports, and the model knows it. Before
    /// the filters start, the model's steady state for the segment's inputs stands for the
    /// estimate. The throttle monitor judges its TPS rails the same way.
    pub map_low_margin_pa: f64,
    pub map_high_ratio: f64,
    pub maf_low_kg_s: f64,
    /// The same for MAF below `maf_low_kg_s` (kg/s): it counts only while the filter's
    /// estimate of the sensor's flow less three standard deviations is above `maf_low_kg_s +
    /// maf_low_margin_kg_s` (a closed plate at high speed passes only its leakage flow).
    pub maf_low_margin_kg_s: f64,
    pub maf_high_kg_s: f64,
    pub circuit_persist_segments: u32,
    /// A MAP or MAF reading repeated exactly this many segments in a row is a stuck sensor
    /// (its range/performance DTC): the noise of a live sensor moves its reading every segment.
    pub frozen_segments: u32,
    /// Normalized residuals are clipped to +-this before the CUSUMs (robust to rare transient
    /// outliers; the isolation fits use them unclipped).
    pub clip_sigma: f64,
    /// Pressure-consistency test: CUSUM on the MAP reading against the MAF-local filter's MAP
    /// prediction (normalized): smallest bias (sigma) and threshold.
    pub pressure_cusum_min_bias_sigma: f64,
    pub pressure_cusum_threshold: f64,
    /// Flow-consistency test: CUSUM on the MAF reading against the MAP-local filter's MAF
    /// prediction.
    pub flow_cusum_min_bias_sigma: f64,
    pub flow_cusum_threshold: f64,
    /// Throttle-model test: CUSUM on the MAF reading against the throttle nozzle flow at the
    /// commanded opening, evaluated only while the throttle is choked (estimated manifold
    /// pressure below `choked_ratio * p_a`), where the nozzle flow does not depend on the
    /// manifold pressure and so on neither the MAP sensor, the EGR nor a leak.
    pub throttle_cusum_min_bias_sigma: f64,
    pub throttle_cusum_threshold: f64,
    pub choked_ratio: f64,
    /// The isolation bank's throttle-flow residual (MAF against the nozzle flow at the MAP
    /// reading) is used while the MAP reading is below `flow_ratio_max * p_a`; nearer ambient
    /// the flow function is too steep for a MAP error to act on it linearly.
    pub flow_ratio_max: f64,
    /// Relative uncertainty of the throttle flow model (-), added to the throttle-model
    /// residual's variance.
    pub throttle_model_rel: f64,
    /// NIS window tests on the centralized EKF and on the federated filter (2 dof each): sum of
    /// NIS (each capped at `nis_cap`) over `nis_window` segments, failed above `nis_threshold`.
    pub nis_window: usize,
    pub nis_cap: f64,
    pub nis_threshold: f64,
    /// Isolation: after a test fails, the fault hypotheses are fitted from the estimated onset.
    /// The best one is named when its GLR statistic exceeds `isolation_min_glr` and leads the
    /// runner-up by `isolation_margin`, at least `isolation_min_s` after the alarm. A fault
    /// that is significant but ambiguous is never forced: the episode stays open until the
    /// driving separates the hypotheses. An episode in which no hypothesis is significant
    /// `isolation_max_s` after the alarm is dropped as unexplained.
    pub isolation_min_glr: f64,
    pub isolation_margin: f64,
    pub isolation_min_s: f64,
    pub isolation_max_s: f64,
    /// DTCs (SAE J2012 code and failure type byte).
    pub dtc_map_performance: String,
    pub dtc_map_low: String,
    pub dtc_map_high: String,
    pub dtc_maf_performance: String,
    pub dtc_maf_low: String,
    pub dtc_maf_high: String,
    pub dtc_egr_insufficient: String,
    pub dtc_egr_excessive: String,
    pub dtc_leak: String,
}

impl Default for IntakeMonitorConfig {
    fn default() -> Self {
        Self {
            speed_signal: "engine_speed".into(),
            throttle_signal: "intake_throttle".into(),
            egr_signal: "egr_command".into(),
            map_signal: "map".into(),
            maf_signal: "maf".into(),
            poll_period_s: 0.001,
            primary_filter: PrimaryFilter::Centralized,
            q_std: [150.0, 20.0, 2.1e-3, 3e-5, 200.0, 6e4],
            p0_std: [2e3, 2e3, 0.1, 0.1, 1e3, 1e5],
            map_noise_pa: 700.0,
            maf_noise_kg_s: 3e-4,
            maf_noise_rel: 0.015,
            federated_shares: [0.5, 0.5],
            map_low_pa: 10_000.0,
            map_low_margin_pa: 5_000.0,
            map_high_ratio: 1.10,
            maf_low_kg_s: 5e-4,
            maf_low_margin_kg_s: 1e-3,
            maf_high_kg_s: 0.25,
            circuit_persist_segments: 10,
            frozen_segments: 10,
            clip_sigma: 8.0,
            pressure_cusum_min_bias_sigma: 2.0,
            pressure_cusum_threshold: 40.0,
            flow_cusum_min_bias_sigma: 2.0,
            flow_cusum_threshold: 60.0,
            throttle_cusum_min_bias_sigma: 2.0,
            throttle_cusum_threshold: 40.0,
            choked_ratio: 0.5,
            flow_ratio_max: 0.9,
            throttle_model_rel: 0.01,
            nis_window: 50,
            nis_cap: 50.0,
            nis_threshold: 1000.0,
            isolation_min_glr: 60.0,
            isolation_margin: 50.0,
            isolation_min_s: 0.2,
            isolation_max_s: 4.0,
            dtc_map_performance: "P0106-64".into(),
            dtc_map_low: "P0107-16".into(),
            dtc_map_high: "P0108-17".into(),
            dtc_maf_performance: "P0101-64".into(),
            dtc_maf_low: "P0102-16".into(),
            dtc_maf_high: "P0103-17".into(),
            dtc_egr_insufficient: "P0401-00".into(),
            dtc_egr_excessive: "P0402-00".into(),
            dtc_leak: "P2279-00".into(),
        }
    }
}
