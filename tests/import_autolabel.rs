//! The autolabel importer on the real YCB-Video scene and on damaged copies of it.
mod import_common;

use std::collections::BTreeSet;
use std::path::Path;

use glam::DMat4;
use image::{GrayImage, ImageBuffer, Luma};
use import_common::*;
use scribblefield::labels::{UNLABELLED, rasterize_frame};
use scribblefield::scene::import::{ImportOptions, Layout, detect_layout, import};
use scribblefield::scene::{Pose, read_archive, write_archive};

const YCB: &str = "ycb-video-0000";

fn no_progress() -> impl FnMut(usize, usize) {
    |_, _| {}
}

/// Copies the first two frames of the YCB scene (and its text files) into a temporary folder.
fn two_frame_copy(src: &Path) -> tempfile::TempDir {
    let tmp = tempfile::tempdir().unwrap();
    let mut files = vec!["intrinsics.txt", "bbox.txt", "classes.txt"];
    let frames = [
        "rgb/00000.png",
        "depth/00000.png",
        "pose/00000.txt",
        "gt/00000.png",
        "rgb/00001.png",
        "depth/00001.png",
        "pose/00001.txt",
        "gt/00001.png",
    ];
    files.extend(frames);
    copy_files(src, tmp.path(), &files);
    tmp
}

#[test]
fn ycb_video_imports_with_depth_ground_truth_and_classes() {
    let Some(dir) = real_data(YCB) else { return };
    assert_eq!(detect_layout(&dir).unwrap(), Layout::Autolabel);
    let mut calls = Vec::new();
    let imported = import(&dir, &ImportOptions::default(), &mut |done, total| {
        calls.push((done, total))
    })
    .unwrap();
    assert_eq!(imported.layout, Layout::Autolabel);
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    assert_eq!(calls.first(), Some(&(0, 10)));
    assert_eq!(calls.last(), Some(&(10, 10)));
    let s = &imported.scene;

    assert_eq!(s.frames.len(), 10);
    assert_eq!((s.width, s.height), (640, 480));
    let k = s.intrinsics;
    assert!(
        (k.fx - 1066.778).abs() < 1e-9 && (k.fy - 1067.487).abs() < 1e-9,
        "{k:?}"
    );
    assert!(
        (k.cx - 312.9869).abs() < 1e-9 && (k.cy - 241.3109).abs() < 1e-9,
        "{k:?}"
    );

    // pose/00000.txt is world-to-camera; the scene's pose must undo it.
    #[rustfmt::skip]
    let world_to_camera = Pose::from_row_major(&[
        0.998481000, -0.042178700, 0.035459500, 0.056121574,
        0.001947550, -0.616090000, -0.787673000, 0.028512416,
        0.055069300, 0.786545000, -0.615072000, 0.603123626,
        0.0, 0.0, 0.0, 1.0,
    ]);
    let product = s.frames[0].pose.0 * world_to_camera.0;
    assert!(product.abs_diff_eq(DMat4::IDENTITY, 1e-12), "{product}");
    assert_eq!(s.frames[0].source.as_deref(), Some("00000"));
    assert_eq!(s.frames[9].source.as_deref(), Some("00009"));

    // depth/00000.png holds 539 (mm) at x = 400, y = 300, and 0 (no reading) at the centre.
    assert_metres(s.depth_m(0, 400, 300), 0.539);
    assert_eq!(s.depth_m(0, 320, 240), None);
    assert!((s.depth_scale - 0.001).abs() < 1e-15);

    let gt = s.frames[0].gt.as_ref().expect("frame 0 has ground truth");
    let present: BTreeSet<u8> = gt.pixels().map(|p| p.0[0]).collect();
    assert_eq!(present, BTreeSet::from([0, 1, 2, 3]));
    assert_eq!(gt.get_pixel(400, 300).0[0], 3, "the foam brick is at (400, 300)");
    let names: Vec<&str> = s.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["background", "009_gelatin_box", "025_mug", "061_foam_brick"]);
    let colors: BTreeSet<[u8; 3]> = s.classes.iter().map(|c| c.color).collect();
    assert_eq!(colors.len(), 4, "class colours must be distinct");

    // bbox.txt: -0.473034 -0.176181 -0.801764 0.292623 0.724193 0.250424 0.01
    assert_eq!(s.bounds.min, [-0.473034, -0.176181, -0.801764]);
    assert_eq!(s.bounds.max, [0.292623, 0.724193, 0.250424]);
    assert!(s.labels.is_none());

    assert_eq!(s.provenance.importer, "autolabel");
    assert!(s.provenance.tool.starts_with("scribblefield "), "{}", s.provenance.tool);
    assert!(s.provenance.source.ends_with(YCB), "{}", s.provenance.source);

    // What imports also archives, and reads back the same.
    let bytes = write_archive(s, std::io::Cursor::new(Vec::new())).unwrap().into_inner();
    assert_same_scene(&read_archive(&bytes, "ycb.scene.zip").unwrap(), s);
}

