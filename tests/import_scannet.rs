//! ScanNet SensReader exports (`color/N.jpg`, `depth/N.png`, `pose/N.txt`, `intrinsic/`), on a
//! fixture written here to that layout at an eighth of ScanNet's sizes and intrinsics (1296x968
//! colour and 640x480 depth there): no ScanNet scene is in ../shared/data.
mod import_common;

use std::path::Path;

use glam::{DMat4, DVec3};
use image::{ImageBuffer, Luma};
use import_common::*;
use scribblefield::scene::import::{ImportOptions, Imported, Layout, detect_layout, import};
use scribblefield::scene::{Intrinsics, SceneError};
use tempfile::TempDir;

const COLOR: (u32, u32) = (162, 121);
const DEPTH: (u32, u32) = (80, 60);
/// ScanNet's typical K, divided by 8 (fx, fy, cx, cy).
const K_COLOR: [f64; 4] = [146.27, 146.27, 80.97, 60.47];
const K_DEPTH: [f64; 4] = [72.2, 72.2, 39.86, 29.86];
const FRAMES: usize = 5;

type Depth16 = ImageBuffer<Luma<u16>, Vec<u16>>;

fn k4(k: [f64; 4]) -> String {
    format!("{} 0 {} 0\n0 {} {} 0\n0 0 1 0\n0 0 0 1\n", k[0], k[2], k[1], k[3])
}

/// Millimetres that tell every depth pixel apart (about 1.5-2.7 m).
fn depth_mm(u: u32, v: u32) -> u16 {
    (1500 + 10 * u + v) as u16
}

fn camera_to_world(i: usize) -> DMat4 {
    DMat4::from_rotation_y(0.1 * i as f64) * DMat4::from_translation(DVec3::new(0.2 * i as f64, 0.0, 0.0))
}

fn row_major(m: DMat4) -> [f64; 16] {
    m.transpose().to_cols_array()
}

/// A SensReader export of FRAMES frames; frame 2's pose is lost (`-inf`, as ScanNet writes).
fn scan() -> TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    for i in 0..FRAMES {
        save_rgb(
            &d.join(format!("color/{i}.jpg")),
            &pattern_rgb(COLOR.0, COLOR.1, i as u32),
        );
        let depth = Depth16::from_fn(DEPTH.0, DEPTH.1, |u, v| Luma([depth_mm(u, v)]));
        save_gray16(&d.join(format!("depth/{i}.png")), &depth);
        write_matrix(&d.join(format!("pose/{i}.txt")), &row_major(camera_to_world(i)));
    }
    write(&d.join("pose/2.txt"), "-inf -inf -inf -inf\n".repeat(4));
    write(&d.join("intrinsic/intrinsic_color.txt"), k4(K_COLOR));
    write(&d.join("intrinsic/intrinsic_depth.txt"), k4(K_DEPTH));
    // SensReader writes these too; they are not read.
    write(&d.join("intrinsic/extrinsic_color.txt"), k4([1.0, 1.0, 0.0, 0.0]));
    tmp
}

fn run_with(dir: &Path, opts: &ImportOptions) -> Result<Imported, SceneError> {
    import(dir, opts, &mut |_, _| {})
}

fn run(dir: &Path) -> Result<Imported, SceneError> {
    run_with(dir, &ImportOptions::default())
}

/// The depth pixels whose footprints a colour pixel's footprint overlaps, along one axis.
fn overlapped(x: u32, kc: f64, cc: f64, kd: f64, cd: f64, n: u32) -> Vec<u32> {
    let to_depth = |x: f64| kd * (x - cc) / kc + cd;
    let (a, b) = (to_depth(x as f64 - 0.5), to_depth(x as f64 + 0.5));
    (0..n).filter(|&u| u as f64 + 0.5 > a && (u as f64 - 0.5) < b).collect()
}

/// Depth of the registered frame where it should be: the nearest of the depth pixels the
/// colour pixel covers, found here from the colour side (the importer splats from the depth side).
/// Returns how many colour pixels cover a single depth pixel.
fn check_registration(imported: &Imported, size: (u32, u32)) -> usize {
    let s = &imported.scene;
    assert_eq!((s.width, s.height), size);
    let k: Intrinsics = s.intrinsics;
    let depth = s.frames[0].depth.as_ref().expect("registered depth");
    let (mut exact, mut holes) = (0, 0);
    for y in 0..size.1 {
        for x in 0..size.0 {
            let us = overlapped(x, k.fx, k.cx, K_DEPTH[0], K_DEPTH[2], DEPTH.0);
            let vs = overlapped(y, k.fy, k.cy, K_DEPTH[1], K_DEPTH[3], DEPTH.1);
            let expected = us
                .iter()
                .flat_map(|&u| vs.iter().map(move |&v| depth_mm(u, v)))
                .min()
                .unwrap_or(0);
            let got = depth.get_pixel(x, y).0[0];
            assert_eq!(got, expected, "pixel ({x}, {y}) of {size:?}");
            exact += usize::from(us.len() == 1 && vs.len() == 1);
            holes += usize::from(got == 0);
        }
    }
    // The colour camera sees a little more than the depth camera: a thin border has no depth.
    let pixels = (size.0 * size.1) as usize;
    assert!(holes < pixels / 10, "{holes} of {pixels} pixels without depth");
    exact
}

