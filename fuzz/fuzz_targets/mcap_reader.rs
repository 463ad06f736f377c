#![no_main]
//! Fuzz target `mcap_reader`: the body is [`fdd_fuzzing::mcap_reader`].

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = fdd_fuzzing::mcap_reader(data);
});
