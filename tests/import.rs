//! `fdd import`: the real-engine fixtures converted from CSV (`fixtures/data/real/`) are what
//! the committed CSVs and mappings (`config/import/`) give, byte for byte; the values written
//! are the CSV's times the scale plus the offset; the truth marks the fault from its onset;
//! bad CSVs, mappings and arguments are refused with errors naming the file, the line and the
//! column (or the key), never with a panic or a partial output.
//!
//! `FDD_BLESS=1 cargo test --release --test import` rewrites the converted fixtures.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use fdd_monitor::log::LogReader;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn fdd() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_fdd"));
    c.env_remove("RUST_LOG").env_remove("RUST_BACKTRACE");
    c
}

const LIU_ICE: &str = "fixtures/data/real/liu-ice";
const TSFS09: &str = "fixtures/data/real/liu-tsfs09";

/// CSVs committed for reference but not converted: compressor and turbine characteristics
/// (maps over corrected flow and speed), not logs of signals over time.
const NOT_CONVERTED: [&str; 2] = ["comp_map.csv", "turb_map.csv"];

/// How one committed CSV is converted.
#[derive(Debug, Clone)]
struct Recipe {
    csv: PathBuf,
    mapping: &'static str,
    fault: Option<(String, f64)>,
}

impl Recipe {
    fn mcap(&self) -> PathBuf {
        self.csv.with_extension("mcap")
    }

    fn args(&self, out: &Path) -> Vec<String> {
        let mut a = vec![
            "import".to_string(),
            self.csv.display().to_string(),
            "--mapping".to_string(),
            root().join(self.mapping).display().to_string(),
            "-o".to_string(),
            out.display().to_string(),
            "--no-progress".to_string(),
        ];
        if let Some((name, onset)) = &self.fault {
            a.extend([
                "--fault".to_string(),
                name.clone(),
                "--fault-onset-s".to_string(),
                format!("{onset}"),
            ]);
        }
        a
    }
}

/// Fault onsets of the LiU-ICE runs (`ftp75city2_fault_time.txt`: run name, tab, onset in s).
fn fault_times() -> BTreeMap<String, f64> {
    let text = std::fs::read_to_string(root().join(LIU_ICE).join("ftp75city2_fault_time.txt"))
        .expect("fault-time file");
    text.lines()
        .skip(1)
        .filter_map(|l| {
            let mut parts = l.split_whitespace();
            let name = parts.next()?;
            let t = parts.last()?.parse().ok()?;
            Some((name.to_string(), t))
        })
        .collect()
}

fn csvs(dir: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
        .expect("data dir")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    v.sort();
    v
}

/// Every committed CSV that is converted, with its mapping and fault. A LiU-ICE fault run
/// `ftp75city2_f_<sensor>_<gain x 100>_window.csv` gets the fault `<sensor>_gain_<gain>` (the
/// sensor reads gain x the true value: `pim_gain_1.15`) from its onset in the fault-time file.
fn recipes() -> Vec<Recipe> {
    let onsets = fault_times();
    let mut out = Vec::new();
    for csv in csvs(LIU_ICE) {
        let stem = csv.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        let fault = stem.split_once("_f_").map(|(_, rest)| {
            let mut parts = rest.split('_');
            let sensor = parts.next().expect("sensor");
            let code: u32 = parts.next().expect("gain").parse().expect("gain x 100");
            let run = stem.trim_end_matches("_window");
            let onset = *onsets
                .get(run)
                .unwrap_or_else(|| panic!("{run}: not in the fault-time file"));
            (
                format!("{sensor}_gain_{}.{:02}", code / 100, code % 100),
                onset,
            )
        });
        out.push(Recipe {
            csv,
            mapping: "config/import/liu_ice.toml",
            fault,
        });
    }
    for csv in csvs(TSFS09) {
        let name = csv.file_name().and_then(|s| s.to_str()).unwrap_or_default();
        let mapping = if name.starts_with("grupp") {
            "config/import/tsfs09_transient.toml"
        } else if name == "engine_map.csv" {
            "config/import/tsfs09_engine_map.toml"
        } else {
            assert!(
                NOT_CONVERTED.contains(&name),
                "{}: no recipe for this CSV",
                csv.display()
            );
            continue;
        };
        out.push(Recipe {
            csv,
            mapping,
            fault: None,
        });
    }
    out
}