/// Equal scenes, except that poses may differ in the last bit: serde_json parses floats to
/// within one unit in the last place unless its `float_roundtrip` feature is on.
fn assert_same_scene(a: &scribblefield::scene::Scene, b: &scribblefield::scene::Scene) {
    assert_eq!(a.frames.len(), b.frames.len());
    for (fa, fb) in a.frames.iter().zip(&b.frames) {
        assert!(fa.pose.0.abs_diff_eq(fb.pose.0, 1e-15));
        assert!(fa.rgb == fb.rgb && fa.depth == fb.depth && fa.gt == fb.gt && fa.source == fb.source);
    }
    let mut a = a.clone();
    for (fa, fb) in a.frames.iter_mut().zip(&b.frames) {
        fa.pose = fb.pose;
    }
    assert_eq!(&a, b);
}

#[test]
fn max_size_scales_images_intrinsics_and_keeps_class_ids() {
    let Some(dir) = real_data(YCB) else { return };
    let opts = ImportOptions {
        max_size: Some(320),
        every: 3,
        max_frames: Some(2),

        ..Default::default()
    };
    let imported = import(&dir, &opts, &mut no_progress()).unwrap();
    let s = &imported.scene;
    assert_eq!(s.frames.len(), 2);
    assert_eq!(s.frames[1].source.as_deref(), Some("00003"));
    assert_eq!((s.width, s.height), (320, 240));
    assert!((s.intrinsics.fx - 1066.778 / 2.0).abs() < 1e-9);
    assert!((s.intrinsics.cx - ((312.9869 + 0.5) / 2.0 - 0.5)).abs() < 1e-9);
    for f in &s.frames {
        assert_eq!(f.rgb.dimensions(), (320, 240));
        assert_eq!(f.depth.as_ref().unwrap().dimensions(), (320, 240));
        let gt = f.gt.as_ref().unwrap();
        assert_eq!(gt.dimensions(), (320, 240));
        assert!(
            gt.pixels().all(|p| p.0[0] <= 3),
            "nearest sampling must not invent class ids"
        );
    }
    // Nearest sampling: output pixel (200, 150) has its centre over source pixel (401, 301),
    // whose reading is 539 mm: copied, never blended with neighbours.
    assert_metres(s.depth_m(0, 200, 150), 0.539);
    assert!(
        s.provenance
            .notes
            .iter()
            .any(|n| n.contains("resized from 640x480 to 320x240")),
        "{:?}",
        s.provenance.notes
    );
    assert!(s.provenance.notes.iter().any(|n| n.contains("--every")));
}

#[test]
fn semantic_scribbles_become_shipped_labels() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    // autolabel writes class c as c + 1; 0 is unlabelled. One 8-bit mask, one 16-bit mask.
    let mut mask8 = GrayImage::new(640, 480);
    for x in 100..140 {
        mask8.put_pixel(x, 50, Luma([2]));
    }
    mask8.put_pixel(400, 300, Luma([4]));
    save_gray8(&tmp.path().join("semantic/00000.png"), &mask8);
    let mut mask16 = ImageBuffer::<Luma<u16>, Vec<u16>>::new(640, 480);
    mask16.put_pixel(10, 20, Luma([1]));
    save_gray16(&tmp.path().join("semantic/00001.png"), &mask16);

    let s = import(tmp.path(), &ImportOptions::default(), &mut no_progress())
        .unwrap()
        .scene;
    let labels = s.labels.as_ref().expect("scribbles become labels");
    assert_eq!(labels.classes, s.classes);
    assert_eq!(labels.classes.len(), 4);
    let map = rasterize_frame(labels.frame(0), 640, 480);
    let labelled: Vec<(usize, u16)> = map
        .iter()
        .copied()
        .enumerate()
        .filter(|&(_, v)| v != UNLABELLED)
        .collect();
    let mut expected: Vec<(usize, u16)> = (100..140).map(|x| (50 * 640 + x, 1)).collect();
    expected.push((300 * 640 + 400, 3));
    assert_eq!(labelled, expected);
    let map1 = rasterize_frame(labels.frame(1), 640, 480);
    assert_eq!(map1[20 * 640 + 10], 0);
    assert_eq!(map1.iter().filter(|&&v| v != UNLABELLED).count(), 1);

    // Scribbles survive the archive.
    let bytes = write_archive(&s, std::io::Cursor::new(Vec::new()))
        .unwrap()
        .into_inner();
    assert_same_scene(&read_archive(&bytes, "x").unwrap(), &s);
}

