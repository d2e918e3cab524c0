//! The shader checks build.rs runs, exercised on broken shaders, and every embedded stage
//! compiled by the device itself.
use std::collections::BTreeMap;

use scribblefield::gpu::pipeline::{KernelSpec, create_compute_pipeline};
use scribblefield::gpu::shader_check::{check_all, constant_name, expand_includes, validate};
use scribblefield::gpu::shaders;
use scribblefield::gpu::test_support::gpu_for_tests;

fn files(pairs: &[(&str, &str)]) -> BTreeMap<String, String> {
    pairs
        .iter()
        .map(|(name, text)| (name.to_string(), text.to_string()))
        .collect()
}

const GOOD_STAGE: &str = "@group(0) @binding(0) var<storage, read_write> out: array<f32>;\n\
@compute @workgroup_size(1)\nfn main() {\n    out[0] = 1.0;\n}\n";

#[test]
fn the_real_shaders_pass_and_are_all_embedded() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut on_disk = BTreeMap::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "wgsl") {
            let name = path.file_name().unwrap().to_str().unwrap().to_string();
            on_disk.insert(name, std::fs::read_to_string(&path).unwrap());
        }
    }
    let stages = check_all(&on_disk).unwrap_or_else(|problems| panic!("{problems:#?}"));
    let embedded: Vec<&str> = shaders::ALL.iter().map(|(file, _)| *file).collect();
    let checked: Vec<&str> = stages.iter().map(|stage| stage.file.as_str()).collect();
    assert_eq!(embedded, checked);
    assert!(embedded.contains(&"matmul.wgsl") && !embedded.iter().any(|f| f.starts_with('_')));
    assert_eq!(
        shaders::MATMUL,
        stages.iter().find(|s| s.file == "matmul.wgsl").unwrap().source
    );
    // The include was pasted, the directive line is gone.
    assert!(shaders::IOTA.contains("fn linear_item_index") && !shaders::IOTA.contains("//!include"));
}

#[test]
fn a_syntax_error_is_rejected_with_file_line_and_column() {
    let broken = "@compute @workgroup_size(1)\nfn main() {\n    let x = 1.0 +;\n}\n";
    let problems = check_all(&files(&[("good.wgsl", GOOD_STAGE), ("broken.wgsl", broken)])).unwrap_err();
    assert_eq!(problems.len(), 1, "{problems:#?}");
    let problem = &problems[0];
    assert_eq!((problem.file.as_str(), problem.line), ("broken.wgsl", 3), "{problem}");
    assert!(problem.column >= 17, "{problem}");
    let shown = problem.to_string();
    assert!(shown.starts_with("shaders/broken.wgsl:3:"), "{shown}");
}

#[test]
fn a_type_error_is_rejected_by_validation() {
    // Parses, but assigns an i32 to an f32 storage element.
    let broken = "@group(0) @binding(0) var<storage, read_write> out: array<f32>;\n\
@compute @workgroup_size(1)\nfn main() {\n    let v: i32 = 3;\n    out[0] = v;\n}\n";
    let shader = expand_includes("types.wgsl", &files(&[("types.wgsl", broken)])).unwrap();
    let problem = validate(&shader).unwrap_err();
    assert_eq!(problem.file, "types.wgsl");
    assert_eq!(problem.line, 5, "{problem}");
    assert!(!problem.message.is_empty());
}

#[test]
fn native_only_capabilities_are_rejected() {
    // f64 parses, but WebGPU has no FLOAT64 capability: the check must be as strict as the browser.
    let needs_f64 = "var<private> wide: f64;\n@compute @workgroup_size(1)\nfn main() {\n    wide = 1.0lf;\n}\n";
    let problems = check_all(&files(&[("wide.wgsl", needs_f64)])).unwrap_err();
    assert_eq!(problems[0].file, "wide.wgsl", "{}", problems[0]);
    // naga gives type errors no source span; the file and message must still say it all.
    assert!(
        problems[0].to_string().starts_with("shaders/wide.wgsl: "),
        "{}",
        problems[0]
    );
    assert!(problems[0].message.contains("FLOAT64"), "{}", problems[0]);
}

#[test]
fn an_optional_feature_must_be_declared_and_known() {
    let adds = "@group(0) @binding(0) var<storage, read_write> sum: array<atomic<f32>>;\n\
@compute @workgroup_size(1)\nfn main() {\n    atomicAdd(&sum[0], 1.0);\n}\n";
    let problems = check_all(&files(&[("adds.wgsl", adds)])).unwrap_err();
    assert_eq!(problems[0].file, "adds.wgsl", "{}", problems[0]);
    assert!(problems[0].message.contains("FLOAT32_ATOMIC"), "{}", problems[0]);

    let declared = format!("//!requires float32-atomics\n{adds}");
    check_all(&files(&[("adds.wgsl", &declared)])).unwrap_or_else(|problems| panic!("{problems:#?}"));

    let unknown = format!("//!requires float64\n{adds}");
    let problems = check_all(&files(&[("adds.wgsl", &unknown)])).unwrap_err();
    assert_eq!(
        (problems[0].file.as_str(), problems[0].line),
        ("adds.wgsl", 1),
        "{}",
        problems[0]
    );
    assert!(
        problems[0].message.contains("`float64`") && problems[0].message.contains("float32-atomics"),
        "{}",
        problems[0]
    );
}