fn run(args: &[String]) -> Output {
    fdd().args(args).output().expect("run fdd")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn converted_fixtures_are_reproduced_byte_for_byte() {
    let bless = std::env::var_os("FDD_BLESS").is_some_and(|v| v == "1");
    let dir = tempfile::tempdir().expect("tempdir");
    let recipes = recipes();
    assert_eq!(
        recipes.len(),
        14,
        "9 LiU-ICE and 5 TSFS09 files: {recipes:#?}"
    );
    assert_eq!(recipes.iter().filter(|r| r.fault.is_some()).count(), 6);
    let mut stale = Vec::new();
    for r in &recipes {
        let out = if bless {
            r.mcap()
        } else {
            dir.path().join("fresh.mcap")
        };
        let o = run(&r.args(&out));
        assert!(o.status.success(), "{:?}: {}", r.args(&out), stderr(&o));
        if !bless {
            let fresh = std::fs::read(&out).expect("written");
            match std::fs::read(r.mcap()) {
                Ok(committed) if committed == fresh => {}
                Ok(committed) => stale.push(format!(
                    "{}: differs from what its CSV gives ({} bytes committed, {} fresh)",
                    r.mcap().display(),
                    committed.len(),
                    fresh.len()
                )),
                Err(e) => stale.push(format!("{}: {e}", r.mcap().display())),
            }
        }
    }
    assert!(
        stale.is_empty(),
        "{}\n(regenerate with FDD_BLESS=1 cargo test --release --test import)",
        stale.join("\n")
    );
    // No converted file without its CSV.
    for dir in [LIU_ICE, TSFS09] {
        for e in std::fs::read_dir(root().join(dir)).expect("dir") {
            let p = e.expect("entry").path();
            if p.extension().is_some_and(|e| e == "mcap") {
                assert!(
                    recipes.iter().any(|r| r.mcap() == p),
                    "{} has no CSV and recipe",
                    p.display()
                );
            }
        }
    }
}

/// The number `field` of the flat JSON object `json`, parsed by Rust's correctly rounded
/// `f64` parser (serde_json without its `float_roundtrip` feature may be 1 ulp off).
fn exact(json: &serde_json::Value, field: &str) -> f64 {
    let text = json.get("_raw").and_then(|r| r.as_str()).expect("raw text");
    let key = format!("\"{field}\":");
    let start = text.find(&key).expect("field") + key.len();
    let rest = &text[start..];
    let end = rest.find([',', '}']).expect("end of number");
    rest[..end].parse().expect("number")
}

/// Every message of `log` on `topic`: (log time ns, JSON, with its text under `_raw`).
fn messages(log: &Path, topic: &str) -> Vec<(u64, serde_json::Value)> {
    let mut reader = LogReader::open(log).expect("open");
    let mut out = Vec::new();
    while let Some(m) = reader.next_message() {
        let m = m.expect("message");
        if m.topic == topic {
            let mut v = m.json().expect("JSON");
            let raw = String::from_utf8(m.data.to_vec()).expect("UTF-8");
            v["_raw"] = serde_json::Value::String(raw);
            out.push((m.log_time_ns, v));
        }
    }
    out
}

/// The CSV's column `name`, as f64, and its first column's text.
fn column(csv: &Path, name: &str) -> Vec<f64> {
    let text = std::fs::read_to_string(csv).expect("csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let i = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("{name}"));
    lines
        .map(|l| l.split(',').nth(i).expect("field").parse().expect("number"))
        .collect()
}

#[test]
fn imported_values_are_the_csv_times_scale_plus_offset() {
    let csv = root().join(TSFS09).join("grupp2_wastegate.csv");
    let log = csv.with_extension("mcap");
    let t = column(&csv, "t");
    // (topic, field, column, scale, offset) as config/import/tsfs09_transient.toml says.
    let cases = [
        ("/turbo/p_im", "pressure_pa", "p_im", 1000.0, 0.0),
        (
            "/turbo/turbo_speed",
            "speed_rad_s",
            "w_tc_LP",
            0.10471975511965977,
            0.0,
        ),
        ("/turbo/maf", "flow_kg_s", "m_dot_air", 0.001, 0.0),
        ("/turbo/wastegate", "position", "wg_pos_LP", 0.01, 0.0),
        ("/turbo/lambda", "lambda", "lambda_bc_cont", 1.0, 0.0),
    ];
    for (topic, field, col, scale, offset) in cases {
        let want = column(&csv, col);
        let got = messages(&log, topic);
        assert_eq!(got.len(), want.len(), "{topic}");
        for (i, ((ns, msg), raw)) in got.iter().zip(&want).enumerate() {
            let v = exact(msg, field);
            assert_eq!(v, raw * scale + offset, "{topic} row {i}: {raw} x {scale}");
            assert_eq!(*ns, (t[i] * 1e9).round() as u64, "{topic} row {i} time");
        }
    }

    // An offset (degC to K), a time in ms from the first row shifted by offset_s, and a
    // column feeding two topics.
    let dir = tempfile::tempdir().expect("tempdir");
    let csv = dir.path().join("c.csv");
    std::fs::write(
        &csv,
        "stamp_ms,temp_c,p_kpa\n1000,25,101.3\n1012.5, -40.5 ,99\n1025,0,100\n",
    )
    .expect("write");
    let mapping = dir.path().join("m.toml");
    std::fs::write(
        &mapping,
        r#"
[time]
column = "stamp_ms"
unit = "ms"
origin = "first_row"
offset_s = 2.0
[[topics]]
topic = "/x/temp"
fields = [{ name = "temperature_k", column = "temp_c", unit = "K", offset = 273.15 }]
[[topics]]
topic = "/x/both"
fields = [
  { name = "temperature_k", column = "temp_c", unit = "K", offset = 273.15 },
  { name = "pressure_pa", column = "p_kpa", unit = "Pa", scale = 1000 },
]
"#,
    )
    .expect("write");
    let log = dir.path().join("c.mcap");
    let o = fdd()
        .args(["import", "--no-progress"])
        .arg(&csv)
        .arg("--mapping")
        .arg(&mapping)
        .arg("-o")
        .arg(&log)
        .output()
        .expect("run");
    assert!(o.status.success(), "{}", stderr(&o));
    let temp = messages(&log, "/x/temp");
    let times: Vec<u64> = temp.iter().map(|(t, _)| *t).collect();
    assert_eq!(times, [2_000_000_000, 2_012_500_000, 2_025_000_000]);
    let k: Vec<f64> = temp
        .iter()
        .map(|(_, m)| exact(m, "temperature_k"))
        .collect();
    assert_eq!(k, [25.0 + 273.15, -40.5 + 273.15, 273.15]);
    let both = messages(&log, "/x/both");
    assert_eq!(exact(&both[0].1, "pressure_pa"), 101.3 * 1000.0);
    assert_eq!(exact(&both[1].1, "temperature_k"), -40.5 + 273.15);
    assert!(
        messages(&log, "/truth/turbo").is_empty(),
        "no [truth], no truth"
    );
}

#[test]
fn truth_marks_the_fault_from_its_onset_and_none_without_one() {
    let dir = root().join(LIU_ICE);
    let faulty = messages(
        &dir.join("ftp75city2_f_pim_115_window.mcap"),
        "/truth/turbo",
    );
    assert_eq!(faulty.len(), 800);
    let onset_ns = 122_750_000_000;
    for (t, m) in &faulty {
        let active = *t >= onset_ns;
        assert_eq!(m["fault_active"], active, "at {t} ns");
        assert_eq!(m["fault_observable"], active, "at {t} ns");
        assert_eq!(
            m["fault"],
            if active { "pim_gain_1.15" } else { "none" },
            "at {t} ns"
        );
        assert!(m["value"].is_null());
    }
    assert_eq!(faulty.iter().filter(|(t, _)| *t >= onset_ns).count(), 300);
    for name in [
        "ftp75city2_NF_window.mcap",
        "ftp75city2_NF_0-100s.mcap",
        "ftp75city2_NF_140-260s.mcap",
    ] {
        let free = messages(&dir.join(name), "/truth/turbo");
        assert!(!free.is_empty(), "{name}");
        assert!(
            free.iter()
                .all(|(_, m)| m["fault"] == "none" && m["fault_active"] == false),
            "{name}: a fault-free log's truth says none"
        );
    }
    // The data topics of a row and its truth share the row's time.
    let p_im = messages(&dir.join("ftp75city2_f_pim_115_window.mcap"), "/turbo/p_im");
    let times = |v: &[(u64, serde_json::Value)]| v.iter().map(|(t, _)| *t).collect::<Vec<_>>();
    assert_eq!(times(&p_im), times(&faulty));
}

#[test]
fn the_imported_truth_is_read_by_fdd_replay() {
    // config/fdd.toml reads the turbo truth topic.
    let cfg = root().join("config/fdd.toml");
    let o = fdd()
        .arg("replay")
        .arg(
            root()
                .join(LIU_ICE)
                .join("ftp75city2_f_waf_085_window.mcap"),
        )
        .arg("--config")
        .arg(&cfg)
        .output()
        .expect("run");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{out}{}", stderr(&o));
    assert!(
        out.contains("/truth/turbo") && out.contains("ground truth"),
        "{out}"
    );
    assert!(
        out.lines()
            .any(|l| l.contains("waf_gain_0.85") && l.contains("124.15")),
        "the onset is read: {out}"
    );
    assert!(
        out.contains("Problems (counted; the replay went on)\n  none"),
        "{out}"
    );
}

#[test]
fn official_python_reader_accepts_the_converted_fixtures() {
    if !fdd_testkit::python_modules_available("mcap.reader") {
        return;
    }
    let files: Vec<PathBuf> = recipes().iter().map(Recipe::mcap).collect();
    let out = Command::new("python3")
        .arg(root().join("tools/check_mcap.py"))
        .args(&files)
        .output()
        .expect("runs python3");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{text}");
    assert_eq!(text.matches(": OK:").count(), files.len(), "{text}");
}

/// A small mapping over columns `t` (s), `a` and `b`, with a truth topic.
const MAPPING: &str = r#"
[time]
column = "t"
unit = "s"
[truth]
topic = "/truth/x"
[[topics]]
topic = "/x/a"
fields = [{ name = "value_u", column = "a", unit = "u" }]
[[topics]]
topic = "/x/b"
fields = [{ name = "value_u", column = "b", unit = "u", scale = 2 }]
"#;

struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new(mapping: &str) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("m.toml"), mapping).expect("write");
        Case { dir }
    }

    fn csv(&self) -> PathBuf {
        self.dir.path().join("in.csv")
    }

    fn out(&self) -> PathBuf {
        self.dir.path().join("out.mcap")
    }

    fn mapping(&self) -> PathBuf {
        self.dir.path().join("m.toml")
    }

    /// Imports `csv` (with `extra` arguments); the exit status and stderr.
    fn import(&self, csv: &[u8], extra: &[&str]) -> (bool, String) {
        std::fs::write(self.csv(), csv).expect("write");
        let o = fdd()
            .arg("import")
            .arg(self.csv())
            .arg("--mapping")
            .arg(self.mapping())
            .arg("-o")
            .arg(self.out())
            .args(extra)
            .output()
            .expect("run");
        (o.status.success(), stderr(&o))
    }
}

