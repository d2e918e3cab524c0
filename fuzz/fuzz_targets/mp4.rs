//! Fuzz target `mp4`: the entry point `scribblefield::fuzzing::mp4`, which tests/fuzz_corpus.rs
//! also replays on stable. Refusals are fine; a panic, a hang or an allocation over the fuzzer's
//! limits is a finding.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = scribblefield::fuzzing::mp4(data);
});
