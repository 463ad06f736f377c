//! The observer's gain table as a calibration file, as an ECU carries it: designing the gains
//! ([`super::design`]) solves a Riccati equation at every node (about half a second for a
//! table), too slow for a monitor's construction, so `fdd fit turbo-gains` designs them
//! offline and writes them, and the monitor embeds the file (`include_str!`) and loads it here.
//!
//! This module is pure: [`GainFileData`] is the file's serde structure (any serde format; the
//! files are TOML, parsed by the caller, who owns the I/O), [`GainFile::from_data`] checks it
//! and builds the [`GainTable`], and [`GainFile::render`] writes the data part of the file in a
//! deterministic text form that parses back to the same values (Rust's shortest round-trip
//! float form). Every error names the file, the table and the key.
//!
//! # Layout
//!
//! ```toml
//! [gains]
//! sample_time_s = 0.05                    # the observer's sample time the gains are for (s)
//! sensors = ["p_ic", "p_im", "maf"]       # the columns of K, in the order of y
//! measurement_variance = [437.4, 2.4e5, 5.8e-10]  # R used in the design, sensor units^2
//! ambient_pressure_pa = 101300.0          # the design's conditions
//! ambient_temperature_k = 301.0
//! lambda = 1.0
//! speeds_rad_s = [80.0, 150.0]            # grid, increasing
//! pressures_pa = [20000.0, 40000.0]
//!
//! [[node]]                                # one per grid node, speed-major
//! speed_rad_s = 80.0
//! pressure_pa = 20000.0
//! reachable = true                        # false: the nearest reachable node's point
//! throttle_pct = 1.2                      # the operating point the gain was designed at
//! wastegate_frac = 0.62
//! closed_loop_radius = 0.97               # spectral radius of (I - K C) Phi there
//! k = [[...], ...]                        # 14 rows (states) of one value per sensor
//! ```

use std::fmt::Write as _;

use nalgebra::SMatrix;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use super::gains::GainTable;
use super::Sensor;
use crate::models::turbo::{N_STATES_AUGMENTED, STATE_NAMES};

/// A gain file that cannot be used: which file, which table, which key, and why.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{file}: [{table}] {key}: {problem}")]
pub struct GainFileError {
    /// The file's name as the caller gave it.
    pub file: String,
    /// The table (`gains`, or `node` with its index, e.g. `node 3`).
    pub table: String,
    /// The key within it (e.g. `sensors[2]`, `k[5]`).
    pub key: String,
    /// What is wrong.
    pub problem: String,
}

/// The `[gains]` table: what the gains are for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainHeaderData {
    /// The sample time the gains were designed for (s).
    pub sample_time_s: f64,
    /// The sensors' names ([`Sensor::name`]), in the order of the gains' columns.
    pub sensors: Vec<String>,
    /// The measurement noise variance the design used, per sensor (sensor units squared).
    pub measurement_variance: Vec<f64>,
    /// Ambient pressure of the design's operating points (Pa).
    pub ambient_pressure_pa: f64,
    /// Ambient temperature of the design's operating points (K).
    pub ambient_temperature_k: f64,
    /// Normalized air/fuel ratio of the design's operating points (-).
    pub lambda: f64,
    /// Speed nodes (rad/s), strictly increasing.
    pub speeds_rad_s: Vec<f64>,
    /// Intake manifold pressure nodes (Pa), strictly increasing.
    pub pressures_pa: Vec<f64>,
}

/// One `[[node]]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainNodeData {
    /// The node's engine speed (rad/s); must equal the grid's.
    pub speed_rad_s: f64,
    /// The node's intake manifold pressure (Pa); must equal the grid's.
    pub pressure_pa: f64,
    /// Whether the actuator path reaches the node's pressure at its speed; if not, the gain is
    /// the nearest reachable node's at the same speed.
    pub reachable: bool,
    /// Throttle of the operating point the gain was designed at (%).
    pub throttle_pct: f64,
    /// Wastegate of that operating point (0 closed .. 1 open).
    pub wastegate_frac: f64,
    /// Spectral radius of the discrete closed loop `(I - K C) Phi` at that point (-).
    pub closed_loop_radius: f64,
    /// The gain, one row per state (14), one value per sensor (state units per sensor unit).
    pub k: Vec<Vec<f64>>,
}

