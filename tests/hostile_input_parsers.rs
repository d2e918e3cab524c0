//! Hostile files for the parsers of user files other than archives and annotations: PyTorch
//! checkpoints (zip + pickle), trainer checkpoints for `export`, capture folders as the command
//! line walks them, COLMAP's binary model, and what an archive says of where it came from. Each
//! input is made here, small: limits that would need gigabytes are lowered through the readers'
//! limit arguments, or the input only claims its size (a sparse file, an image header).
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use scribblefield::features::pth::{PickleLimits, Pth, PthLimits};
use scribblefield::field::gpu::trainer::TrainerState;
use scribblefield::field::{ParamLayout, Preset};
use scribblefield::safetensors::SafeTensors;
use scribblefield::saved_field::Checkpoint;
use scribblefield::scene::import::{ImportOptions, import, text_checks};

fn err<T>(r: Result<T, impl std::fmt::Display>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

fn assert_mentions(e: &str, parts: &[&str]) {
    for p in parts {
        assert!(e.contains(p), "error {e:?} should mention {p:?}");
    }
}

// ---- pickles and .pth files -------------------------------------------------------------

fn text(out: &mut Vec<u8>, s: &str) {
    out.push(b'X');
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// `_rebuild_tensor_v2` of a 1-d tensor of `len` values over storage `key` of `numel` `class`.
fn tensor(out: &mut Vec<u8>, key: &str, class: &str, numel: u8, len: u8) {
    out.extend_from_slice(b"ctorch._utils\n_rebuild_tensor_v2\n(");
    out.push(b'(');
    text(out, "storage");
    out.extend_from_slice(format!("ctorch\n{class}\n").as_bytes());
    text(out, key);
    text(out, "cpu");
    out.extend_from_slice(&[
        b'K', numel, b't', b'Q', b'K', 0, b'(', b'K', len, b't', b'(', b'K', 1, b't', 0x89,
    ]);
    out.extend_from_slice(b"ccollections\nOrderedDict\n)Rt");
    out.push(b'R');
}

/// A `.pth` zip of `pickle` and `entries`, deflated (so a run of zeros is a small zip bomb).
fn pth_zip(pickle: &[u8], entries: &[(&str, &[u8])]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let deflated = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    zip.start_file("archive/data.pkl", deflated).unwrap();
    zip.write_all(pickle).unwrap();
    for (name, bytes) in entries {
        zip.start_file(format!("archive/data/{name}"), deflated).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap().into_inner()
}

fn open(bytes: Vec<u8>) -> Result<Pth, scribblefield::features::FeatureError> {
    Pth::from_bytes("hostile.pth", bytes)
}

#[test]
fn two_tensors_naming_one_storage_with_other_sizes_are_refused() {
    for (class_b, numel_b) in [("FloatStorage", 4), ("HalfStorage", 2)] {
        let mut p = b"\x80\x02}(".to_vec();
        text(&mut p, "a");
        tensor(&mut p, "0", "FloatStorage", 2, 2);
        text(&mut p, "b");
        tensor(&mut p, "0", class_b, numel_b, numel_b);
        p.extend_from_slice(b"u.");
        let e = err(open(pth_zip(&p, &[("0", &[0u8; 8])])));
        assert_mentions(
            &e,
            &[
                "hostile.pth",
                "tensor `b` names storage `0` as",
                "another tensor as 2 float32",
            ],
        );
    }
}

#[test]
fn deeply_nested_tuples_end_in_an_error_not_a_stack_overflow() {
    let deep = vec![0x85u8; 1_000_000];
    let root = [&b"\x80\x02N"[..], &deep, b"."].concat();
    let no_stop = [&b"\x80\x02N"[..], &deep].concat();
    let key = [&b"\x80\x02}N"[..], &deep, b"K\x00s."].concat();
    for pickle in [root, no_stop, key] {
        let e = err(open(pth_zip(&pickle, &[])));
        assert_mentions(&e, &["archive/data.pkl byte", "tuples nested more than 64 deep"]);
    }
}

#[test]
fn a_pickle_that_inflates_past_its_cap_is_refused_by_what_was_read() {
    let limits = PthLimits {
        pickle_bytes: 1 << 20,
        ..PthLimits::default()
    };
    let bomb = pth_zip(&vec![b'N'; 2 << 20], &[]);
    assert!(bomb.len() < 20_000, "{} bytes", bomb.len());
    let e = err(Pth::from_bytes_with("bomb.pth", bomb, limits));
    assert_mentions(
        &e,
        &["bomb.pth", "archive/data.pkl` inflates to more than 1048576 bytes"],
    );
}

#[test]
fn memo_fetches_share_their_value_and_what_is_built_is_bounded() {
    // A 1 MiB string fetched 2,500 times: 2.5 GB if each fetch copied it.
    let mut p = b"\x80\x02(".to_vec();
    text(&mut p, &"a".repeat(1 << 20));
    p.extend_from_slice(b"q\x00");
    for _ in 0..2500 {
        p.extend_from_slice(b"h\x00");
    }
    p.extend_from_slice(b"t.");
    let start = Instant::now();
    let e = err(open(pth_zip(&p, &[])));
    assert!(start.elapsed() < Duration::from_secs(10), "{:?}", start.elapsed());
    assert_mentions(&e, &["the checkpoint is not a dict but (\"aaaa"]);
    assert!(e.len() < 1000, "a message of {} bytes", e.len());
    // Values built at all are counted: 100,000 Nones against a 64 KiB budget.
    let limits = PthLimits {
        pickle: PickleLimits {
            built_bytes: 64 << 10,
            ..PickleLimits::default()
        },
        ..PthLimits::default()
    };
    let many = [&b"\x80\x02("[..], &vec![b'N'; 100_000], b"t."].concat();
    let e = err(Pth::from_bytes_with("nones.pth", pth_zip(&many, &[]), limits));
    assert_mentions(&e, &["builds more than 65536 bytes of values"]);
}

#[test]
fn one_setitems_of_400k_keys_is_linear() {
    let mut p = b"\x80\x02}(".to_vec();
    for i in 0..400_000 {
        text(&mut p, &format!("k{i}"));
        p.extend_from_slice(b"K\x00");
    }
    p.extend_from_slice(b"u.");
    let start = Instant::now();
    let e = err(open(pth_zip(&p, &[])));
    assert!(start.elapsed() < Duration::from_secs(15), "{:?}", start.elapsed());
    assert_mentions(&e, &["no state dict", "keys: k0, k1"]);
    assert!(e.len() < 2000, "a message of {} bytes", e.len());
}

#[test]
fn a_storage_is_checked_before_it_is_read_and_reads_are_capped() {
    let mut p = b"\x80\x02}(".to_vec();
    text(&mut p, "a");
    tensor(&mut p, "0", "FloatStorage", 2, 2);
    p.extend_from_slice(b"u.");
    // The entry inflates to 64 MiB; the pickle says 8 bytes: refused from the entry's header.
    let start = Instant::now();
    let e = err(open(pth_zip(&p, &[("0", &vec![0u8; 64 << 20])])));
    assert!(start.elapsed() < Duration::from_secs(10), "{:?}", start.elapsed());
    assert_mentions(
        &e,
        &[
            "storage `archive/data/0` has 67108864 bytes",
            "2 float32 values (8 bytes)",
        ],
    );
    // What tensors read is capped over the whole file.
    let limits = PthLimits {
        storage_bytes: 4,
        ..PthLimits::default()
    };
    let p = Pth::from_bytes_with("w.pth", pth_zip(&p, &[("0", &[0u8; 8])]), limits).unwrap();
    let e = err(p.f32("a", &[2]));
    assert_mentions(
        &e,
        &[
            "w.pth",
            "storage `archive/data/0` would take the tensors read past 4 bytes",
        ],
    );
}

// ---- trainer checkpoints (`export`) -----------------------------------------------------

fn small_checkpoint() -> Checkpoint {
    let changes = serde_json::json!({
        "encoding": {"kind": "freq_only", "frequencies": 1},
        "density_width": 2, "density_layers": 1, "geometry_dim": 2, "color_width": 2, "color_layers": 1,
        "feature_width": 2, "feature_layers": 1, "feature_dim": 2, "semantic_width": 2, "num_classes": 2
    });
    let config = Preset::parse("budget")
        .unwrap()
        .config()
        .with_changes(&changes)
        .unwrap();
    let total = ParamLayout::new(&config).total;
    Checkpoint {
        config,
        state: TrainerState {
            step: 1,
            params: vec![0.5; total],
            first_moment: vec![0.0; total],
            second_moment: vec![0.0; total],
        },
        extra: Default::default(),
    }
}

/// A safetensors file of `header` (JSON) and `data`.
fn safetensors_of(header: &serde_json::Value, data: &[u8]) -> Vec<u8> {
    let h = header.to_string();
    [&(h.len() as u64).to_le_bytes()[..], h.as_bytes(), data].concat()
}

#[test]
fn checkpoints_with_overlapping_tensors_huge_configs_or_nan_are_refused() {
    let ok = small_checkpoint();
    Checkpoint::from_bytes("ok.safetensors", ok.to_bytes()).unwrap();
    // Not finite: by the tensor's name.
    let mut nan = ok.clone();
    nan.state.params[1] = f32::NAN;
    let e = err(Checkpoint::from_bytes("nan.safetensors", nan.to_bytes()));
    assert_mentions(
        &e,
        &[
            "nan.safetensors",
            "has 1 values that are not finite (the first: NaN at index 1)",
        ],
    );
    // Tensors sharing bytes.
    let shared = serde_json::json!({
        "a": {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]},
        "b": {"dtype": "F32", "shape": [2], "data_offsets": [4, 12]},
    });
    let e = err(SafeTensors::from_bytes(
        "overlap.safetensors",
        safetensors_of(&shared, &[0; 12]),
    ));
    assert_mentions(&e, &["overlap.safetensors", "tensors `a`", "and `b`", "overlap"]);
    // A config that validates but needs 17 GB: refused before any tensor is read.
    let mut huge = serde_json::to_value(&ok.config).unwrap();
    let fields = [
        ("encoding", serde_json::json!({"kind": "hash_freq", "frequencies": 4})),
        ("hash_levels", 32.into()),
        ("log2_hash_table_size", 24.into()),
        ("hash_features_per_level", 8.into()),
        ("hash_level_scale", 1.0.into()),
        ("hash_base_resolution", 4096.into()),
    ];
    for (k, v) in fields {
        huge[k] = v;
    }
    let meta = serde_json::json!({"__metadata__": {
        "format": "scribblefield-trainer", "version": "2", "step": "0", "config": huge.to_string()
    }});
    let e = err(Checkpoint::from_bytes("huge.safetensors", safetensors_of(&meta, &[])));
    assert_mentions(
        &e,
        &[
            "huge.safetensors",
            "parameters, more than the 33554432 a checkpoint may hold",
        ],
    );
}

/// Writes the `checkpoint` fuzz target's seed (a tiny field with the metadata `segment
/// --save-checkpoint` writes): `cargo test --test hostile_input_parsers -- --ignored`.
#[test]
#[ignore = "writes the seed corpus"]
fn write_checkpoint_fuzz_seed() {
    use scribblefield::saved_field::TrainedOn;
    use scribblefield::scene::label_set::{ClassInfo, LabelSet};
    let mut ck = small_checkpoint();
    let classes = (0..2)
        .map(|i| ClassInfo {
            name: format!("c{i}"),
            color: [i, 0, 0],
        })
        .collect();
    let trained = TrainedOn {
        archive: "demo.scene.zip".into(),
        frames: 2,
        width: 8,
        height: 6,
        cameras: "0".into(),
        images: "0".into(),
        seed: 1,
        labels: LabelSet::new(classes),
    };
    ck.extra = trained.to_extra();
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/checkpoint");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("seed-tiny.safetensors"), ck.to_bytes()).unwrap();
}

// ---- COLMAP's binary model ----------------------------------------------------------------

/// cameras.bin of one camera of model `model_id` with `params`, images.bin of one image with
/// translation `t`.
fn colmap_model(model_id: u32, params: &[f64], t: [f64; 3]) -> (Vec<u8>, Vec<u8>) {
    let mut cameras = Vec::new();
    for part in [
        &1u64.to_le_bytes()[..],
        &1u32.to_le_bytes(),
        &model_id.to_le_bytes(),
        &64u64.to_le_bytes(),
        &48u64.to_le_bytes(),
    ] {
        cameras.extend_from_slice(part);
    }
    params.iter().for_each(|v| cameras.extend_from_slice(&v.to_le_bytes()));
    let mut images = [&1u64.to_le_bytes()[..], &1u32.to_le_bytes()].concat();
    [1.0, 0.0, 0.0, 0.0, t[0], t[1], t[2]]
        .iter()
        .for_each(|v: &f64| images.extend_from_slice(&v.to_le_bytes()));
    for part in [&1u32.to_le_bytes()[..], b"a.jpg\0", &0u64.to_le_bytes()] {
        images.extend_from_slice(part);
    }
    (cameras, images)
}

#[test]
fn colmap_binary_garbage_and_huge_point_counts_are_refused() {
    let no_points = 0u64.to_le_bytes();
    let pinhole = [50.0, 50.0, 32.0, 24.0];
    let (c, i) = colmap_model(1, &pinhole, [0.0; 3]);
    assert_eq!(text_checks::colmap_binary(&c, &i, &no_points).unwrap(), 1);
    // Finite in f64, infinite in f32: refused as the other importers refuse such a pose.
    let (c, i) = colmap_model(1, &pinhole, [1e300, 0.0, 0.0]);
    let e = err(text_checks::colmap_binary(&c, &i, &no_points));
    assert_mentions(&e, &["images.bin", "image 1 (a.jpg)", "outside the 32-bit float range"]);
    // OPENCV (model 4) with k1 = 1e300.
    let (c, i) = colmap_model(4, &[50.0, 50.0, 32.0, 24.0, 1e300, 0.0, 0.0, 0.0], [0.0; 3]);
    let e = err(text_checks::colmap_binary(&c, &i, &no_points));
    assert_mentions(
        &e,
        &["cameras.bin", "camera 1: distortion k1 = 1e300 is outside [-10, 10]"],
    );
    // More points than a model may hold: refused from the count, before any is built.
    let (c, i) = colmap_model(1, &pinhole, [0.0; 3]);
    let n = 2_000_001u64;
    let mut points = vec![0u8; 8 + n as usize * 51];
    points[..8].copy_from_slice(&n.to_le_bytes());
    let e = err(text_checks::colmap_binary(&c, &i, &points));
    assert_mentions(&e, &["points3D.bin", "2000001 3D points, more than the 2000000"]);
}

// ---- capture folders --------------------------------------------------------------------

fn png_bytes(w: u32, h: u32) -> Vec<u8> {
    let img = image::RgbImage::from_pixel(w, h, image::Rgb([90, 20, 30]));
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// A transforms.json capture in `dir` of frames `names` (each image `<name>.png`), `w` x `h`.
fn transforms_capture(dir: &Path, names: &[String], (w, h): (u32, u32)) {
    let frames: Vec<serde_json::Value> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            serde_json::json!({"file_path": format!("{n}.png"),
                "transform_matrix": [[1, 0, 0, i as f64 * 0.1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]})
        })
        .collect();
    let json = serde_json::json!({"fl_x": w, "fl_y": w, "cx": w / 2, "cy": h / 2, "w": w, "h": h, "frames": frames});
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("transforms.json"), json.to_string()).unwrap();
}

#[cfg(unix)]
#[test]
fn capture_files_that_are_not_regular_files_are_refused_without_reading() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("cap");
    let names = vec!["a".to_string(), "b".to_string()];
    transforms_capture(&cap, &names, (8, 6));
    std::fs::write(cap.join("a.png"), png_bytes(8, 6)).unwrap();
    std::os::unix::fs::symlink("/dev/zero", cap.join("b.png")).unwrap();
    let e = err(import(&cap, &ImportOptions::default(), &mut |_, _| {}));
    assert_mentions(&e, &["b.png", "a character device, not a regular file"]);
    std::fs::remove_file(cap.join("b.png")).unwrap();
    let made = std::process::Command::new("mkfifo").arg(cap.join("b.png")).status();
    if made.is_ok_and(|s| s.success()) {
        let e = err(import(&cap, &ImportOptions::default(), &mut |_, _| {}));
        assert_mentions(&e, &["b.png", "a FIFO (named pipe), not a regular file"]);
    }
}