#[test]
fn csv_errors_name_the_file_the_line_and_the_column() {
    let c = Case::new(MAPPING);
    let csv = c.csv().display().to_string();
    let long_row = format!("t,a,b\n0,1,2\n1,{},2\n", "9".repeat(2 << 20));
    let cases: Vec<(Vec<u8>, &[&str])> = vec![
        (
            b"t,a,b\n0,1,2\n1,x,2\n".to_vec(),
            &["line 3, column 2 `a`: \"x\": not a number"],
        ),
        (
            b"t,a,b\n0,1,2\n\n\n1,x,2\n".to_vec(),
            &["line 5, column 2 `a`: \"x\": not a number"],
        ),
        (
            b"t,a,b\r\n0,1,2\r\n\r\n1,x,2\r\n".to_vec(),
            &["line 4, column 2 `a`: \"x\": not a number"],
        ),
        (
            b"t,a,b\n0,1,2\n1,2,\"3\n\"\n2,x,2\n".to_vec(),
            &["line 5, column 2 `a`: \"x\": not a number"],
        ),
        (
            b"t,a,b\n0,1,2\n1,NaN,2\n".to_vec(),
            &["line 3, column 2 `a`: \"NaN\": not a finite number"],
        ),
        (
            b"t,a,b\n0,1,inf\n".to_vec(),
            &["line 2, column 3 `b`: \"inf\": not a finite number"],
        ),
        (
            b"t,a,b\n0,1,2\n1,,2\n".to_vec(),
            &["line 3, column 2 `a`: empty field"],
        ),
        (
            b"t,a,b\n0,1,2\n1,2\n".to_vec(),
            &["line 3: 2 fields, the header has 3 columns"],
        ),
        (
            b"t,a,b\n0,1,2\n1,2,3,4\n".to_vec(),
            &["line 3: 4 fields, the header has 3 columns"],
        ),
        (
            b"t,a,b\n0,1,2\n0.5,1,2\n0.5,1,2\n".to_vec(),
            &[
                "line 4, column 1 `t`",
                "not after the previous row's",
                "line 3",
            ],
        ),
        (
            b"t,a,b\n1,1,2\n0.5,1,2\n".to_vec(),
            &["line 3, column 1 `t`", "must increase"],
        ),
        (
            b"t,a,b\n0,1,2\nabc,1,2\n".to_vec(),
            &["line 3, column 1 `t`: \"abc\": not a time in s"],
        ),
        (
            b"t,a,b\nnan,1,2\n".to_vec(),
            &["line 2, column 1 `t`: \"nan\": not a finite time"],
        ),
        (
            b"t,a,b\n-1,1,2\n".to_vec(),
            &["line 2, column 1 `t`", "outside 0 .. 2^64 ns", "offset_s"],
        ),
        (
            b"t,a,b\n1e300,1,2\n".to_vec(),
            &["line 2, column 1 `t`", "beyond any log time"],
        ),
        (
            b"t,a,b\n0,1,1e308\n".to_vec(),
            &[
                "line 2, column 3 `b`",
                "is not a finite number (topic /x/b)",
            ],
        ),
        (
            b"t,a,b\n0,\xff\xfe,2\n".to_vec(),
            &["line 2, column 2 `a`", "not UTF-8"],
        ),
        (
            b"t,a,c\n0,1,2\n".to_vec(),
            &[
                "line 1 (the header) has no column `b`",
                "topics[1].fields[0].column",
                "m.toml",
                "`t`, `a`, `c`",
            ],
        ),
        (
            b"time,a,b\n0,1,2\n".to_vec(),
            &["line 1 (the header) has no column `t`", "[time] column"],
        ),
        (
            b"t,a,a,b\n0,1,2,3\n".to_vec(),
            &["line 1, column 3 `a`", "also column 2", "ambiguous"],
        ),
        (b"".to_vec(), &["line 1: empty file"]),
        (b"t,a,b\n".to_vec(), &["no data rows"]),
        (
            long_row.into_bytes(),
            &["line 3", "longer than 1048576 bytes"],
        ),
    ];
    for (input, wants) in cases {
        let (ok, err) = c.import(&input, &[]);
        let shown = String::from_utf8_lossy(&input[..input.len().min(60)]).into_owned();
        assert!(!ok, "{shown:?} was imported");
        assert!(
            err.contains(&format!("error: {csv}: ")) || err.contains("m.toml"),
            "{shown:?}: the error names the file: {err}"
        );
        for w in wants {
            assert!(err.contains(w), "{shown:?}: want {w:?} in: {err}");
        }
        assert!(!err.contains("panicked"), "{err}");
        assert!(!c.out().exists(), "{shown:?}: no partial output");
        assert!(
            std::fs::read_dir(c.dir.path()).expect("dir").all(|e| !e
                .expect("entry")
                .file_name()
                .to_string_lossy()
                .contains(".fdd-import-")),
            "{shown:?}: the temporary file is removed"
        );
    }

    // Times whose difference from the first row's overflows 128 bits.
    let c2 = Case::new(&MAPPING.replace("unit = \"s\"", "unit = \"s\"\norigin = \"first_row\""));
    let (ok, err) = c2.import(
        b"t,a,b\n99999999999999999999999999999,1,2\n-99999999999999999999999999999,1,2\n",
        &[],
    );
    assert!(
        !ok && err.contains("line 3, column 1 `t`") && err.contains("beyond 10^38"),
        "{err}"
    );

    // Quotes, CRLF, spaces around fields, a byte-order mark, blank lines: read.
    let (ok, err) = c.import(
        b"\xEF\xBB\xBFt, a ,\"b\"\r\n0, 1 ,\"2\"\r\n\r\n1,2,3\r\n",
        &[],
    );
    assert!(ok, "{err}");
    let b = messages(&c.out(), "/x/b");
    assert_eq!(b.len(), 2);
    assert_eq!(b[1].1["value_u"].as_f64(), Some(6.0));
}

