//! `include/fdd.h` is what cbindgen generates from `src/ffi/` with `cbindgen.toml`: a change
//! to the ABI that is not in the committed header fails here. `FDD_BLESS=1` rewrites it.

use std::path::Path;

#[test]
fn the_committed_header_is_what_cbindgen_generates() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    // The ABI's module only (cbindgen follows its `mod`s), not the crate: the rest of
    // fdd-monitor's public constants are not part of it.
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/ffi/mod.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let path = dir.join("include/fdd.h");
    if std::env::var_os("FDD_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("write include/fdd.h");
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    if committed != generated {
        let text = String::from_utf8_lossy(&generated);
        panic!(
            "{} differs from what cbindgen generates from src/ffi/ (rerun with FDD_BLESS=1 \
             to accept); generated:\n{text}",
            path.display()
        );
    }
}