#[test]
fn scribbles_of_classes_beyond_classes_txt_are_an_error() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    let mut mask = GrayImage::new(640, 480);
    mask.put_pixel(1, 1, Luma([9]));
    save_gray8(&tmp.path().join("semantic/00000.png"), &mask);
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["semantic", "class 8"],
    );
}

#[test]
fn missing_folders_and_files_are_named() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("depth/00001.png")).unwrap();
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["00001.png", "depth", "2 images"],
    );

    let tmp = two_frame_copy(&dir);
    std::fs::remove_dir_all(tmp.path().join("pose")).unwrap();
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["pose/", "missing"],
    );

    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("intrinsics.txt")).unwrap();
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["intrinsics.txt", "missing"],
    );

    // A pose with no colour image: the counts do not match.
    let tmp = two_frame_copy(&dir);
    std::fs::copy(tmp.path().join("pose/00001.txt"), tmp.path().join("pose/00002.txt")).unwrap();
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["pose/00002.txt", "no colour image"],
    );
}

#[test]
fn a_missing_bbox_is_estimated_from_depth() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    std::fs::remove_file(tmp.path().join("bbox.txt")).unwrap();
    let imported = import(tmp.path(), &ImportOptions::default(), &mut no_progress()).unwrap();
    assert!(
        imported.warnings.iter().any(|w| w.contains("bbox.txt")),
        "{:?}",
        imported.warnings
    );
    let s = &imported.scene;
    let b = s.bounds;
    let inside = |p: [f64; 3]| (0..3).all(|i| b.min[i] <= p[i] && p[i] <= b.max[i]);
    // The estimate holds the cameras and the middle of the bbox.txt written from the same depth,
    // and is of a similar size (it also holds the cameras, which bbox.txt does not).
    assert!(s.frames.iter().all(|f| inside(f.pose.position().to_array())), "{b:?}");
    let given = ([-0.473034, -0.176181, -0.801764], [0.292623, 0.724193, 0.250424]);
    assert!(inside([0, 1, 2].map(|i| (given.0[i] + given.1[i]) / 2.0)), "{b:?}");
    for i in 0..3 {
        let (size, given_size) = (b.max[i] - b.min[i], given.1[i] - given.0[i]);
        assert!(size > 0.5 * given_size && size < 2.0 * given_size, "axis {i}: {b:?}");
    }
}

#[test]
fn empty_scene_is_an_error() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    for sub in ["rgb", "depth", "pose", "gt"] {
        std::fs::remove_dir_all(tmp.path().join(sub)).unwrap();
        std::fs::create_dir(tmp.path().join(sub)).unwrap();
    }
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["rgb", "no frames"],
    );
}

#[test]
fn unreadable_and_truncated_images_are_named() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    truncate_half(&tmp.path().join("rgb/00001.png"));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["rgb/00001.png"],
    );

    let tmp = two_frame_copy(&dir);
    write(&tmp.path().join("depth/00000.png"), b"this is not a PNG at all");
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["depth/00000.png"],
    );

    let tmp = two_frame_copy(&dir);
    write(&tmp.path().join("rgb/00000.png"), b"");
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["rgb/00000.png", "empty"],
    );
}

#[test]
fn depth_of_wrong_bit_depth_or_size_is_rejected() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    save_gray8(&tmp.path().join("depth/00001.png"), &GrayImage::new(640, 480));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["depth/00001.png", "16-bit"],
    );

    let tmp = two_frame_copy(&dir);
    save_gray16(&tmp.path().join("depth/00001.png"), &ImageBuffer::new(640, 360));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["depth/00001.png", "640x360"],
    );

    // Same field of view at a lower resolution (as phone depth sensors record it) is resampled.
    let tmp = two_frame_copy(&dir);
    let mut low = ImageBuffer::<Luma<u16>, Vec<u16>>::new(160, 120);
    low.put_pixel(100, 75, Luma([1234]));
    save_gray16(&tmp.path().join("depth/00001.png"), &low);
    let imported = import(tmp.path(), &ImportOptions::default(), &mut no_progress()).unwrap();
    let s = &imported.scene;
    assert_eq!(s.frames[1].depth.as_ref().unwrap().dimensions(), (640, 480));
    // Each low-resolution pixel covers 4x4 full-resolution pixels.
    assert_metres(s.depth_m(1, 401, 301), 1.234);
    assert_eq!(s.depth_m(1, 404, 301), None);
    assert!(s.provenance.notes.iter().any(|n| n.contains("resampled")));
}

