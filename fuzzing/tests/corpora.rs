//! Every committed fuzz input, replayed on stable: the seeds (`fuzz/seeds/<target>/`), the
//! minimized corpora cargo-fuzz grew from them (`fuzz/corpus/<target>/`) and every input that
//! once crashed a target (`fuzz/regressions/<target>/`, named for the defect). A defect fixed
//! after a fuzzer found it stays fixed without the fuzzer; see fuzz/README.md.
//!
//! `FDD_BLESS=1` rewrites the seeds and the dictionaries from the sources they come from (the
//! configuration files, the scenario files, the seed simulations); without it the test fails
//! when a committed seed differs from what would be written.

use std::path::{Path, PathBuf};

use fdd_fuzzing::{seeds, Outcome, TARGETS};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn fuzz_dir() -> PathBuf {
    root().join("fuzz")
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = match std::fs::read_dir(dir) {
        Ok(rd) => rd
            .map(|e| e.expect("readable directory entry").path())
            .filter(|p| p.is_file())
            .collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

/// The JSON-field seeds: a length byte, the path, the text.
fn json_seeds() -> Vec<(String, Vec<u8>)> {
    let cases: &[(&str, &str, &str)] = &[
        ("flat", "voltage_v", r#"{"voltage_v":1.25}"#),
        ("null", "voltage_v", r#"{"voltage_v":null}"#),
        (
            "nested",
            "test_result.value",
            r#"{"t":1,"test_result":{"value":-3.5e-7,"unit":"V"}}"#,
        ),
        ("string", "power_w", r#"{"power_w":"1.0"}"#),
        ("escaped_key", "a\"b", r#"{"a\"b":2,"x":[1,{"y":3}]}"#),
        ("duplicate", "k", r#"{"k":1,"k":2}"#),
        (
            "exponent",
            "p",
            r#"{"p":1.7976931348623157e308,"q":5e-324}"#,
        ),
        ("whitespace", "v", " {\n\t\"v\" : 0.1 , \"w\":true } "),
        ("not_object", "v", "[1,2,3]"),
    ];
    cases
        .iter()
        .map(|(name, path, json)| {
            let mut b = vec![path.len() as u8];
            b.extend_from_slice(path.as_bytes());
            b.extend_from_slice(json.as_bytes());
            (format!("{name}.bin"), b)
        })
        .collect()
}

/// What `fuzz/seeds/<target>/` holds, from its sources.
fn expected_seeds(target: &str) -> Vec<(String, Vec<u8>)> {
    let read = |p: PathBuf| std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    match target {
        "mcap_reader" | "replay" => seeds::small_logs().expect("the seed scenarios simulate"),
        "json_field" => json_seeds(),
        "runtime_config" => vec![("fdd.toml".into(), read(root().join("config/fdd.toml")))],
        "throttle_config" => vec![(
            "throttle.toml".into(),
            read(root().join("config/throttle.toml")),
        )],
        "intake_config" => vec![(
            "intake.toml".into(),
            read(root().join("config/intake.toml")),
        )],
        "scenario" => {
            let mut v: Vec<(String, Vec<u8>)> = files(&root().join("fixtures/scenarios"))
                .into_iter()
                .map(|p| {
                    let name = p.file_name().expect("a file name").to_string_lossy().into();
                    (name, read(p))
                })
                .collect();
            v.extend(
                seeds::scenario_texts().map(|(n, t)| (format!("{n}.toml"), t.as_bytes().to_vec())),
            );
            v
        }
        other => panic!("no seeds defined for target {other}"),
    }
}

/// Every key of the TOML texts, for the configuration targets' dictionary.
fn toml_dictionary() -> String {
    let mut keys = std::collections::BTreeSet::new();
    fn walk(t: &toml::Table, keys: &mut std::collections::BTreeSet<String>) {
        for (k, v) in t {
            keys.insert(k.clone());
            match v {
                toml::Value::Table(inner) => walk(inner, keys),
                toml::Value::Array(items) => {
                    for i in items {
                        if let toml::Value::Table(inner) = i {
                            walk(inner, keys);
                        }
                    }
                }
                _ => {}
            }
        }
    }
    let mut sources: Vec<PathBuf> = ["fdd.toml", "throttle.toml", "intake.toml"]
        .iter()
        .map(|f| root().join("config").join(f))
        .collect();
    sources.extend(files(&root().join("fixtures/scenarios")));
    for p in sources {
        let text = std::fs::read_to_string(&p).expect("readable source");
        let table: toml::Table = toml::from_str(&text).expect("committed TOML parses");
        walk(&table, &mut keys);
    }
    let mut out = String::from(
        "# Keys of config/*.toml and fixtures/scenarios/*.toml (written by fuzzing/tests/corpora.rs, FDD_BLESS=1)\n",
    );
    for k in keys {
        out.push_str(&format!("\"{k} = \"\n\"[{k}]\"\n"));
    }
    for v in [
        "nan", "inf", "-inf", "1e300", "-1e300", "0", "-1", "1e-300", "[]", "\"\"",
    ] {
        out.push_str(&format!("\"{v}\"\n"));
    }
    out
}

#[test]
fn the_seeds_and_dictionaries_are_what_their_sources_give() {
    let bless = std::env::var_os("FDD_BLESS").is_some();
    let mut stale = Vec::new();
    for (target, _) in TARGETS {
        let dir = fuzz_dir().join("seeds").join(target);
        let want = expected_seeds(target);
        if bless {
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("create the seed directory");
            for (name, bytes) in &want {
                std::fs::write(dir.join(name), bytes).expect("write a seed");
            }
        }
        let have = files(&dir);
        if have.len() != want.len() {
            stale.push(format!(
                "{target}: {} seeds, expected {}",
                have.len(),
                want.len()
            ));
        }
        for (name, bytes) in &want {
            if std::fs::read(dir.join(name)).ok().as_ref() != Some(bytes) {
                stale.push(format!("{target}/{name}"));
            }
        }
    }
    let dict = fuzz_dir().join("dicts/toml.dict");
    let want = toml_dictionary();
    if bless {
        std::fs::create_dir_all(dict.parent().expect("a parent")).expect("create dicts/");
        std::fs::write(&dict, &want).expect("write the dictionary");
    }
    if std::fs::read_to_string(&dict).ok().as_deref() != Some(want.as_str()) {
        stale.push("dicts/toml.dict".into());
    }
    assert!(
        stale.is_empty(),
        "committed fuzz seeds differ from their sources (FDD_BLESS=1 rewrites them): {stale:?}"
    );
}

#[test]
fn every_committed_fuzz_input_runs_without_a_crash() {
    let mut total = 0;
    for (target, body) in TARGETS {
        let mut inputs = Vec::new();
        for kind in ["seeds", "corpus", "regressions"] {
            inputs.extend(files(&fuzz_dir().join(kind).join(target)));
        }
        assert!(
            !inputs.is_empty(),
            "fuzz target {target} has no committed input under fuzz/"
        );
        for p in &inputs {
            let bytes = std::fs::read(p).expect("readable fuzz input");
            // A panic names the input; the harness itself asserts what must hold.
            eprintln!("{target}: {}", p.display());
            let outcome = body(&bytes);
            // Every seed but the JSON texts that are not a number at the path is a valid
            // input: a harness that refused them would fuzz only its error paths.
            let refusable = ["string.bin", "not_object.bin"];
            let is_seed = p.parent().and_then(Path::parent).and_then(Path::file_name)
                == Some(std::ffi::OsStr::new("seeds"));
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if is_seed && !refusable.contains(&name) {
                assert_eq!(outcome, Outcome::Accepted, "{target}: seed {name} refused");
            }
        }
        total += inputs.len();
    }
    eprintln!("{total} fuzz inputs replayed");
}
