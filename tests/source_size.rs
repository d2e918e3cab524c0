//! `segment --source`: masks at the capture's resolution. The demo scene, written out as an
//! autolabel capture at 96 x 72, is packed at `--max-size 48` (48 x 36), trained briefly on the
//! GPU (lavapipe in CI) and segmented twice with the same seed: at the archive's size and with
//! `--source` at the capture's. The capture-size masks must be 96 x 72 and agree with the
//! archive-size masks upsampled on most pixels. Then the bad inputs: another capture (other
//! poses), a capture missing a frame, a folder that is no capture.
mod cli_support;

use std::path::{Path, PathBuf};

use cli_support::{fails, ok, run, write_autolabel};
use image::GrayImage;
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::scene::demo::{DemoOptions, demo_scene};

const SOURCE: (u32, u32) = (96, 72);
const ARCHIVE: (u32, u32) = (48, 36);
const FRAMES: u32 = 12;

fn capture(dir: &Path, seed: u64) -> PathBuf {
    let scene = demo_scene(&DemoOptions {
        seed,
        width: SOURCE.0,
        height: SOURCE.1,
        frames: FRAMES,
    })
    .unwrap();
    write_autolabel(&scene, dir);
    dir.to_path_buf()
}

fn mask(dir: &Path, i: usize) -> GrayImage {
    image::open(dir.join(format!("{i:05}.png"))).unwrap().into_luma8()
}

#[test]
fn masks_at_the_capture_size_agree_with_the_archive_size() {
    let Some(_ctx) = gpu_for_tests("masks_at_the_capture_size_agree_with_the_archive_size") else {
        return;
    };
    drop(_ctx);
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = |name: &str| d.join(name).to_str().unwrap().to_string();
    let cap = capture(&d.join("capture"), 0);
    let cap = cap.to_str().unwrap();
    let t = ok(&run(&[
        "pack",
        cap,
        "-o",
        &path("s.scene.zip"),
        "--max-size",
        "48",
        "--no-features",
    ]));
    assert!(t.contains(&format!("{} x {}", ARCHIVE.0, ARCHIVE.1)), "{t}");
    ok(&run(&[
        "scribble-from-gt",
        &path("s.scene.zip"),
        "--frames",
        "0,6",
        "-o",
        &path("l.json"),
    ]));
    // Small enough for lavapipe: the point is the path and the agreement, not the quality.
    let config = r#"{"hash_levels": 4, "log2_hash_table_size": 12, "density_width": 16, "color_width": 16,
        "feature_width": 16, "semantic_width": 16, "samples_coarse": 4, "samples_fine": 12, "batch_rays": 256}"#;
    std::fs::write(d.join("c.json"), config).unwrap();
    let segment = |out: &str, extra: &[&str]| {
        let (scene, labels, out, cfg) = (path("s.scene.zip"), path("l.json"), path(out), path("c.json"));
        let mut args = vec![
            "segment", &scene, "--labels", &labels, "-o", &out, "--preset", "tiny", "--config", &cfg, "--warmup", "10",
            "--steps", "60",
        ];
        args.extend_from_slice(extra);
        run(&args)
    };

    let started = std::time::Instant::now();
    let t = ok(&segment("small", &[]));
    assert!(t.contains("wrote 12 masks of 48 x 36 (the archive's resolution"), "{t}");
    let t = ok(&segment("full", &["--source", cap]));
    eprintln!("{t}\nboth segment runs: {:.1} s", started.elapsed().as_secs_f64());
    assert!(
        t.contains("all 12 frames found with the archive's poses; masks at 96 x 72 (the archive is 48 x 36)"),
        "{t}"
    );
    assert!(t.contains("wrote 12 masks of 96 x 72 (the capture's resolution"), "{t}");
    assert!(
        t.contains("scored against the capture's ground truth at 96 x 72"),
        "{t}"
    );

    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("full/classes.json")).unwrap()).unwrap();
    assert_eq!(
        (manifest["width"].as_u64(), manifest["height"].as_u64()),
        (Some(96), Some(72))
    );
    assert_eq!(manifest["frames"].as_u64(), Some(12));
    assert!(d.join("full/preview/00011.png").is_file() && d.join("full/labels.json").is_file());
    let (mut equal, mut total) = (0usize, 0usize);
    for i in 0..FRAMES as usize {
        let (full, small) = (mask(&d.join("full"), i), mask(&d.join("small"), i));
        assert_eq!(full.dimensions(), SOURCE, "frame {i}");
        assert_eq!(small.dimensions(), ARCHIVE, "frame {i}");
        for (x, y, p) in full.enumerate_pixels() {
            equal += usize::from(p.0[0] == small.get_pixel(x / 2, y / 2).0[0]);
            total += 1;
        }
    }
    let agree = equal as f64 / total as f64;
    eprintln!(
        "capture-size masks agree with the archive-size masks upsampled on {:.1} % of pixels",
        100.0 * agree
    );
    assert!(agree > 0.85, "only {:.1} % of pixels agree", 100.0 * agree);

    // Another capture of the same kind (the demo scene of another seed: other poses).
    let other = capture(&d.join("other"), 1);
    let o = segment("x1", &["--source", other.to_str().unwrap()]);
    fails(&o, &["--source", "frame 0 of", "\"00000\"", "another pose", "degrees"]);
    // The capture lost a frame.
    let lost = capture(&d.join("lost"), 0);
    for f in ["rgb/00005.png", "depth/00005.png", "pose/00005.txt", "gt/00005.png"] {
        std::fs::remove_file(lost.join(f)).unwrap();
    }
    let o = segment("x2", &["--source", lost.to_str().unwrap()]);
    fails(&o, &["frame 5 of", "\"00005\"", "is not in this capture", "11 frames"]);
    // Not a capture at all.
    std::fs::create_dir_all(d.join("empty")).unwrap();
    let o = segment("x3", &["--source", &path("empty")]);
    fails(&o, &["--source", "empty", "not a capture layout"]);
    // The same photos with another camera matrix (fx doubled).
    let zoomed = capture(&d.join("zoomed"), 0);
    let k = std::fs::read_to_string(zoomed.join("intrinsics.txt")).unwrap();
    let fx: f64 = k.split_whitespace().next().unwrap().parse().unwrap();
    std::fs::write(
        zoomed.join("intrinsics.txt"),
        k.replacen(&fx.to_string(), &(2.0 * fx).to_string(), 1),
    )
    .unwrap();
    let o = segment("x4", &["--source", zoomed.to_str().unwrap()]);
    fails(&o, &["--source", "intrinsics fx", "at 96 x 72", "s.scene.zip"]);
    // An archive not packed from a capture: the demo scene names its frames demo-000, ...
    ok(&run(&[
        "demo-scene",
        "-o",
        &path("demo.scene.zip"),
        "--size",
        "48x36",
        "--frames",
        "12",
    ]));
    let (demo, labels, out) = (path("demo.scene.zip"), path("l.json"), path("x5"));
    let o = run(&["segment", &demo, "--labels", &labels, "-o", &out, "--source", cap]);
    fails(
        &o,
        &["frame 0 of", "(\"demo-000\") is not in this capture", "12 frames"],
    );
    for out in ["x1", "x2", "x3", "x4", "x5"] {
        assert!(!d.join(out).exists(), "a refused run must not create its output folder");
    }
}