#[test]
fn mapping_errors_name_the_file_the_table_and_the_key() {
    let cases: Vec<(String, &[&str])> = vec![
        (
            MAPPING.replace("unit = \"s\"", "unit = \"sec\""),
            &["[time] unit = \"sec\": must be one of"],
        ),
        (
            MAPPING.replace("scale = 2", "scale = 0"),
            &["topics[1].fields[0].scale = 0.0"],
        ),
        (
            MAPPING.replace("scale = 2", "scale = nan"),
            &["topics[1].fields[0].scale = NaN"],
        ),
        (
            MAPPING.replace("scale = 2", "scael = 2"),
            &["topics[1].fields[0]", "scael"],
        ),
        (
            MAPPING.replace("\"/x/b\"", "\"/x/a\""),
            &["topics[1].topic = \"/x/a\"", "already written by topics[0]"],
        ),
        (MAPPING.replace("[truth]", "[truht]"), &["truht"]),
        (
            MAPPING.replace("column = \"t\"\n", ""),
            &["[time] column = (missing)"],
        ),
        (
            MAPPING.replace("column = \"t\"", "column = \"t\"\nperiod_s = 1.0"),
            &["[time] period_s = 1.0", "not both"],
        ),
        (
            MAPPING.replace("unit = \"u\", scale", "unit = \"\", scale"),
            &["topics[1].fields[0].unit = \"\": must not be empty"],
        ),
        ("not toml [".to_string(), &["m.toml"]),
    ];
    for (mapping, wants) in cases {
        let c = Case::new(&mapping);
        let (ok, err) = c.import(b"t,a,b\n0,1,2\n", &[]);
        assert!(!ok, "{mapping}");
        assert!(
            err.contains(&c.mapping().display().to_string()),
            "names the mapping file: {err}"
        );
        for w in wants {
            assert!(err.contains(w), "want {w:?} in: {err}");
        }
        assert!(!c.out().exists());
    }
}