#[test]
fn export_packs_with_depth_registered_to_colour() {
    let tmp = scan();
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::ScanNet);
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.layout, Layout::ScanNet);
    let s = &imported.scene;
    assert_eq!(s.frames.len(), FRAMES - 1);
    let w = imported.warnings.join("\n");
    assert!(
        w.contains("skipped 1 of 5 frames whose pose is invalid") && w.contains("2.txt"),
        "{w}"
    );
    let sources: Vec<&str> = s.frames.iter().map(|f| f.source.as_deref().unwrap()).collect();
    assert_eq!(sources, ["color/0.jpg", "color/1.jpg", "color/3.jpg", "color/4.jpg"]);
    let k = s.intrinsics;
    assert_eq!(
        (k.fx, k.fy, k.cx, k.cy),
        (K_COLOR[0], K_COLOR[1], K_COLOR[2], K_COLOR[3])
    );
    assert!(s.frames[2].pose.0.abs_diff_eq(camera_to_world(3), 1e-12));
    // About half the colour pixels along each axis lie inside one depth pixel.
    let exact = check_registration(&imported, COLOR);
    assert!(exact > (COLOR.0 * COLOR.1) as usize / 8, "{exact}");
    // Near both optical axes: colour pixel (81, 60) covers depth pixels (40, 29) and (40, 30);
    // the nearer wins.
    assert_metres(s.depth_m(0, 81, 60), depth_mm(40, 29) as f64 / 1000.0);
    // Bounds hold the back-projected wall.
    let p = s.frames[0].pose.transform_point(k.ray_dir(81.0, 60.0) * 1.9);
    assert!(
        (0..3).all(|i| s.bounds.min[i] < p[i] && p[i] < s.bounds.max[i]),
        "{:?}",
        s.bounds
    );
    assert!(
        s.provenance
            .notes
            .iter()
            .any(|n| n.contains("registered to the colour camera"))
    );
}

#[test]
fn downscaled_exports_register_at_the_packed_size() {
    let tmp = scan();
    let opts = ImportOptions {
        max_size: Some(40),
        every: 2,
        ..Default::default()
    };
    let imported = run_with(tmp.path(), &opts).unwrap();
    // Frames 0, 1, 3, 4 are posed; every second of them is kept.
    let sources: Vec<&str> = imported
        .scene
        .frames
        .iter()
        .map(|f| f.source.as_deref().unwrap())
        .collect();
    assert_eq!(sources, ["color/0.jpg", "color/3.jpg"]);
    check_registration(&imported, (40, 30));
}

/// `ImportOptions::only` (what `segment --source` re-imports with) picks frames by the names
/// the archive keeps, `color/N.jpg`, and names one the export lacks or lost.
#[test]
fn frames_are_picked_by_their_source_names() {
    let tmp = scan();
    let only = |names: &[&str]| ImportOptions {
        only: Some(names.iter().map(|n| n.to_string()).collect()),
        ..Default::default()
    };
    let imported = run_with(tmp.path(), &only(&["color/4.jpg", "color/1.jpg"])).unwrap();
    let sources: Vec<&str> = imported
        .scene
        .frames
        .iter()
        .map(|f| f.source.as_deref().unwrap())
        .collect();
    assert_eq!(sources, ["color/1.jpg", "color/4.jpg"]);
    assert_eq!((imported.scene.width, imported.scene.height), COLOR);
    // Frame 2's pose is lost (-inf): it is not there to pick.
    expect_err(
        run_with(tmp.path(), &only(&["color/2.jpg"])),
        &[
            "no frame named \"color/2.jpg\"",
            "4 frames",
            "\"color/0.jpg\" ... \"color/4.jpg\"",
        ],
    );
}

/// A fresh export with `file` (relative) replaced by `contents`.
fn with_file(file: &str, contents: &str) -> TempDir {
    let tmp = scan();
    write(&tmp.path().join(file), contents);
    tmp
}