/// The whole file's data (the header comment is not data).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GainFileData {
    /// What the gains are for.
    pub gains: GainHeaderData,
    /// The nodes, speed-major.
    #[serde(rename = "node", default)]
    pub nodes: Vec<GainNodeData>,
}

/// A node's design record, besides its gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GainNodeRecord {
    /// Engine speed (rad/s).
    pub speed_rad_s: f64,
    /// Intake manifold pressure (Pa).
    pub pressure_pa: f64,
    /// Whether the actuator path reaches the node (see [`GainNodeData::reachable`]).
    pub reachable: bool,
    /// Throttle of the operating point (%).
    pub throttle_pct: f64,
    /// Wastegate of the operating point (0 closed .. 1 open).
    pub wastegate_frac: f64,
    /// Closed-loop spectral radius at the operating point (-).
    pub closed_loop_radius: f64,
}

/// A checked gain file: the table and what it was designed for.
#[derive(Debug, Clone, PartialEq)]
pub struct GainFile<const M: usize> {
    /// The sensors, in the order of the gains' columns.
    pub sensors: [Sensor; M],
    /// The sample time the gains are for (s).
    pub sample_time_s: f64,
    /// The design's measurement noise variances (sensor units squared).
    pub measurement_variance: [f64; M],
    /// Ambient pressure of the design (Pa).
    pub ambient_pressure_pa: f64,
    /// Ambient temperature of the design (K).
    pub ambient_temperature_k: f64,
    /// Lambda of the design (-).
    pub lambda: f64,
    /// The gains.
    pub table: GainTable<M>,
    /// Per node, speed-major, in the table's order.
    pub nodes: Vec<GainNodeRecord>,
}

/// Builds errors for one file.
struct Ctx<'a> {
    file: &'a str,
}

impl Ctx<'_> {
    fn err(
        &self,
        table: impl Into<String>,
        key: impl Into<String>,
        problem: String,
    ) -> GainFileError {
        GainFileError {
            file: self.file.to_string(),
            table: table.into(),
            key: key.into(),
            problem,
        }
    }

    fn finite(&self, table: &str, key: &str, v: f64) -> Result<f64, GainFileError> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(table, key, format!("{v} is not a finite number")))
        }
    }

    fn positive(&self, table: &str, key: &str, v: f64) -> Result<f64, GainFileError> {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(self.err(table, key, format!("{v} must be a finite number above 0")))
        }
    }

    fn axis(&self, key: &str, v: &[f64]) -> Result<(), GainFileError> {
        if v.is_empty() {
            return Err(self.err("gains", key, "no nodes".into()));
        }
        for (i, x) in v.iter().enumerate() {
            self.finite("gains", &format!("{key}[{i}]"), *x)?;
        }
        if let Some(i) = v.windows(2).position(|w| w[0] >= w[1]) {
            return Err(self.err(
                "gains",
                format!("{key}[{}]", i + 1),
                format!(
                    "{} does not exceed the node before it ({}): the axis must increase strictly",
                    v[i + 1],
                    v[i]
                ),
            ));
        }
        Ok(())
    }
}

/// Two grid coordinates are the same node if within this relative distance (the file's
/// numbers are written in round-trip form, so they match exactly; the tolerance admits a
/// hand-edited file with fewer digits).
const NODE_REL_TOL: f64 = 1e-9;

fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= NODE_REL_TOL * a.abs().max(b.abs())
}

