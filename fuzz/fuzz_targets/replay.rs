#![no_main]
//! Fuzz target `replay`: the body is [`fdd_fuzzing::replay`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::replay(data);
});