#[test]
fn webgpu_core_builtins_that_naga_gates_are_accepted() {
    // unpack2x16float is core WGSL but needs a naga capability: the baseline must include it.
    let unpacks = "@group(0) @binding(0) var<storage, read_write> out: array<f32>;\n\
@compute @workgroup_size(1)\nfn main() {\n    out[0] = unpack2x16float(0x3c00u).x;\n}\n";
    check_all(&files(&[("unpack.wgsl", unpacks)])).unwrap_or_else(|problems| panic!("{problems:#?}"));
}

#[test]
fn errors_inside_snippets_point_at_the_snippet() {
    let snippet = "fn helper() -> f32 {\n    return 1.0;\n}\n\nfn broken() -> f32 {\n    return undefined_name;\n}\n";
    let stage = format!("//!include _helpers.wgsl\n{GOOD_STAGE}");
    let problems = check_all(&files(&[("_helpers.wgsl", snippet), ("stage.wgsl", &stage)])).unwrap_err();
    let problem = &problems[0];
    assert_eq!(
        (problem.file.as_str(), problem.line, problem.stage.as_str()),
        ("_helpers.wgsl", 6, "stage.wgsl")
    );
    assert!(problem.to_string().contains("while checking stage stage.wgsl"));
}

#[test]
fn includes_paste_once_and_reject_cycles_and_missing_files() {
    let shared = "const SHARED: f32 = 2.0;\n";
    let a = "//!include _shared.wgsl\nconst A: f32 = SHARED;\n";
    let b = "//!include _shared.wgsl\n//!include _a.wgsl\nconst B: f32 = SHARED + A;\n";
    let stage = format!("//!include _a.wgsl\n//!include _b.wgsl\n{GOOD_STAGE}");
    let all = files(&[
        ("_shared.wgsl", shared),
        ("_a.wgsl", a),
        ("_b.wgsl", b),
        ("stage.wgsl", &stage),
    ]);
    let expanded = expand_includes("stage.wgsl", &all).unwrap();
    assert_eq!(expanded.source.matches("const SHARED").count(), 1);
    validate(&expanded).unwrap();
    // Line 1 of the expansion is the first line of _shared.wgsl, pasted through _a.wgsl.
    assert_eq!(expanded.origin_of_line(1), ("_shared.wgsl", 1));

    let cyclic = files(&[
        ("_x.wgsl", "//!include _y.wgsl\n"),
        ("_y.wgsl", "//!include _x.wgsl\n"),
        ("s.wgsl", "//!include _x.wgsl\n"),
    ]);
    let problem = expand_includes("s.wgsl", &cyclic).unwrap_err();
    assert!(problem.message.contains("cycle"), "{problem}");

    let missing = files(&[("s.wgsl", "//!include _nowhere.wgsl\n")]);
    let problem = expand_includes("s.wgsl", &missing).unwrap_err();
    assert_eq!((problem.file.as_str(), problem.line), ("s.wgsl", 1));

    let not_a_snippet = files(&[("s.wgsl", "//!include other.wgsl\n"), ("other.wgsl", GOOD_STAGE)]);
    assert!(expand_includes("s.wgsl", &not_a_snippet).is_err());
}

#[test]
fn constant_names_are_rust_identifiers_and_clashes_are_caught() {
    assert_eq!(constant_name("matmul.wgsl"), "MATMUL");
    assert_eq!(constant_name("ray-march.wgsl"), "RAY_MARCH");
    assert_eq!(constant_name("3d.wgsl"), "_3D");
    let clash = files(&[("a-b.wgsl", GOOD_STAGE), ("a_b.wgsl", GOOD_STAGE)]);
    let problems = check_all(&clash).unwrap_err();
    assert!(problems[0].message.contains("clashes"), "{problems:#?}");
}

#[test]
fn every_embedded_stage_compiles_on_the_device() {
    let Some(ctx) = gpu_for_tests("every_embedded_stage_compiles_on_the_device") else {
        return;
    };
    for (file, source) in shaders::ALL {
        let float_atomics = ctx.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC);
        if source.contains("//!requires float32-atomics") && !float_atomics {
            eprintln!("{file}: needs float atomics, which {} lacks", ctx.describe());
            continue;
        }
        let module = ctx.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(file),
            source: wgpu::ShaderSource::Wgsl((*source).into()),
        });
        let info = pollster::block_on(module.get_compilation_info());
        let errors: Vec<_> = info
            .messages
            .iter()
            .filter(|m| m.message_type == wgpu::CompilationMessageType::Error)
            .collect();
        assert!(errors.is_empty(), "{file}: {errors:#?}");
    }
    // And a broken shader surfaces as an error value, not a panic.
    let broken = KernelSpec::new(
        "broken",
        "@compute @workgroup_size(1) fn main() { let x: f32 = 1i; }",
        "main",
    );
    let result = pollster::block_on(create_compute_pipeline(&ctx, &broken));
    assert!(result.is_err());
}
