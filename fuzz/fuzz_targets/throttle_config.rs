#![no_main]
//! Fuzz target `throttle_config`: the body is [`fdd_fuzzing::throttle_config`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::throttle_config(data);
});
