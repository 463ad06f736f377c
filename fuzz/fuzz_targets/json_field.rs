#![no_main]
//! Fuzz target `json_field`: the body is [`fdd_fuzzing::json_field`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::json_field(data);
});
