//! The 7-Scenes importer on the real subset and on damaged copies of it.
mod import_common;

use std::path::Path;

use glam::DVec3;
use image::{GrayImage, ImageBuffer, Luma};
use import_common::*;
use scribblefield::scene::import::{ImportOptions, Layout, detect_layout, import};
use scribblefield::scene::{Pose, Scene};

const SEVEN: &str = "7scenes-subset";

fn no_progress() -> impl FnMut(usize, usize) {
    |_, _| {}
}

fn frame_files(n: u32) -> Vec<String> {
    ["color.jpg", "depth.png", "pose.txt"]
        .iter()
        .map(|s| format!("frame-{:06}.{s}", n * 10))
        .collect()
}

/// The first two frames and the intrinsics, copied into a temporary folder.
fn two_frame_copy(src: &Path) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let mut files: Vec<String> = frame_files(0).into_iter().chain(frame_files(1)).collect();
    files.push("camera-intrinsics.txt".into());
    copy_files(src, tmp.path(), &files.iter().map(String::as_str).collect::<Vec<_>>());
    tmp
}

fn inside(s: &Scene, p: DVec3) -> bool {
    (0..3).all(|i| s.bounds.min[i] <= p[i] && p[i] <= s.bounds.max[i])
}

#[test]
fn seven_scenes_imports_poses_depth_and_intrinsics() {
    let Some(dir) = real_data(SEVEN) else { return };
    assert_eq!(detect_layout(&dir).unwrap(), Layout::SevenScenes);
    let opts = ImportOptions {
        max_frames: Some(3),
        ..Default::default()
    };
    let imported = import(&dir, &opts, &mut no_progress()).unwrap();
    assert_eq!(imported.layout, Layout::SevenScenes);
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let s = &imported.scene;
    assert_eq!(s.frames.len(), 3);
    assert_eq!((s.width, s.height), (640, 480));
    let k = s.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (585.0, 585.0, 320.0, 240.0));
    let names: Vec<&str> = s.frames.iter().map(|f| f.source.as_deref().unwrap()).collect();
    assert_eq!(names, ["frame-000000", "frame-000010", "frame-000020"]);

    // frame-000000.pose.txt is camera-to-world already.
    // (The file's 19-digit values, written as their shortest exact f64 spelling.)
    #[rustfmt::skip]
    let expected = Pose::from_row_major(&[
        0.9093129, 0.27262229, -0.31422433, -0.34045634,
        -0.27248618, 0.9610498, 0.045279626, 0.016469818,
        0.31433925, 0.044449646, 0.94820935, 0.29656917,
        0.0, 0.0, 0.0, 1.0,
    ]);
    assert_eq!(s.frames[0].pose, expected);

    // frame-000000.depth.png holds 1382 mm at the image centre.
    assert_metres(s.depth_m(0, 320, 240), 1.382);
    assert!(s.frames.iter().all(|f| inside(s, f.pose.position())));
    // The bounds hold what the centre pixel sees.
    let centre_point = s.frames[0].pose.transform_point(k.ray_dir(320.0, 240.0) * 1.382);
    assert!(inside(s, centre_point));
    assert_eq!(s.provenance.importer, "7-scenes");
    assert!(s.provenance.notes.iter().any(|n| n.contains("--max-frames")));
}

#[test]
fn every_tenth_frame_at_320_pixels() {
    let Some(dir) = real_data(SEVEN) else { return };
    let mut calls = 0;
    let opts = ImportOptions {
        max_size: Some(320),
        every: 10,
        max_frames: None,

        ..Default::default()
    };
    let s = import(&dir, &opts, &mut |_, total| {
        calls += 1;
        assert_eq!(total, 10);
    })
    .unwrap()
    .scene;
    assert_eq!(calls, 11);
    assert_eq!(s.frames.len(), 10);
    assert_eq!(s.frames[9].source.as_deref(), Some("frame-000900"));
    assert_eq!((s.width, s.height), (320, 240));
    let k = s.intrinsics;
    assert_eq!((k.fx, k.fy), (292.5, 292.5));
    assert_eq!(
        (k.cx, k.cy),
        (159.75, 119.75),
        "principal point scaled with pixel centres kept"
    );
    for f in &s.frames {
        assert_eq!(f.rgb.dimensions(), (320, 240));
        assert_eq!(f.depth.as_ref().unwrap().dimensions(), (320, 240));
    }
    assert!(s.frames.iter().all(|f| inside(&s, f.pose.position())), "{:?}", s.bounds);
    // A room-sized box: the subset sweeps an office corner.
    assert!(
        (0..3).all(|i| (0.5..10.0).contains(&(s.bounds.max[i] - s.bounds.min[i]))),
        "{:?}",
        s.bounds
    );
}

#[test]
fn all_hundred_frames_are_found() {
    let Some(dir) = real_data(SEVEN) else { return };
    // Tiny frames keep this fast; the count is what is checked.
    let opts = ImportOptions {
        max_size: Some(32),
        ..Default::default()
    };
    let s = import(&dir, &opts, &mut no_progress()).unwrap().scene;
    assert_eq!(s.frames.len(), 100);
    assert_eq!((s.width, s.height), (32, 24));
}