#[test]
fn no_output_over_an_input_and_a_failed_import_leaves_the_old_output() {
    let c = Case::new(MAPPING);
    std::fs::write(c.csv(), "t,a,b\n0,1,2\n").expect("write");
    let import_to = |out: &Path| {
        let o = fdd()
            .arg("import")
            .arg(c.csv())
            .arg("--mapping")
            .arg(c.mapping())
            .arg("-o")
            .arg(out)
            .output()
            .expect("run");
        (o.status.success(), stderr(&o))
    };
    let (ok, err) = import_to(&c.csv());
    assert!(
        !ok && err.contains("refusing to write the log over its CSV input"),
        "{err}"
    );
    let (ok, err) = import_to(&c.mapping());
    assert!(
        !ok && err.contains("refusing to write the log over its mapping file"),
        "{err}"
    );
    let dotted = c.dir.path().join(".").join("in.csv");
    let (ok, err) = import_to(&dotted);
    assert!(!ok && err.contains("over its CSV input"), "{err}");
    #[cfg(unix)]
    {
        let link = c.dir.path().join("link.mcap");
        std::fs::hard_link(c.csv(), &link).expect("hard link");
        let (ok, err) = import_to(&link);
        assert!(!ok && err.contains("over its CSV input"), "{err}");
    }
    let (ok, err) = import_to(&c.dir.path().join("other.toml"));
    assert!(!ok && err.contains("give the log a .mcap name"), "{err}");
    assert_eq!(
        std::fs::read_to_string(c.csv()).expect("csv"),
        "t,a,b\n0,1,2\n",
        "inputs untouched"
    );

    // An existing output survives a failed import and is replaced by a good one.
    std::fs::write(c.out(), "old").expect("write");
    let (ok, _) = c.import(b"t,a,b\n0,1,2\n1,x,2\n", &[]);
    assert!(!ok);
    assert_eq!(std::fs::read_to_string(c.out()).expect("old"), "old");
    let (ok, err) = c.import(b"t,a,b\n0,1,2\n1,3,4\n", &[]);
    assert!(ok, "{err}");
    assert_eq!(messages(&c.out(), "/x/a").len(), 2);
}