/// A PNG of `w` x `h` that holds its header and a token of data: enough for its size to be read.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    fn crc(bytes: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in bytes {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }
    let chunk = |kind: &[u8], data: &[u8]| {
        let body = [kind, data].concat();
        [&(data.len() as u32).to_be_bytes()[..], &body, &crc(&body).to_be_bytes()].concat()
    };
    let ihdr = [&w.to_be_bytes()[..], &h.to_be_bytes(), &[8, 2, 0, 0, 0]].concat();
    [
        &b"\x89PNG\r\n\x1a\n"[..],
        &chunk(b"IHDR", &ihdr),
        &chunk(b"IDAT", &[0x78, 0x9c]),
        &chunk(b"IEND", &[]),
    ]
    .concat()
}

#[test]
fn the_decoded_budget_is_checked_from_image_headers_before_decoding() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("big");
    let names: Vec<String> = (0..8).map(|i| format!("f{i}")).collect();
    transforms_capture(&cap, &names, (8192, 8192));
    for n in &names {
        std::fs::write(cap.join(format!("{n}.png")), png_header_only(8192, 8192)).unwrap();
    }
    let start = Instant::now();
    let e = err(import(&cap, &ImportOptions::default(), &mut |_, _| {}));
    assert!(start.elapsed() < Duration::from_secs(5), "{:?}", start.elapsed());
    assert_mentions(&e, &["f0.png", "8 frames of 8192x8192 decode to", "before decoding"]);
}

