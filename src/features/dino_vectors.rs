//! The DINO and DINOv2 backbones against the official PyTorch code on random weights of the real
//! shapes: `../shared/models/dino-vits8-random/` (DINO ViT-S/8, 12 blocks) and
//! `../shared/models/dinov2-vits14-random/` (DINOv2 ViT-S/14, 2 blocks), each with three images
//! and the float64 reference outputs (see their READMEs). Every value of both outputs must be
//! within `|got - want| / (1 + |want|) < 1e-4`. Where the folders are absent the tests say so
//! loudly and pass. Run in release mode: the ViT-S/8 vector is about 5 GMAC.
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::checkpoint::Checkpoint;
use super::dino::{DinoModel, DinoOutput, input_from_rgb};
use super::pth_writer;
use super::{FeatureMap, NpyLayout, read_npy_map};

const TOLERANCE: f64 = 1e-4;

fn vector_dir(test: &str, name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/models")
        .join(name);
    if dir.is_dir() {
        return Some(dir);
    }
    eprintln!(
        "\n!!! SKIPPING {test}: the reference vector {} is absent; this test checks nothing here !!!\n",
        dir.display()
    );
    None
}

fn error(got: f64, want: f64) -> f64 {
    (got - want).abs() / (1.0 + want.abs())
}

fn num(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("expected.json: no number `{key}` in {v}"))
}

fn idx(v: &serde_json::Value, key: &str) -> usize {
    num(v, key) as usize
}

/// The worst error of `got` against the expected outputs of one image (`outputs[name]`): the
/// full `.npy` map, the samples and the channel means.
fn compare(dir: &Path, got: &FeatureMap, expected: &serde_json::Value) -> f64 {
    let want = read_npy_map(&dir.join(expected["npy"].as_str().unwrap()), NpyLayout::Hwc).unwrap();
    let shape: Vec<usize> = serde_json::from_value(expected["shape"].clone()).unwrap();
    assert_eq!(
        [got.height, got.width, got.dim].map(|v| v as usize).to_vec(),
        shape,
        "output shape"
    );
    assert_eq!((want.height, want.width, want.dim), (got.height, got.width, got.dim));
    let mut worst = got
        .data
        .iter()
        .zip(&want.data)
        .map(|(&g, &w)| error(g as f64, w as f64))
        .fold(0.0, f64::max);
    for s in expected["samples"].as_array().unwrap() {
        let v = got.cell(idx(s, "col") as u32, idx(s, "row") as u32)[idx(s, "channel")];
        worst = worst.max(error(v as f64, num(s, "value")));
    }
    let (cells, dim) = ((got.height * got.width) as usize, got.dim as usize);
    for (c, m) in expected["channel_mean"].as_array().unwrap().iter().enumerate() {
        let mean = (0..cells).map(|i| got.data[i * dim + c] as f64).sum::<f64>() / cells as f64;
        worst = worst.max(error(mean, m.as_f64().unwrap()));
    }
    worst
}

/// Runs `model` with `weights` on the vector's three images, checks the input, the resampled
/// position embedding and both outputs, and returns the worst error per image and output.
fn check_vector(model: DinoModel, dir: &Path, weights: &Path) -> Vec<(String, f64)> {
    let started = Instant::now();
    let expected: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("expected.json")).unwrap()).unwrap();
    let vit = model.load(weights).unwrap();
    let mut report = Vec::new();
    for image in expected["images"].as_array().unwrap() {
        let name = image["image"].as_str().unwrap();
        let rgb = image::open(dir.join(name)).unwrap().to_rgb8();
        let input = input_from_rgb(&rgb, model.patch());
        assert_eq!(
            (input.width as usize, input.height as usize),
            (idx(image, "padded_width"), idx(image, "padded_height")),
            "{name}: padded size"
        );
        for s in image["input_samples"].as_array().unwrap() {
            let v = input.cell(idx(s, "x") as u32, idx(s, "y") as u32)[idx(s, "channel")];
            assert_eq!(v as f64, num(s, "value"), "{name}: input sample {s}");
        }
        let (rows, cols) = (
            image["grid"][0].as_u64().unwrap() as usize,
            image["grid"][1].as_u64().unwrap() as usize,
        );
        let pos = vit.position_embedding(rows, cols);
        let mut pos_worst = 0f64;
        for s in image["pos_embed_samples"].as_array().unwrap() {
            let v = pos[(idx(s, "row") * cols + idx(s, "col")) * vit.dim + idx(s, "channel")];
            pos_worst = pos_worst.max(error(v as f64, num(s, "value")));
        }
        report.push((format!("{name} pos_embed_samples"), pos_worst));
        for (output, key) in [(DinoOutput::Tokens, "tokens"), (DinoOutput::Keys, "keys")] {
            let got = vit.forward(&input, output);
            let worst = compare(dir, &got, &image["outputs"][key]);
            report.push((format!("{name} {key}"), worst));
        }
    }
    for (what, worst) in &report {
        eprintln!("{}: {what}: worst error {worst:.2e}", model.name());
    }
    eprintln!(
        "{}: loading and 3 images in {:.2} s",
        model.name(),
        started.elapsed().as_secs_f64()
    );
    for (what, worst) in &report {
        assert!(*worst < TOLERANCE, "{}: {what}: error {worst:.2e}", model.name());
    }
    report
}