#[test]
fn fault_arguments_are_checked() {
    let c = Case::new(MAPPING);
    let csv = b"t,a,b\n0,1,2\n1,1,2\n2,1,2\n";
    let (ok, err) = c.import(csv, &["--fault", "a_gain_1.1", "--fault-onset-s", "1"]);
    assert!(ok, "{err}");
    let truth = messages(&c.out(), "/truth/x");
    let active: Vec<bool> = truth
        .iter()
        .map(|(_, m)| m["fault_active"].as_bool().expect("bool"))
        .collect();
    assert_eq!(active, [false, true, true], "active from t >= onset");
    for (args, want) in [
        (&["--fault", "x"][..], "--fault-onset-s"),
        (&["--fault-onset-s", "1"][..], "--fault"),
        (
            &["--fault", "pim_gain_+15", "--fault-onset-s", "1"][..],
            "`+` joins two fault names",
        ),
        (
            &["--fault", "none", "--fault-onset-s", "1"][..],
            "leave --fault out",
        ),
        (
            &["--fault", "a b", "--fault-onset-s", "1"][..],
            "use letters, digits",
        ),
        (
            &["--fault", "x", "--fault-onset-s", "-1"][..],
            "--fault-onset-s",
        ),
        (
            &["--fault", "x", "--fault-onset-s", "nan"][..],
            "--fault-onset-s",
        ),
        (
            &["--fault", "x", "--fault-onset-s", "2.5"][..],
            "after the last row (2 s of log time): the fault would never be active",
        ),
    ] {
        std::fs::remove_file(c.out()).ok();
        let (ok, err) = c.import(csv, args);
        assert!(!ok, "{args:?}");
        assert!(err.contains(want), "{args:?}: want {want:?} in: {err}");
        assert!(!c.out().exists(), "{args:?}");
    }
    let c = Case::new(&MAPPING.replace("[truth]\ntopic = \"/truth/x\"\n", ""));
    let (ok, err) = c.import(csv, &["--fault", "x", "--fault-onset-s", "1"]);
    assert!(
        !ok && err.contains("--fault needs a [truth] table"),
        "{err}"
    );
}