#[cfg(unix)]
#[test]
fn links_to_folders_among_the_photos_are_not_walked() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("linked");
    let sparse = cap.join("sparse/0");
    std::fs::create_dir_all(&sparse).unwrap();
    std::fs::create_dir_all(cap.join("images")).unwrap();
    let (c, i) = colmap_model(1, &[50.0, 50.0, 32.0, 24.0], [0.0; 3]);
    std::fs::write(sparse.join("cameras.bin"), c).unwrap();
    std::fs::write(sparse.join("images.bin"), i).unwrap();
    std::fs::write(sparse.join("points3D.bin"), 0u64.to_le_bytes()).unwrap();
    let img = image::RgbImage::from_pixel(64, 48, image::Rgb([90, 20, 30]));
    img.save(cap.join("images/a.jpg")).unwrap();
    img.save(cap.join("images/b.jpg")).unwrap();
    // 30 links to the folder itself: 30^4 folders to walk if links were followed.
    for k in 0..30 {
        std::os::unix::fs::symlink(".", cap.join(format!("images/l{k:02}"))).unwrap();
    }
    let start = Instant::now();
    let _ = import(&cap, &ImportOptions::default(), &mut |_, _| {});
    assert!(start.elapsed() < Duration::from_secs(10), "{:?}", start.elapsed());
}

