//! Replays the fuzz targets' corpus (`fuzz/corpus/<target>/`) through the same entry points the
//! fuzzer runs (`scribblefield::fuzzing`), on stable, as an ordinary test: every seed and every
//! input that once was a finding must end in acceptance or a clear refusal, never a panic.
//! docs/fuzzing.md says how the corpus was made and how to fuzz.
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};

use scribblefield::fuzzing::TARGETS;

fn corpus_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target)
}

fn files_of(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.expect("a directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

#[test]
fn every_corpus_input_is_accepted_or_refused_without_a_panic() {
    let mut failures = Vec::new();
    for (name, run) in TARGETS {
        let files = files_of(&corpus_dir(name));
        assert!(!files.is_empty(), "fuzz/corpus/{name} has no inputs");
        let mut accepted = 0;
        for path in &files {
            let data = std::fs::read(path).expect("read a corpus file");
            match catch_unwind(AssertUnwindSafe(|| run(&data))) {
                Ok(Ok(())) => accepted += 1,
                Ok(Err(refusal)) => assert!(!refusal.is_empty(), "{}: refused without a message", path.display()),
                Err(_) => failures.push(format!("{name}: {} panicked", path.display())),
            }
        }
        // The seeds must reach past the first checks, or the fuzzer starts from nothing.
        assert!(accepted > 0, "no input of fuzz/corpus/{name} is accepted");
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn every_target_has_a_fuzz_binary() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/fuzz_targets");
    for (name, _) in TARGETS {
        let source = std::fs::read_to_string(dir.join(format!("{name}.rs")))
            .unwrap_or_else(|e| panic!("fuzz/fuzz_targets/{name}.rs: {e}"));
        assert!(
            source.contains(&format!("scribblefield::fuzzing::{name}(")),
            "fuzz/fuzz_targets/{name}.rs must call scribblefield::fuzzing::{name}"
        );
    }
}
