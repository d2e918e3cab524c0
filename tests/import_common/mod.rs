//! Helpers shared by the importer tests: finding the real data, copying parts of it into a
//! temporary folder to damage, and writing small images.
#![allow(dead_code)]
use std::path::{Path, PathBuf};

use image::{GrayImage, ImageBuffer, Luma, RgbImage, RgbaImage};

/// A capture from ../shared/data, or None (with a loud message) where it is absent.
pub fn real_data(name: &str) -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(name);
    if dir.is_dir() {
        Some(dir)
    } else {
        eprintln!(
            "\n!!! SKIPPING: real data {} is absent; this test checks nothing here !!!\n",
            dir.display()
        );
        None
    }
}

/// Copies `files` (paths relative to `from`) into `to`, creating folders as needed.
pub fn copy_files(from: &Path, to: &Path, files: &[&str]) {
    for f in files {
        let dst = to.join(f);
        std::fs::create_dir_all(dst.parent().unwrap()).unwrap();
        std::fs::copy(from.join(f), &dst).unwrap_or_else(|e| panic!("copy {f}: {e}"));
    }
}

pub fn write(path: &Path, contents: impl AsRef<[u8]>) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, contents).unwrap();
}

/// Cuts a file to half its length, as an interrupted copy would.
pub fn truncate_half(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    std::fs::write(path, &bytes[..bytes.len() / 2]).unwrap();
}

/// A colourful test pattern that differs per `seed`.
pub fn pattern_rgb(w: u32, h: u32, seed: u32) -> RgbImage {
    RgbImage::from_fn(w, h, |x, y| {
        image::Rgb([(x * 7 + seed) as u8, (y * 11 + seed * 3) as u8, ((x ^ y) * 5) as u8])
    })
}

pub fn save_rgb(path: &Path, img: &RgbImage) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    img.save(path).unwrap();
}

pub fn save_rgba(path: &Path, img: &RgbaImage) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    img.save(path).unwrap();
}

pub fn save_gray8(path: &Path, img: &GrayImage) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    img.save(path).unwrap();
}

pub fn save_gray16(path: &Path, img: &ImageBuffer<Luma<u16>, Vec<u16>>) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    img.save(path).unwrap();
}

/// Writes a 4x4 row-major matrix as a pose text file.
pub fn write_matrix(path: &Path, m: &[f64; 16]) {
    let text: String = m
        .chunks(4)
        .map(|r| format!("{} {} {} {}\n", r[0], r[1], r[2], r[3]))
        .collect();
    write(path, text);
}

/// Asserts `result` is an error whose message contains every one of `needles`; returns it.
#[track_caller]
pub fn expect_err<T>(result: Result<T, scribblefield::scene::SceneError>, needles: &[&str]) -> String {
    let msg = match result {
        Ok(_) => panic!("expected an error mentioning {needles:?}, but the import succeeded"),
        Err(e) => e.to_string(),
    };
    eprintln!("error as the user sees it: {msg}");
    for n in needles {
        assert!(msg.contains(n), "error {msg:?} does not mention {n:?}");
    }
    msg
}

/// Asserts a depth reading in metres, to within float rounding of millimetres times 0.001.
#[track_caller]
pub fn assert_metres(got: Option<f64>, expected: f64) {
    match got {
        Some(m) => assert!((m - expected).abs() < 1e-9, "depth {m} m, expected {expected} m"),
        None => panic!("no depth reading, expected {expected} m"),
    }
}

/// Every file under `dir` by its path from `dir`'s parent, as the page holds a picked folder.
pub fn folder_in_memory(dir: &Path) -> scribblefield::scene::import::MemoryFiles {
    let root = dir.file_name().unwrap().to_string_lossy().into_owned();
    let mut files = scribblefield::scene::import::MemoryFiles::new();
    let mut stack = vec![(dir.to_path_buf(), root)];
    while let Some((folder, prefix)) = stack.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            let name = format!("{prefix}/{}", path.file_name().unwrap().to_string_lossy());
            if path.is_dir() {
                stack.push((path, name));
            } else {
                files.add(&name, std::fs::read(&path).unwrap()).unwrap();
            }
        }
    }
    files
}

/// Copies one file, creating its folder.
pub fn copy_file(from: &Path, to: &Path) {
    std::fs::create_dir_all(to.parent().unwrap()).unwrap();
    std::fs::copy(from, to).unwrap_or_else(|e| panic!("copy {}: {e}", from.display()));
}

/// A 4x4 matrix written as 16 numbers (a capture's pose file).
pub fn read_matrix(path: &Path) -> scribblefield::scene::Pose {
    let v: Vec<f64> = std::fs::read_to_string(path)
        .unwrap()
        .split_whitespace()
        .map(|w| w.parse().unwrap())
        .collect();
    scribblefield::scene::Pose::from_row_major(&v.try_into().unwrap())
}

/// Frame 0's ground truth `source` (a `classes`-class map at `scene`'s size) carried to every
/// other frame of `scene` through its depth, intrinsics and poses (back-projected, moved,
/// projected; the nearest wins where several land on one pixel), scored against `truth`'s
/// ground truth of those frames: mean IoU. What an importer decides (where each pixel lies)
/// without training a field.
pub fn carried_ground_truth_iou(
    scene: &scribblefield::scene::Scene,
    source: &GrayImage,
    truth: &scribblefield::scene::Scene,
    classes: usize,
) -> f64 {
    let (w, h) = (scene.width, scene.height);
    let k = scene.intrinsics;
    let depth = scene.frames[0].depth.as_ref().unwrap();
    let mut counts = vec![(0usize, 0usize); classes];
    for j in 1..scene.frames.len() {
        let to_camera = scene.frames[j].pose.inverse();
        let mut carried = vec![(f64::INFINITY, u8::MAX); (w * h) as usize];
        for (x, y, d) in depth.enumerate_pixels() {
            if d.0[0] == 0 {
                continue;
            }
            let world = scene.frames[0]
                .pose
                .transform_point(k.ray_dir(x as f64, y as f64) * (d.0[0] as f64 * scene.depth_scale));
            let p = to_camera.transform_point(world);
            let (u, v) = ((k.fx * p.x / p.z + k.cx).round(), (k.fy * p.y / p.z + k.cy).round());
            if p.z <= 0.0 || u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
                continue;
            }
            let at = &mut carried[(v as u32 * w + u as u32) as usize];
            if p.z < at.0 {
                *at = (p.z, source.get_pixel(x, y).0[0]);
            }
        }
        let truth = truth.frames[j].gt.as_ref().unwrap();
        for ((_, label), t) in carried.iter().zip(truth.pixels()) {
            for (c, (hit, union)) in counts.iter_mut().enumerate() {
                let (l, t) = (*label as usize == c, t.0[0] as usize == c);
                *hit += usize::from(l && t);
                *union += usize::from(l || t);
            }
        }
    }
    counts.iter().map(|(h, u)| *h as f64 / (*u).max(1) as f64).sum::<f64>() / classes as f64
}

/// Runs the import of `dir` with the default options and returns its error, which must name
/// `file`.
pub fn error_naming(dir: &Path, file: &str) -> String {
    let e = scribblefield::scene::import::import(
        dir,
        &scribblefield::scene::import::ImportOptions::default(),
        &mut |_, _| {},
    )
    .map(|_| ())
    .unwrap_err()
    .to_string();
    assert!(e.contains(file), "the error should name {file}: {e}");
    e
}
