//! Fuzz target `seven_scenes_text`: the entry point `scribblefield::fuzzing::seven_scenes_text`, which tests/fuzz_corpus.rs
//! also replays on stable. Refusals are fine; a panic, a hang or an allocation over the fuzzer's
//! limits is a finding.
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = scribblefield::fuzzing::seven_scenes_text(data);
});