/// Times `segment --source` on a capture of 2 frames at `SCRIBBLEFIELD_SOURCE_SIZE` (default
/// 1920x1440) packed at `--max-size 160`, with the preset the adapter picks:
/// `cargo test --release --test source_size -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_masks_at_full_size() {
    let Some(ctx) = gpu_for_tests("time_masks_at_full_size") else {
        return;
    };
    drop(ctx);
    let size = std::env::var("SCRIBBLEFIELD_SOURCE_SIZE").unwrap_or_else(|_| "1920x1440".into());
    let (w, h) = size.split_once('x').expect("SCRIBBLEFIELD_SOURCE_SIZE is WxH");
    let (w, h): (u32, u32) = (w.parse().unwrap(), h.parse().unwrap());
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let path = |name: &str| d.join(name).to_str().unwrap().to_string();
    let scene = demo_scene(&DemoOptions {
        seed: 0,
        width: w,
        height: h,
        frames: 2,
    })
    .unwrap();
    write_autolabel(&scene, &d.join("capture"));
    let cap = path("capture");
    ok(&run(&[
        "pack",
        &cap,
        "-o",
        &path("s.scene.zip"),
        "--max-size",
        "160",
        "--no-features",
    ]));
    ok(&run(&[
        "scribble-from-gt",
        &path("s.scene.zip"),
        "--frames",
        "0",
        "-o",
        &path("l.json"),
    ]));
    let started = std::time::Instant::now();
    let t = ok(&run(&[
        "segment",
        &path("s.scene.zip"),
        "--labels",
        &path("l.json"),
        "-o",
        &path("m"),
        "--warmup",
        "5",
        "--steps",
        "5",
        "--source",
        &cap,
    ]));
    eprintln!(
        "{t}\nsegment --source at {w} x {h}, 2 frames: {:.1} s in all",
        started.elapsed().as_secs_f64()
    );
}