#[test]
fn bad_text_files_name_file_and_value() {
    let tmp = scan();
    std::fs::remove_file(tmp.path().join("intrinsic/intrinsic_depth.txt")).unwrap();
    expect_err(
        run(tmp.path()),
        &["intrinsic_depth.txt", "missing", "the depth camera's intrinsics"],
    );
    let tmp = with_file("intrinsic/intrinsic_color.txt", "146 0 80\n0 146 60\n0 0\n");
    expect_err(run(tmp.path()), &["intrinsic_color.txt", "found 8 numbers"]);
    let tmp = with_file("intrinsic/intrinsic_color.txt", "146 0 80\n0 146 60\n0 0 2\n");
    expect_err(run(tmp.path()), &["intrinsic_color.txt", "not a camera matrix"]);
    let tmp = with_file("intrinsic/intrinsic_color.txt", "146 0 80\n0 -146 60\n0 0 1\n");
    expect_err(
        run(tmp.path()),
        &["intrinsic_color.txt", "focal lengths must be positive", "-146"],
    );
    // ScanNet's full-size colour intrinsics beside these eighth-size images.
    let tmp = with_file("intrinsic/intrinsic_color.txt", &k4([1170.19, 1170.19, 647.75, 483.75]));
    expect_err(
        run(tmp.path()),
        &[
            "intrinsic_color.txt",
            "cx = 647.75, cy = 483.75 lies outside the 162x121 images",
        ],
    );
    let tmp = with_file("intrinsic/intrinsic_depth.txt", &k4([72.2, 72.2, 39.86, 90.0]));
    expect_err(run(tmp.path()), &["intrinsic_depth.txt", "cy = 90", "80x60"]);

    let tmp = with_file("pose/3.txt", "1 0 0 0\n0 1 abc 0\n0 0 1 0\n0 0 0 1\n");
    expect_err(run(tmp.path()), &["3.txt", "line 2", "\"abc\""]);
    let tmp = with_file("pose/3.txt", "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n");
    expect_err(run(tmp.path()), &["3.txt", "not rigid"]);
    let tmp = with_file("pose/3.txt", "1 0 0 0\n0 1 0 0\n");
    expect_err(run(tmp.path()), &["3.txt", "found 8 numbers"]);
    let tmp = scan();
    for i in 0..FRAMES {
        write(
            &tmp.path().join(format!("pose/{i}.txt")),
            "-inf -inf -inf -inf\n".repeat(4),
        );
    }
    expect_err(run(tmp.path()), &["pose", "all 5 poses are invalid"]);
}

#[test]
fn missing_and_mismatched_frames_are_named() {
    let tmp = scan();
    std::fs::remove_file(tmp.path().join("depth/3.png")).unwrap();
    expect_err(
        run(tmp.path()),
        &[
            "depth/3.png",
            "missing",
            "the depth of frame 3",
            "5 colour frames, 4 in depth/",
        ],
    );
    let tmp = scan();
    write_matrix(&tmp.path().join("pose/9.txt"), &row_major(DMat4::IDENTITY));
    expect_err(run(tmp.path()), &["pose/9.txt", "no colour image color/9.jpg"]);
    let tmp = scan();
    std::fs::remove_dir_all(tmp.path().join("pose")).unwrap();
    expect_err(
        run(tmp.path()),
        &["pose", "missing", "the pose/ folder of a ScanNet export"],
    );
    let tmp = scan();
    for i in 0..FRAMES {
        std::fs::remove_file(tmp.path().join(format!("color/{i}.jpg"))).unwrap();
    }
    expect_err(run(tmp.path()), &["color", "no colour frames"]);
}

#[test]
fn bad_images_are_named() {
    let tmp = scan();
    save_gray8(
        &tmp.path().join("depth/1.png"),
        &image::GrayImage::new(DEPTH.0, DEPTH.1),
    );
    expect_err(run(tmp.path()), &["depth/1.png", "16-bit"]);
    let tmp = scan();
    save_gray16(&tmp.path().join("depth/3.png"), &Depth16::new(DEPTH.0 / 2, DEPTH.1 / 2));
    expect_err(
        run(tmp.path()),
        &["depth/3.png", "depth is 40x30", "first depth image is 80x60"],
    );
    let tmp = scan();
    truncate_half(&tmp.path().join("color/4.jpg"));
    expect_err(run(tmp.path()), &["color/4.jpg", "truncated"]);
    let tmp = scan();
    save_rgb(
        &tmp.path().join("color/1.jpg"),
        &pattern_rgb(COLOR.0 / 2, COLOR.1 / 2, 1),
    );
    expect_err(run(tmp.path()), &["color/1.jpg", "81x60", "162x121"]);
    // No depth reading anywhere: no bounds.
    let tmp = scan();
    for i in 0..FRAMES {
        save_gray16(
            &tmp.path().join(format!("depth/{i}.png")),
            &Depth16::new(DEPTH.0, DEPTH.1),
        );
    }
    expect_err(run(tmp.path()), &["depth", "no valid depth"]);
}
