#![no_main]
//! Fuzz target `intake_config`: the body is [`fdd_fuzzing::intake_config`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::intake_config(data);
});