#[test]
fn depth_65535_is_stored_as_no_reading() {
    let Some(dir) = real_data(SEVEN) else { return };
    // Frames 0 and 86 (frame-000860), whose depth holds 65535 at x = 615, y = 78.
    let opts = ImportOptions {
        every: 86,
        max_frames: Some(2),
        ..Default::default()
    };
    let s = import(&dir, &opts, &mut no_progress()).unwrap().scene;
    assert_eq!(s.frames[1].source.as_deref(), Some("frame-000860"));
    let raw = image::open(dir.join("frame-000860.depth.png")).unwrap().into_luma16();
    assert_eq!(raw.get_pixel(615, 78).0[0], 65535, "the test's premise about the data");
    assert_eq!(s.depth_m(1, 615, 78), None);
    assert_eq!(s.frames[1].depth.as_ref().unwrap().get_pixel(615, 78).0[0], 0);
    assert!(
        s.frames
            .iter()
            .all(|f| f.depth.as_ref().unwrap().pixels().all(|p| p.0[0] != 65535))
    );
    assert_metres(s.depth_m(1, 320, 240), 3.357);
}

#[test]
fn missing_intrinsics_fall_back_to_the_7_scenes_defaults() {
    let Some(dir) = real_data(SEVEN) else { return };
    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("camera-intrinsics.txt")).unwrap();
    let imported = import(tmp.path(), &ImportOptions::default(), &mut no_progress()).unwrap();
    let k = imported.scene.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (585.0, 585.0, 320.0, 240.0));
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("camera-intrinsics.txt") && w.contains("585"))
    );
    assert!(
        imported
            .scene
            .provenance
            .notes
            .iter()
            .any(|n| n.contains("camera-intrinsics.txt"))
    );

    // The defaults only describe 640x480 images.
    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("camera-intrinsics.txt")).unwrap();
    for n in [0, 10] {
        save_rgb(
            &tmp.path().join(format!("frame-{n:06}.color.png")),
            &pattern_rgb(320, 240, n),
        );
        std::fs::remove_file(tmp.path().join(format!("frame-{n:06}.color.jpg"))).unwrap();
    }
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["camera-intrinsics.txt", "320x240"],
    );
}

#[test]
fn mismatched_frames_are_named() {
    let Some(dir) = real_data(SEVEN) else { return };
    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("frame-000010.pose.txt")).unwrap();
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000010.pose.txt", "missing", "2 colour frames, 1 .pose.txt"],
    );

    let tmp = two_frame_copy(&dir);
    copy_files(&dir, tmp.path(), &["frame-000020.depth.png"]);
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000020.depth.png", "no colour"],
    );
}

#[test]
fn damaged_images_are_named() {
    let Some(dir) = real_data(SEVEN) else { return };
    let tmp = two_frame_copy(&dir);
    truncate_half(&tmp.path().join("frame-000010.color.jpg"));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000010.color.jpg", "truncated"],
    );

    let tmp = two_frame_copy(&dir);
    truncate_half(&tmp.path().join("frame-000010.depth.png"));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000010.depth.png"],
    );

    let tmp = two_frame_copy(&dir);
    save_gray8(&tmp.path().join("frame-000000.depth.png"), &GrayImage::new(640, 480));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000000.depth.png", "16-bit"],
    );
}

#[test]
fn bad_poses_and_intrinsics_are_named() {
    let Some(dir) = real_data(SEVEN) else { return };
    let tmp = two_frame_copy(&dir);
    write_matrix(
        &tmp.path().join("frame-000010.pose.txt"),
        &[
            1.0, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ],
    );
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000010.pose.txt", "not rigid"],
    );

    let tmp = two_frame_copy(&dir);
    write(
        &tmp.path().join("frame-000000.pose.txt"),
        "1 0 0 0\n0 1 0 0\n0 0 1 inf\n0 0 0 1\n",
    );
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["frame-000000.pose.txt", "non-finite"],
    );

    let tmp = two_frame_copy(&dir);
    write(
        &tmp.path().join("camera-intrinsics.txt"),
        "585 0 320\n0 585 240\n0 0 1\n0 0 0\n",
    );
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["camera-intrinsics.txt", "found 12"],
    );

    let tmp = two_frame_copy(&dir);
    write(
        &tmp.path().join("camera-intrinsics.txt"),
        "585 0 320\n0 585 240\n0 0 1.0.0\n",
    );
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["camera-intrinsics.txt", "line 3", "1.0.0"],
    );
}

#[test]
fn without_any_depth_there_are_no_bounds() {
    let Some(dir) = real_data(SEVEN) else { return };
    let tmp = two_frame_copy(&dir);
    for n in [0, 10] {
        save_gray16(
            &tmp.path().join(format!("frame-{n:06}.depth.png")),
            &ImageBuffer::<Luma<u16>, _>::new(640, 480),
        );
    }
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["no valid depth", "bounds"],
    );
}

#[test]
fn unknown_and_missing_folders_are_explained() {
    let tmp = tempfile::tempdir().unwrap();
    write(&tmp.path().join("notes.txt"), "hello");
    let msg = expect_err(detect_layout(tmp.path()), &["autolabel", "7-Scenes", "transforms.json"]);
    assert!(msg.contains(&tmp.path().display().to_string()));
    expect_err(detect_layout(&tmp.path().join("nowhere")), &["nowhere", "missing"]);
    expect_err(
        detect_layout(&tmp.path().join("notes.txt")),
        &["notes.txt", "is a file"],
    );
}
