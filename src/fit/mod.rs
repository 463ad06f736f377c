//! `fdd fit turbo` (and `fdd fit turbo-ice`, in [`ice`]): calibrates the turbocharged air-path model to the stationary TSFS09 engine
//! map and its compressor and turbine maps, checks the whole model at every map point and
//! writes a complete, commented parameter file.
//!
//! The math is in `fdd_estimators::models::turbo::fit`; this module reads the CSV files (every
//! error names the file, the line and the column), loads the start parameter file, and renders
//! the output file and the error table. The output is deterministic: the same inputs give the
//! same bytes (the fits and the check run in a fixed order on one thread, and every number is
//! written in Rust's shortest round-trip form or a fixed number of decimals).

pub mod gains;
pub mod ice;
pub mod render;

use std::path::{Path, PathBuf};

use fdd_estimators::models::turbo::fit::{
    check_engine_map, fit_turbo, CheckReport, CompressorMapPoint, EnginePoint, FitData, FitError,
    FitOptions, FitOutcome, TurbineMapPoint,
};
use fdd_estimators::models::turbo::TurboParams;
use thiserror::Error;

/// The engine map's file name in the data directory.
pub const ENGINE_MAP_FILE: &str = "engine_map.csv";
/// The compressor map's file name.
pub const COMPRESSOR_MAP_FILE: &str = "comp_map.csv";
/// The turbine map's file name.
pub const TURBINE_MAP_FILE: &str = "turb_map.csv";

/// The engine map's columns the fit reads, in [`EnginePoint`] order (the units are decided in
/// `config/import/tsfs09_engine_map.toml`: Pa, K, rev/s, a fraction, kg/s).
pub const ENGINE_COLUMNS: [&str; 14] = [
    "p_af",
    "p_bef_thr",
    "p_im",
    "p_em",
    "p_t",
    "T_af",
    "T_bef_thr",
    "T_im",
    "T_em",
    "T_t",
    "N",
    "alpha",
    "m_dot_at",
    "lambda_bc_cont",
];
/// The compressor map's columns.
pub const COMPRESSOR_COLUMNS: [&str; 4] = ["WcCorr", "PiC", "NcCorr", "etaC"];
/// The turbine map's columns.
pub const TURBINE_COLUMNS: [&str; 4] = ["TFP", "PiT", "TSP", "etaT"];