mod random_input {
    use super::*;
    use proptest::prelude::*;

    fn csv_text() -> impl Strategy<Value = Vec<u8>> {
        let field = prop_oneof![
            4 => (-1e6..1e6f64).prop_map(|v| v.to_string()),
            2 => (0u32..100).prop_map(|v| v.to_string()),
            1 => Just(String::new()),
            1 => Just("NaN".to_string()),
            1 => Just("\"1\"".to_string()),
            1 => Just("1e999".to_string()),
            1 => Just("-0".to_string()),
            1 => "[ -~]{0,6}",
        ];
        let row = prop::collection::vec(field, 1..5).prop_map(|f| f.join(","));
        (
            prop::collection::vec(row, 0..8),
            any::<bool>(),
            any::<prop::sample::Index>(),
            any::<u8>(),
        )
            .prop_map(|(rows, header, at, byte)| {
                let mut text = if header {
                    String::from("t,a,b\n")
                } else {
                    String::new()
                };
                text.push_str(&rows.join("\n"));
                let mut b = text.into_bytes();
                // One byte changed somewhere, now and then a control or non-UTF-8 byte.
                if !b.is_empty() && byte % 3 == 0 {
                    let i = at.index(b.len());
                    b[i] = byte;
                }
                b
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        /// Any input is imported or refused with an error naming the CSV or the mapping, in
        /// the library (no process per case), and nothing is left behind on refusal.
        #[test]
        fn any_csv_is_imported_or_refused(input in csv_text(), period in any::<bool>()) {
            let mapping = if period {
                MAPPING.replace("column = \"t\"\nunit = \"s\"", "period_s = 0.5")
            } else {
                MAPPING.to_string()
            };
            let c = Case::new(&mapping);
            std::fs::write(c.csv(), &input).expect("write");
            let result = fdd::import::import(
                &c.csv(),
                &c.mapping(),
                &c.out(),
                &fdd::import::ImportOptions::default(),
            );
            match result {
                Ok(stats) => {
                    prop_assert!(stats.rows > 0);
                    prop_assert_eq!(
                        LogReader::open(c.out()).expect("readable").count() as u64,
                        stats.messages
                    );
                }
                Err(e) => {
                    let text = e.to_string();
                    prop_assert!(text.contains("in.csv") || text.contains("m.toml"), "{}", text);
                    prop_assert!(!c.out().exists());
                }
            }
        }
    }
}