impl<const M: usize> GainFile<M> {
    /// Checks `data` (the content of the file named `file`, for the messages) and builds the
    /// table: `M` known, distinct sensors; a positive sample time and variances; strictly
    /// increasing axes; one node per grid point, speed-major, each at its grid point, with 14
    /// rows of `M` finite gains and a finite operating point.
    pub fn from_data(file: &str, data: &GainFileData) -> Result<Self, GainFileError> {
        let c = Ctx { file };
        let g = &data.gains;
        if g.sensors.len() != M {
            return Err(c.err(
                "gains",
                "sensors",
                format!(
                    "{} sensors ({}) where the observer reads {M}",
                    g.sensors.len(),
                    g.sensors.join(", ")
                ),
            ));
        }
        let mut sensors = [Sensor::PIm; M];
        for (i, name) in g.sensors.iter().enumerate() {
            let s = Sensor::from_name(name).ok_or_else(|| {
                c.err(
                    "gains",
                    format!("sensors[{i}]"),
                    format!(
                        "unknown sensor `{name}` (known: {})",
                        Sensor::ALL.map(Sensor::name).join(", ")
                    ),
                )
            })?;
            if sensors[..i].contains(&s) {
                return Err(c.err(
                    "gains",
                    format!("sensors[{i}]"),
                    format!("sensor `{name}` appears twice"),
                ));
            }
            sensors[i] = s;
        }
        let sample_time_s = c.positive("gains", "sample_time_s", g.sample_time_s)?;
        if g.measurement_variance.len() != M {
            return Err(c.err(
                "gains",
                "measurement_variance",
                format!("{} values for {M} sensors", g.measurement_variance.len()),
            ));
        }
        let mut measurement_variance = [0.0; M];
        for (i, v) in g.measurement_variance.iter().enumerate() {
            measurement_variance[i] =
                c.positive("gains", &format!("measurement_variance[{i}]"), *v)?;
        }
        let ambient_pressure_pa =
            c.positive("gains", "ambient_pressure_pa", g.ambient_pressure_pa)?;
        let ambient_temperature_k =
            c.positive("gains", "ambient_temperature_k", g.ambient_temperature_k)?;
        let lambda = c.positive("gains", "lambda", g.lambda)?;
        c.axis("speeds_rad_s", &g.speeds_rad_s)?;
        c.axis("pressures_pa", &g.pressures_pa)?;
        let (ns, np) = (g.speeds_rad_s.len(), g.pressures_pa.len());
        if data.nodes.len() != ns * np {
            return Err(c.err(
                "node",
                "(the [[node]] tables)",
                format!(
                    "{} nodes where the grid has {ns} speeds x {np} pressures = {}",
                    data.nodes.len(),
                    ns * np
                ),
            ));
        }
        let mut gains = Vec::with_capacity(data.nodes.len());
        let mut nodes = Vec::with_capacity(data.nodes.len());
        for (n, node) in data.nodes.iter().enumerate() {
            let table = format!("node {n}");
            let (ws, wp) = (g.speeds_rad_s[n / np], g.pressures_pa[n % np]);
            if !same(node.speed_rad_s, ws) {
                return Err(c.err(
                    table,
                    "speed_rad_s",
                    format!(
                        "{} where the grid's node {n} (speed-major) is at {ws} rad/s",
                        node.speed_rad_s
                    ),
                ));
            }
            if !same(node.pressure_pa, wp) {
                return Err(c.err(
                    table,
                    "pressure_pa",
                    format!(
                        "{} where the grid's node {n} (speed-major) is at {wp} Pa",
                        node.pressure_pa
                    ),
                ));
            }
            let throttle_pct = c.finite(&table, "throttle_pct", node.throttle_pct)?;
            let wastegate_frac = c.finite(&table, "wastegate_frac", node.wastegate_frac)?;
            let closed_loop_radius =
                c.finite(&table, "closed_loop_radius", node.closed_loop_radius)?;
            if node.k.len() != N_STATES_AUGMENTED {
                return Err(c.err(
                    table,
                    "k",
                    format!(
                        "{} rows where the observer has {N_STATES_AUGMENTED} states",
                        node.k.len()
                    ),
                ));
            }
            let mut k = SMatrix::<f64, N_STATES_AUGMENTED, M>::zeros();
            for (r, row) in node.k.iter().enumerate() {
                if row.len() != M {
                    return Err(c.err(
                        table,
                        format!("k[{r}]"),
                        format!(
                            "{} values where the file has {M} sensors (row of {})",
                            row.len(),
                            STATE_NAMES[r]
                        ),
                    ));
                }
                for (j, v) in row.iter().enumerate() {
                    k[(r, j)] = c.finite(&table, &format!("k[{r}][{j}]"), *v)?;
                }
            }
            gains.push(k);
            nodes.push(GainNodeRecord {
                speed_rad_s: ws,
                pressure_pa: wp,
                reachable: node.reachable,
                throttle_pct,
                wastegate_frac,
                closed_loop_radius,
            });
        }
        let table = GainTable::new(g.speeds_rad_s.clone(), g.pressures_pa.clone(), gains)
            .map_err(|e| c.err("gains", "(the table)", e.to_string()))?;
        Ok(Self {
            sensors,
            sample_time_s,
            measurement_variance,
            ambient_pressure_pa,
            ambient_temperature_k,
            lambda,
            table,
            nodes,
        })
    }