#[test]
fn dino_vits8_matches_the_official_code_on_random_weights() {
    let test = "dino_vits8_matches_the_official_code_on_random_weights";
    let Some(dir) = vector_dir(test, "dino-vits8-random") else {
        return;
    };
    check_vector(DinoModel::DinoVits8, &dir, &dir.join("dino-vits8-random.safetensors"));
}

#[test]
fn dinov2_vits14_matches_the_official_code_on_random_weights() {
    let test = "dinov2_vits14_matches_the_official_code_on_random_weights";
    let Some(dir) = vector_dir(test, "dinov2-vits14-random") else {
        return;
    };
    check_vector(
        DinoModel::Dinov2Vits14,
        &dir,
        &dir.join("dinov2-vits14-random.safetensors"),
    );
}

/// The same weights saved as `torch.save` would (a zip with `archive/data.pkl` and one entry per
/// storage) load to the same tensors and give the same outputs as the safetensors file, also when
/// nested in a training checkpoint as DINO's are.
#[test]
fn a_pth_of_the_dinov2_vector_loads_the_same_tensors_and_outputs() {
    let test = "a_pth_of_the_dinov2_vector_loads_the_same_tensors_and_outputs";
    let Some(dir) = vector_dir(test, "dinov2-vits14-random") else {
        return;
    };
    let st_path = dir.join("dinov2-vits14-random.safetensors");
    let st = Checkpoint::open(&st_path).unwrap();
    let names = st.names();
    let tensors: Vec<(String, Vec<usize>, Vec<f32>)> = names
        .iter()
        .map(|n| {
            let shape = st.shape(n).unwrap().to_vec();
            let v = st.f32(n, &shape).unwrap();
            (n.clone(), shape, v)
        })
        .collect();
    let list: Vec<(&str, &[usize], &[f32])> = tensors.iter().map(|(n, s, v)| (n.as_str(), &s[..], &v[..])).collect();
    let tmp = tempfile::tempdir().unwrap();
    let pth_path = tmp.path().join("dinov2_vits14_random.pth");
    std::fs::write(&pth_path, pth_writer::to_pth_bytes(&list)).unwrap();
    let pth = Checkpoint::open(&pth_path).unwrap();
    assert!(matches!(pth, Checkpoint::Pth(_)));
    assert_eq!(pth.names(), names);
    for (n, s, v) in &tensors {
        assert_eq!(&pth.f32(n, s).unwrap(), v, "{n}");
    }
    // The whole chain from the .pth, compared with the reference as the safetensors run is.
    let report = check_vector(DinoModel::Dinov2Vits14, &dir, &pth_path);
    assert_eq!(report.len(), 9);

    // The same backbone inside a training checkpoint (`teacher`, `backbone.` names, a head).
    let mut entries: Vec<pth_writer::Entry> = list
        .iter()
        .map(|(n, s, v)| pth_writer::f32_entry(&format!("backbone.{n}"), s, v))
        .collect();
    entries.push(pth_writer::f32_entry("head.last_layer.weight", &[2, 384], &[0.5; 768]));
    let pickle = pth_writer::pickle_checkpoint(&entries, Some("teacher"));
    let wrapped_path = tmp.path().join("checkpoint.pth");
    std::fs::write(
        &wrapped_path,
        pth_writer::zip_checkpoint("checkpoint", &pickle, &entries),
    )
    .unwrap();
    let wrapped = DinoModel::Dinov2Vits14.load(&wrapped_path).unwrap();
    let plain = DinoModel::Dinov2Vits14.load(&st_path).unwrap();
    let rgb = image::open(dir.join("input-100x60.png")).unwrap().to_rgb8();
    let input = input_from_rgb(&rgb, 14);
    for output in [DinoOutput::Tokens, DinoOutput::Keys] {
        assert_eq!(wrapped.forward(&input, output).data, plain.forward(&input, output).data);
    }
}
