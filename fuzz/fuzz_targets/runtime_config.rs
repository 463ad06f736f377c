#![no_main]
//! Fuzz target `runtime_config`: the body is [`fdd_fuzzing::runtime_config`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::runtime_config(data);
});