#[test]
fn colour_images_of_different_sizes_are_rejected() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    save_rgb(&tmp.path().join("rgb/00001.png"), &pattern_rgb(320, 240, 1));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["rgb/00001.png", "320x240"],
    );
}

#[test]
fn bad_poses_are_rejected() {
    let Some(dir) = real_data(YCB) else { return };
    let cases: [(&str, &[&str]); 4] = [
        (
            "1 0 0 0\n0 1 0 0\n0 0 1 nan\n0 0 0 1\n",
            &["pose/00001.txt", "non-finite"],
        ),
        ("2 0 0 0\n0 2 0 0\n0 0 2 0\n0 0 0 1\n", &["pose/00001.txt", "not rigid"]),
        ("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n", &["pose/00001.txt", "found 15"]),
        (
            "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 one\n",
            &["pose/00001.txt", "line 4", "\"one\""],
        ),
    ];
    for (text, needles) in cases {
        let tmp = two_frame_copy(&dir);
        write(&tmp.path().join("pose/00001.txt"), text);
        expect_err(
            import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
            needles,
        );
    }
}

#[test]
fn unparsable_intrinsics_and_bbox_are_rejected() {
    let Some(dir) = real_data(YCB) else { return };
    let cases: [(&str, &str, &[&str]); 5] = [
        (
            "intrinsics.txt",
            "1066 0 312\n0 1067 241\n",
            &["intrinsics.txt", "found 6 numbers"],
        ),
        (
            "intrinsics.txt",
            "fx 0 312\n0 1067 241\n0 0 1\n",
            &["intrinsics.txt", "line 1", "\"fx\""],
        ),
        (
            "intrinsics.txt",
            "0 0 312\n0 1067 241\n0 0 1\n",
            &["intrinsics.txt", "positive"],
        ),
        ("bbox.txt", "1 1 1 0 0 0\n", &["bbox.txt", "min must be below max"]),
        ("bbox.txt", "1 2 3\n", &["bbox.txt", "found 3 numbers"]),
    ];
    for (file, text, needles) in cases {
        let tmp = two_frame_copy(&dir);
        write(&tmp.path().join(file), text);
        expect_err(
            import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
            needles,
        );
    }
}

#[test]
fn ground_truth_must_be_8_bit_ids_of_known_classes() {
    let Some(dir) = real_data(YCB) else { return };
    let tmp = two_frame_copy(&dir);
    let mut gt = GrayImage::new(640, 480);
    gt.put_pixel(5, 5, Luma([7]));
    save_gray8(&tmp.path().join("gt/00001.png"), &gt);
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["gt/00001.png", "class id 7"],
    );

    let tmp = two_frame_copy(&dir);
    save_gray16(&tmp.path().join("gt/00000.png"), &ImageBuffer::new(640, 480));
    expect_err(
        import(tmp.path(), &ImportOptions::default(), &mut no_progress()),
        &["gt/00000.png", "8-bit"],
    );

    // Void (255) is always allowed; without classes.txt the classes are numbered.
    let tmp = two_frame_copy(&dir);
    let mut gt = GrayImage::new(640, 480);
    gt.put_pixel(5, 5, Luma([255]));
    save_gray8(&tmp.path().join("gt/00001.png"), &gt);
    std::fs::remove_file(tmp.path().join("classes.txt")).unwrap();
    let imported = import(tmp.path(), &ImportOptions::default(), &mut no_progress()).unwrap();
    let names: Vec<&str> = imported.scene.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["class 0", "class 1", "class 2", "class 3"]);
    assert!(imported.warnings.iter().any(|w| w.contains("classes.txt")));
}

#[test]
fn zero_options_are_rejected() {
    let Some(dir) = real_data(YCB) else { return };
    let bad = [
        (
            ImportOptions {
                every: 0,
                ..Default::default()
            },
            "--every",
        ),
        (
            ImportOptions {
                max_frames: Some(0),
                ..Default::default()
            },
            "--max-frames",
        ),
        (
            ImportOptions {
                max_size: Some(0),
                ..Default::default()
            },
            "--max-size",
        ),
    ];
    for (opts, needle) in bad {
        expect_err(import(&dir, &opts, &mut no_progress()), &[needle]);
    }
}
