//! `scribblefield bench --json` prints one JSON object with every field docs/results/bench.md
//! lists, on the tiny preset (a few seconds on lavapipe).
use std::process::Command;

use scribblefield::gpu::test_support::gpu_for_tests;

fn names_of(v: &serde_json::Value) -> Vec<&str> {
    v["stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["name"].as_str().unwrap())
        .collect()
}

#[test]
fn bench_json_is_one_object_with_every_field() {
    // Only to skip loudly where there is no adapter; the command finds its own.
    if gpu_for_tests("bench_json_is_one_object_with_every_field").is_none() {
        return;
    }
    let out = Command::new(env!("CARGO_BIN_EXE_scribblefield"))
        .args([
            "bench", "--preset", "tiny", "--rays", "64", "--steps", "2", "--warmup", "1",
        ])
        .args(["--matmul", "128", "--json"])
        .output()
        .unwrap();
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(stdout.trim().lines().count(), 1, "{stdout}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let number = |key: &str| {
        v[key]
            .as_f64()
            .unwrap_or_else(|| panic!("`{key}` is not a number in {v}"))
    };
    for key in [
        "steps_per_s",
        "rays_per_s",
        "samples_per_s",
        "mlp_gflops",
        "matmul_gflops",
        "ratio_to_matmul",
        "bytes_per_step",
        "dispatches_per_step",
    ] {
        assert!(number(key) > 0.0, "`{key}` in {v}");
    }
    assert_eq!(number("rays"), 64.0);
    // Measured: the mean the keep stage kept over the timed steps, at most every sample.
    let to_heads = number("samples_to_heads_per_step");
    assert!(to_heads > 0.0 && to_heads <= 64.0 * number("samples_per_ray"), "{v}");
    assert!(names_of(&v).contains(&"keep"), "{v}");
    assert!(v["adapter"].is_string() && v["config"] == "tiny", "{v}");
    // The CLI's own fields: building the trainer compiled at least one kernel per kind of stage
    // (rays, samples, encoding, SH, composite, dense, glue, keep, hash backward, Adam).
    assert!(number("build_s") > 0.0 && number("kernels_compiled") >= 15.0, "{v}");
    // Float atomics where the device has them (lavapipe), else one invocation per level on a
    // CPU device and fixed point on a GPU (`AtomicAdd::best_for`).
    let atomics = v["hash_atomics"].as_str().unwrap_or_default();
    let expected: &[&str] = match v["kernels"].as_str() {
        Some("uniform") => &["float", "per_level"],
        _ => &["float", "fixed_point"],
    };
    assert!(expected.contains(&atomics), "{v}");
    let stages = v["stages"].as_array().unwrap();
    let names: Vec<&str> = stages.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names.first(), Some(&"rays"));
    assert_eq!(names.last(), Some(&"adam"));
    assert!(names.contains(&"density mlp backward"), "{names:?}");
    // The per-stage figures add up to the step's.
    let sum = |key: &str| stages.iter().map(|s| s[key].as_f64().unwrap()).sum::<f64>();
    assert_eq!(sum("dispatches"), number("dispatches_per_step"));
    assert_eq!(sum("bytes"), number("bytes_per_step"));
    // Per-stage GPU time where the adapter has timestamp queries (lavapipe does), else null.
    assert!(
        stages
            .iter()
            .all(|s| s["gpu_ms"].is_null() || s["gpu_ms"].as_f64().unwrap() >= 0.0),
        "{v}"
    );
}
