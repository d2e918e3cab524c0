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