// ---- privacy ----------------------------------------------------------------------------

#[test]
fn archives_name_the_capture_folder_never_a_path_of_the_packing_machine() {
    let tmp = tempfile::tempdir().unwrap();
    let cap = tmp.path().join("kitchen");
    let names = vec!["a".to_string(), "b".to_string()];
    transforms_capture(&cap, &names, (8, 6));
    for n in &names {
        std::fs::write(cap.join(format!("{n}.png")), png_bytes(8, 6)).unwrap();
    }
    let scene = import(&cap, &ImportOptions::default(), &mut |_, _| {}).unwrap().scene;
    assert_eq!(scene.provenance.source, "kitchen");
    let machine = tmp.path().display().to_string();
    let summary = scene.summary();
    assert!(!summary.contains(&machine), "{summary}");
    for n in &scene.provenance.notes {
        assert!(!n.contains(&machine), "{n}");
    }
    // An archive packed before this holds an absolute path: `info` shows its last name only.
    let mut old = scene;
    old.provenance.source = "/home/ana/scans/kitchen".into();
    old.provenance.notes = vec!["skipped 1 frame (first: /home/ana/scans/kitchen/pose/3.txt)".into()];
    let summary = old.summary();
    assert!(!summary.contains("/home/ana"), "{summary}");
    assert!(
        summary.contains(".../kitchen") && summary.contains(".../3.txt"),
        "{summary}"
    );
}