/// What can go wrong around the fit.
#[derive(Debug, Error)]
pub enum FitIoError {
    /// A file cannot be read.
    #[error("cannot read {}: {source}", file.display())]
    Read {
        /// The file.
        file: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The CSV parser refused a line (e.g. a row with another number of fields than the
    /// header).
    #[error("{}: line {line}: {message}", file.display())]
    Csv {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// The parser's message.
        message: String,
    },
    /// The header lacks a column the fit needs.
    #[error("{}: line 1 (the header) has no column `{column}` (its columns: {columns})", file.display())]
    MissingColumn {
        /// The file.
        file: PathBuf,
        /// The missing column.
        column: String,
        /// The header's columns.
        columns: String,
    },
    /// A cell is not a finite number.
    #[error("{}: line {line}, column {column} (`{name}`): {cell:?} is not a finite number", file.display())]
    Cell {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column.
        column: usize,
        /// The column's name.
        name: String,
        /// The cell's text.
        cell: String,
    },
    /// A file has no data rows.
    #[error("{}: no data rows after the header", file.display())]
    Empty {
        /// The file.
        file: PathBuf,
    },
    /// The start parameter file cannot be parsed or does not validate.
    #[error("{}: {message}", file.display())]
    Start {
        /// The file.
        file: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The output would overwrite an input.
    #[error("{}: refusing to write the parameter file over an input", file.display())]
    OutputIsInput {
        /// The output.
        file: PathBuf,
    },
    /// A log cannot be read.
    #[error("{source}")]
    Log {
        /// The log.
        file: PathBuf,
        /// The reader's error (it names the file).
        #[source]
        source: Box<fdd_monitor::log::LogError>,
    },
    /// A log lacks a topic the fit needs.
    #[error("{}: no message on topic `{topic}` (field `{field}`), which the fit needs", file.display())]
    MissingTopic {
        /// The log.
        file: PathBuf,
        /// The topic.
        topic: &'static str,
        /// Its field.
        field: &'static str,
    },
    /// A log has too few rows with every signal.
    #[error("{}: {rows} rows with every signal, at least {need} needed", file.display())]
    TooFewRows {
        /// The log.
        file: PathBuf,
        /// Complete rows.
        rows: usize,
        /// Needed.
        need: usize,
    },
    /// The log that anchors the shaft's loss torque cannot be used.
    #[error("the log the shaft's loss torque is fitted to: {message}")]
    Anchor {
        /// The log.
        file: PathBuf,
        /// What is wrong (the reader's and the reproduction's errors name the log).
        message: String,
    },
    /// A fit or the check failed.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// The output cannot be written.
    #[error("cannot write {}: {source}", file.display())]
    Write {
        /// The file.
        file: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
}

/// Reads the named columns of a CSV file (header line, then rows) as finite numbers, one
/// vector per row in `columns` order.
pub fn read_columns(path: &Path, columns: &[&str]) -> Result<Vec<Vec<f64>>, FitIoError> {
    let file = || path.to_path_buf();
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_path(path)
        .map_err(|e| csv_error(path, e))?;
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| csv_error(path, e))?
        .iter()
        .map(|h| h.trim().to_string())
        .collect();
    let index: Vec<usize> = columns
        .iter()
        .map(|c| {
            header
                .iter()
                .position(|h| h == c)
                .ok_or_else(|| FitIoError::MissingColumn {
                    file: file(),
                    column: (*c).to_string(),
                    columns: header.join(", "),
                })
        })
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| csv_error(path, e))?;
        let line = record.position().map_or(0, |p| p.line());
        let row = index
            .iter()
            .map(|&j| {
                let cell = record.get(j).unwrap_or("").trim();
                cell.parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| FitIoError::Cell {
                        file: file(),
                        line,
                        column: j + 1,
                        name: header[j].clone(),
                        cell: cell.to_string(),
                    })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(FitIoError::Empty { file: file() });
    }
    Ok(rows)
}

fn csv_error(path: &Path, e: csv::Error) -> FitIoError {
    let line = e.position().map_or(0, |p| p.line());
    match e.into_kind() {
        csv::ErrorKind::Io(source) => FitIoError::Read {
            file: path.to_path_buf(),
            source,
        },
        kind => FitIoError::Csv {
            file: path.to_path_buf(),
            line,
            message: match kind {
                csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => format!("{len} fields where the header has {expected_len}"),
                csv::ErrorKind::Utf8 { err, .. } => format!("not UTF-8: {err}"),
                other => format!("{other:?}"),
            },
        },
    }
}

/// Reads the three files of a TSFS09 data directory.
pub fn read_data(dir: &Path) -> Result<FitData, FitIoError> {
    let engine = read_columns(&dir.join(ENGINE_MAP_FILE), &ENGINE_COLUMNS)?
        .into_iter()
        .map(|r| EnginePoint {
            p_af_pa: r[0],
            p_ic_pa: r[1],
            p_im_pa: r[2],
            p_em_pa: r[3],
            p_t_pa: r[4],
            t_af_k: r[5],
            t_ic_k: r[6],
            t_im_k: r[7],
            t_em_k: r[8],
            t_t_k: r[9],
            engine_speed_rev_s: r[10],
            throttle_frac: r[11],
            air_flow_kg_s: r[12],
            lambda: r[13],
        })
        .collect();
    let compressor_map = read_columns(&dir.join(COMPRESSOR_MAP_FILE), &COMPRESSOR_COLUMNS)?
        .into_iter()
        .map(|r| CompressorMapPoint {
            corrected_flow_kg_s: r[0],
            pressure_ratio: r[1],
            corrected_speed_rpm: r[2],
            efficiency: r[3],
        })
        .collect();
    let turbine_map = read_columns(&dir.join(TURBINE_MAP_FILE), &TURBINE_COLUMNS)?
        .into_iter()
        .map(|r| TurbineMapPoint {
            flow_parameter: r[0],
            pressure_ratio: r[1],
            speed_parameter: r[2],
            efficiency: r[3],
        })
        .collect();
    Ok(FitData {
        engine,
        compressor_map,
        turbine_map,
        shaft_anchor: None,
    })
}

/// Loads a parameter file's `[model]` table and validates it.
pub fn load_params(path: &Path) -> Result<TurboParams, FitIoError> {
    #[derive(serde::Deserialize)]
    struct File {
        model: TurboParams,
    }
    let text = std::fs::read_to_string(path).map_err(|source| FitIoError::Read {
        file: path.to_path_buf(),
        source,
    })?;
    let f: File = toml::from_str(&text).map_err(|e| FitIoError::Start {
        file: path.to_path_buf(),
        message: e.to_string(),
    })?;
    f.model.validate().map_err(|e| FitIoError::Start {
        file: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(f.model)
}

/// The command's arguments.
#[derive(Debug, Clone)]
pub struct FitTurboArgs {
    /// The data directory.
    pub data: PathBuf,
    /// The start parameter file.
    pub start: PathBuf,
    /// The output parameter file.
    pub out: PathBuf,
}

/// What the command computed.
#[derive(Debug, Clone)]
pub struct FitRun {
    /// The fit.
    pub outcome: FitOutcome,
    /// The whole-model check.
    pub check: CheckReport,
    /// The options used.
    pub options: FitOptions,
    /// The parameter file's text as written.
    pub file_text: String,
}

/// Runs the fit and the check, and writes the parameter file (to a temporary file beside it,
/// renamed when complete).
pub fn run(args: &FitTurboArgs) -> Result<FitRun, FitIoError> {
    let inputs = [
        args.start.clone(),
        args.data.join(ENGINE_MAP_FILE),
        args.data.join(COMPRESSOR_MAP_FILE),
        args.data.join(TURBINE_MAP_FILE),
        args.data.join(crate::reproduce::turbo::TUNING_LOG),
    ];
    if let Ok(out) = args.out.canonicalize() {
        if inputs
            .iter()
            .any(|i| i.canonicalize().is_ok_and(|i| i == out))
        {
            return Err(FitIoError::OutputIsInput {
                file: args.out.clone(),
            });
        }
    }
    let mut data = read_data(&args.data)?;
    data.shaft_anchor = Some(
        crate::reproduce::turbo::shaft_anchor(&args.data, &data.engine).map_err(|e| {
            FitIoError::Anchor {
                file: args.data.join(crate::reproduce::turbo::TUNING_LOG),
                message: e.to_string(),
            }
        })?,
    );
    let start = load_params(&args.start)?;
    let options = FitOptions::tsfs09();
    let outcome = fit_turbo(&start, &data, &options)?;
    let p_amb = outcome.report.air_filter.ambient_pressure_pa.value;
    let check = check_engine_map(&outcome.params, &data.engine, p_amb, &options)?;
    let file_text = render::parameter_file(&outcome, &check, &options);
    write_atomic(&args.out, &file_text)?;
    Ok(FitRun {
        outcome,
        check,
        options,
        file_text,
    })
}

pub(crate) fn write_atomic(path: &Path, text: &str) -> Result<(), FitIoError> {
    use std::io::Write as _;
    let err = |source| FitIoError::Write {
        file: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(err)?;
    tmp.write_all(text.as_bytes()).map_err(err)?;
    tmp.flush().map_err(err)?;
    tmp.persist(path).map_err(|e| err(e.error))?;
    Ok(())
}
