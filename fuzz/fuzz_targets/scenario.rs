#![no_main]
//! Fuzz target `scenario`: the body is [`fdd_fuzzing::scenario`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::scenario(data);
});