    /// Refuses a file whose sensors are not `want` in that order, or whose sample time is not
    /// `dt_s` (relative 1e-9): gains designed for other sensors or another rate would be
    /// applied to the wrong innovations.
    pub fn expect(&self, file: &str, want: &[Sensor; M], dt_s: f64) -> Result<(), GainFileError> {
        let c = Ctx { file };
        if let Some(i) = (0..M).find(|&i| self.sensors[i] != want[i]) {
            return Err(c.err(
                "gains",
                format!("sensors[{i}]"),
                format!(
                    "`{}` where the observer reads `{}` (its sensors: {})",
                    self.sensors[i].name(),
                    want[i].name(),
                    want.map(Sensor::name).join(", ")
                ),
            ));
        }
        if !same(self.sample_time_s, dt_s) {
            return Err(c.err(
                "gains",
                "sample_time_s",
                format!(
                    "{} s where the observer samples every {dt_s} s",
                    self.sample_time_s
                ),
            ));
        }
        Ok(())
    }

    /// The data part of the file (the `[gains]` and `[[node]]` tables), deterministic, each
    /// number in Rust's shortest round-trip form, each gain row commented with its state.
    pub fn render(&self) -> String {
        let list = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:?}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut s = String::new();
        let _ = writeln!(s, "[gains]");
        let _ = writeln!(s, "sample_time_s = {:?}", self.sample_time_s);
        let _ = writeln!(
            s,
            "sensors = [{}]",
            self.sensors.map(|x| format!("\"{}\"", x.name())).join(", ")
        );
        let _ = writeln!(
            s,
            "measurement_variance = [{}]",
            list(&self.measurement_variance)
        );
        let _ = writeln!(s, "ambient_pressure_pa = {:?}", self.ambient_pressure_pa);
        let _ = writeln!(
            s,
            "ambient_temperature_k = {:?}",
            self.ambient_temperature_k
        );
        let _ = writeln!(s, "lambda = {:?}", self.lambda);
        let _ = writeln!(s, "speeds_rad_s = [{}]", list(self.table.speeds_rad_s()));
        let _ = writeln!(s, "pressures_pa = [{}]", list(self.table.pressures_pa()));
        for (node, k) in self.nodes.iter().zip(self.table.gains()) {
            let _ = writeln!(s, "\n[[node]]");
            let _ = writeln!(s, "speed_rad_s = {:?}", node.speed_rad_s);
            let _ = writeln!(s, "pressure_pa = {:?}", node.pressure_pa);
            let _ = writeln!(s, "reachable = {}", node.reachable);
            let _ = writeln!(s, "throttle_pct = {:?}", node.throttle_pct);
            let _ = writeln!(s, "wastegate_frac = {:?}", node.wastegate_frac);
            let _ = writeln!(s, "closed_loop_radius = {:?}", node.closed_loop_radius);
            let _ = writeln!(s, "k = [");
            for r in 0..N_STATES_AUGMENTED {
                let row: Vec<f64> = (0..M).map(|j| k[(r, j)]).collect();
                let _ = writeln!(s, "  [{}], # {}", list(&row), STATE_NAMES[r]);
            }
            let _ = writeln!(s, "]");
        }
        s
    }

    /// The serde structure of this file (what [`Self::render`] writes).
    pub fn to_data(&self) -> GainFileData {
        GainFileData {
            gains: GainHeaderData {
                sample_time_s: self.sample_time_s,
                sensors: self.sensors.iter().map(|s| s.name().to_string()).collect(),
                measurement_variance: self.measurement_variance.to_vec(),
                ambient_pressure_pa: self.ambient_pressure_pa,
                ambient_temperature_k: self.ambient_temperature_k,
                lambda: self.lambda,
                speeds_rad_s: self.table.speeds_rad_s().to_vec(),
                pressures_pa: self.table.pressures_pa().to_vec(),
            },
            nodes: self
                .nodes
                .iter()
                .zip(self.table.gains())
                .map(|(n, k)| GainNodeData {
                    speed_rad_s: n.speed_rad_s,
                    pressure_pa: n.pressure_pa,
                    reachable: n.reachable,
                    throttle_pct: n.throttle_pct,
                    wastegate_frac: n.wastegate_frac,
                    closed_loop_radius: n.closed_loop_radius,
                    k: (0..N_STATES_AUGMENTED)
                        .map(|r| (0..M).map(|j| k[(r, j)]).collect())
                        .collect(),
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file() -> GainFile<2> {
        let speeds = vec![100.0, 200.0];
        let pressures = vec![30e3, 60e3, 90e3];
        let gains: Vec<SMatrix<f64, N_STATES_AUGMENTED, 2>> = (0..6)
            .map(|n| SMatrix::from_fn(|r, j| (n * 100 + r * 2 + j) as f64 * 1.0e-7 - 3.3e-9))
            .collect();
        let nodes = (0..6)
            .map(|n| GainNodeRecord {
                speed_rad_s: speeds[n / 3],
                pressure_pa: pressures[n % 3],
                reachable: n != 5,
                throttle_pct: 10.0 + n as f64 / 3.0,
                wastegate_frac: 0.62,
                closed_loop_radius: 0.9 + n as f64 * 0.01,
            })
            .collect();
        GainFile {
            sensors: [Sensor::PIm, Sensor::Maf],
            sample_time_s: 0.05,
            measurement_variance: [240133.85575595152, 5.78375043664363e-10],
            ambient_pressure_pa: 101_300.0,
            ambient_temperature_k: 301.1,
            lambda: 1.0,
            table: GainTable::new(speeds, pressures, gains).expect("valid"),
            nodes,
        }
    }

    fn parse(text: &str) -> Result<GainFile<2>, GainFileError> {
        let data: GainFileData = toml::from_str(text).expect("TOML");
        GainFile::from_data("t.toml", &data)
    }

    #[test]
    fn render_parses_back_to_the_same_file() {
        let f = file();
        let text = f.render();
        assert_eq!(parse(&text).expect("parses"), f);
        assert_eq!(
            GainFile::<2>::from_data("t.toml", &f.to_data()).expect("ok"),
            f
        );
        f.expect("t.toml", &[Sensor::PIm, Sensor::Maf], 0.05)
            .expect("matches");
        let e = f
            .expect("t.toml", &[Sensor::Maf, Sensor::PIm], 0.05)
            .expect_err("order");
        assert_eq!(e.key, "sensors[0]");
        let e = f
            .expect("t.toml", &[Sensor::PIm, Sensor::Maf], 0.0125)
            .expect_err("rate");
        assert_eq!(e.key, "sample_time_s");
    }

    #[test]
    fn bad_files_name_the_file_table_and_key() {
        let f = file();
        let mut d = f.to_data();
        d.gains.sensors[1] = "mass_flow".into();
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("unknown sensor");
        assert_eq!((e.table.as_str(), e.key.as_str()), ("gains", "sensors[1]"));
        assert!(
            e.to_string()
                .starts_with("t.toml: [gains] sensors[1]: unknown sensor `mass_flow`"),
            "{e}"
        );

        let mut d = f.to_data();
        d.nodes[4].k[7].pop();
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("short row");
        assert_eq!((e.table.as_str(), e.key.as_str()), ("node 4", "k[7]"));

        let mut d = f.to_data();
        d.nodes[2].k.pop();
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("13 rows");
        assert_eq!((e.table.as_str(), e.key.as_str()), ("node 2", "k"));

        let mut d = f.to_data();
        d.nodes.pop();
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("5 nodes");
        assert_eq!(e.table, "node");

        let mut d = f.to_data();
        d.nodes.swap(0, 1);
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("order");
        assert_eq!(
            (e.table.as_str(), e.key.as_str()),
            ("node 0", "pressure_pa")
        );

        let mut d = f.to_data();
        d.gains.pressures_pa[2] = 60e3;
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("axis");
        assert_eq!(e.key, "pressures_pa[2]");

        let mut d = f.to_data();
        d.gains.sensors[1] = "p_im".into();
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("twice");
        assert_eq!(e.key, "sensors[1]");

        let d = f.to_data();
        let e = GainFile::<3>::from_data("t.toml", &d).expect_err("M");
        assert_eq!(e.key, "sensors");

        let mut d = f.to_data();
        d.gains.measurement_variance[0] = 0.0;
        let e = GainFile::<2>::from_data("t.toml", &d).expect_err("R");
        assert_eq!(e.key, "measurement_variance[0]");

        // An unknown key is refused by the serde structure itself.
        let text = f
            .render()
            .replacen("lambda = 1.0", "lambda = 1.0\nlamda = 1.0", 1);
        let e = toml::from_str::<GainFileData>(&text).expect_err("unknown key");
        assert!(e.to_string().contains("lamda"), "{e}");
    }
}
