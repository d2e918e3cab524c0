//! NeRF-synthetic split folders (`transforms_train.json`, `transforms_val.json`,
//! `transforms_test.json`, RGBA PNGs named without extension), on a small fixture written here
//! to the published layout of the lego scene (no real one is in ../shared/data).
mod import_common;

use std::path::Path;

use glam::{DMat4, DVec3};
use image::{Rgba, RgbaImage};
use import_common::*;
use scribblefield::scene::import::{Background, ImportOptions, Imported, Layout, Split, detect_layout, import};
use scribblefield::scene::{GT_VOID, Pose, SceneError};
use serde_json::{Value, json};
use tempfile::TempDir;

const SIDE: u32 = 32;
/// lego's own field of view.
const ANGLE_X: f64 = 0.6911112070083618;
const SPLITS: [(&str, usize); 3] = [("train", 4), ("val", 2), ("test", 3)];
const OBJECT: [u8; 3] = [200, 50, 30];

/// Camera-to-world in OpenGL axes at `eye`, looking at the origin, world +z up (as Blender).
fn gl_look_at_origin(eye: DVec3) -> DMat4 {
    let forward = (-eye).normalize();
    let x = forward.cross(DVec3::Z).normalize();
    let z = -forward;
    let y = z.cross(x);
    DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
}

fn eye(split: usize, i: usize) -> DVec3 {
    let a = (split * 10 + i) as f64 * 0.7;
    DVec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.5)
}

fn rows(m: DMat4) -> Value {
    let r = m.transpose().to_cols_array();
    json!([
        [r[0], r[1], r[2], r[3]],
        [r[4], r[5], r[6], r[7]],
        [r[8], r[9], r[10], r[11]],
        [r[12], r[13], r[14], r[15]]
    ])
}

/// An object disc on a transparent background, its rim half transparent (antialiasing).
fn rgba_frame() -> RgbaImage {
    RgbaImage::from_fn(SIDE, SIDE, |x, y| {
        let r = ((x as f64 - 15.5).powi(2) + (y as f64 - 15.5).powi(2)).sqrt();
        let [cr, cg, cb] = OBJECT;
        if r < 8.0 {
            Rgba([cr, cg, cb, 255])
        } else if r < 10.0 {
            Rgba([cr, cg, cb, 128])
        } else {
            Rgba([0, 0, 0, 0])
        }
    })
}

/// The split's transforms document as Blender's NeRF exporter writes it.
fn split_doc(split: usize, name: &str, count: usize) -> Value {
    let frames: Vec<Value> = (0..count)
        .map(|i| {
            json!({
                "file_path": format!("./{name}/r_{i}"),
                "rotation": 0.012566370614359171,
                "transform_matrix": rows(gl_look_at_origin(eye(split, i))),
            })
        })
        .collect();
    json!({ "camera_angle_x": ANGLE_X, "frames": frames })
}

fn write_doc(dir: &Path, split: &str, doc: &Value) {
    write(
        &dir.join(format!("transforms_{split}.json")),
        serde_json::to_vec_pretty(doc).unwrap(),
    );
}

/// A lego-like folder: three splits of RGBA PNGs.
fn lego() -> TempDir {
    let tmp = tempfile::tempdir().unwrap();
    for (s, (name, count)) in SPLITS.iter().enumerate() {
        for i in 0..*count {
            save_rgba(&tmp.path().join(format!("{name}/r_{i}.png")), &rgba_frame());
        }
        write_doc(tmp.path(), name, &split_doc(s, name, *count));
    }
    tmp
}

fn run_with(dir: &Path, opts: &ImportOptions) -> Result<Imported, SceneError> {
    import(dir, opts, &mut |_, _| {})
}

fn run(dir: &Path) -> Result<Imported, SceneError> {
    run_with(dir, &ImportOptions::default())
}

#[test]
fn all_splits_pack_in_order_on_white() {
    let tmp = lego();
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::NerfSplits);
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.layout, Layout::NerfSplits);
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let s = &imported.scene;
    assert_eq!(s.frames.len(), 9);
    let sources: Vec<&str> = s.frames.iter().map(|f| f.source.as_deref().unwrap()).collect();
    assert_eq!(sources[0], "./train/r_0");
    assert_eq!(sources[4], "./val/r_0");
    assert_eq!(sources[8], "./test/r_2");
    // Poses from OpenGL axes, in split order.
    let expected = Pose::from_opengl(gl_look_at_origin(eye(1, 1)));
    assert!(s.frames[5].pose.0.abs_diff_eq(expected.0, 1e-12));
    let fx = 0.5 * SIDE as f64 / (0.5 * ANGLE_X).tan();
    assert!((s.intrinsics.fx - fx).abs() < 1e-9);
    // Transparent pixels are white, the object keeps its colour, the rim is mixed.
    let rgb = &s.frames[0].rgb;
    assert_eq!(rgb.get_pixel(0, 0).0, [255, 255, 255]);
    assert_eq!(rgb.get_pixel(16, 16).0, OBJECT);
    assert_eq!(rgb.get_pixel(16, 25).0, [227, 152, 142]);
    assert!(s.frames.iter().all(|f| f.gt.is_none()) && s.classes.is_empty());
    let report = imported.report.join("\n");
    assert!(
        report.contains("splits packed: train (4 frames), val (2 frames), test (3 frames)"),
        "{report}"
    );
    assert!(
        report.contains(
            "9 of 9 images have an alpha channel: composited on white, the default (--background black for black)"
        ),
        "{report}"
    );
    assert!(s.provenance.notes.iter().any(|n| n.contains("splits packed")));
}

#[test]
fn chosen_splits_and_a_black_background() {
    let tmp = lego();
    let opts = ImportOptions {
        // Out of order and repeated: packed once each, in split order.
        splits: vec![Split::Test, Split::Val, Split::Test],
        background: Background::Black,
        ..Default::default()
    };
    let imported = run_with(tmp.path(), &opts).unwrap();
    let s = &imported.scene;
    assert_eq!(s.frames.len(), 5);
    assert_eq!(s.frames[0].source.as_deref(), Some("./val/r_0"));
    assert_eq!(s.frames[0].rgb.get_pixel(0, 0).0, [0, 0, 0]);
    assert_eq!(s.frames[0].rgb.get_pixel(16, 25).0, [100, 25, 15]);
    let report = imported.report.join("\n");
    assert!(
        report.contains("splits packed: val (2 frames), test (3 frames); not packed: train"),
        "{report}"
    );
    assert!(
        report.contains("composited on black (--background white for white)"),
        "{report}"
    );

    // A single split file still packs as a plain transforms file.
    let one = tmp.path().join("transforms_val.json");
    assert_eq!(detect_layout(&one).unwrap(), Layout::Transforms);
    assert_eq!(run(&one).unwrap().scene.frames.len(), 2);
    // A folder with only some splits packs those.
    std::fs::remove_file(tmp.path().join("transforms_train.json")).unwrap();
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.scene.frames.len(), 5);
    assert!(
        imported.report[0].contains("not packed: train"),
        "{:?}",
        imported.report
    );
}

#[test]
fn alpha_becomes_two_class_ground_truth() {
    let tmp = lego();
    let opts = ImportOptions {
        alpha_gt: true,
        splits: vec![Split::Train],
        max_size: Some(16),
        ..Default::default()
    };
    let imported = run_with(tmp.path(), &opts).unwrap();
    let s = &imported.scene;
    let names: Vec<&str> = s.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["background", "object"]);
    let gt = s.frames[0].gt.as_ref().expect("ground truth");
    assert_eq!(gt.dimensions(), (16, 16));
    assert_eq!(gt.get_pixel(0, 0).0[0], 0);
    assert_eq!(gt.get_pixel(8, 8).0[0], 1);
    // Output pixel (8, 12) samples source pixel (17, 25), on the half-transparent rim.
    assert_eq!(gt.get_pixel(8, 12).0[0], GT_VOID);
    let report = imported.report.join("\n");
    assert!(
        report.contains("ground truth from alpha (--alpha-gt): alpha 0 = background") && report.contains("void"),
        "{report}"
    );
    // The archive accepts it.
    let bytes = scribblefield::scene::write_archive(s, std::io::Cursor::new(Vec::new()))
        .unwrap()
        .into_inner();
    assert!(
        scribblefield::scene::read_archive(&bytes, "l.scene.zip")
            .unwrap()
            .has_gt()
    );

    // One split file is a plain transforms.json capture, which takes --alpha-gt too.
    let opts = ImportOptions {
        alpha_gt: true,
        mask_classes: ["sky".into(), "lego".into()],
        ..Default::default()
    };
    let s = run_with(&tmp.path().join("transforms_val.json"), &opts).unwrap().scene;
    assert_eq!(s.frames.len(), 2);
    assert_eq!(s.classes[1].name, "lego");
    assert_eq!(s.frames[1].gt.as_ref().unwrap().get_pixel(16, 16).0[0], 1);
}

#[test]
fn bad_split_folders_name_file_field_and_value() {
    // A split asked for that is not there.
    let tmp = lego();
    std::fs::remove_file(tmp.path().join("transforms_val.json")).unwrap();
    let opts = ImportOptions {
        splits: vec![Split::Val],
        ..Default::default()
    };
    expect_err(
        run_with(tmp.path(), &opts),
        &["transforms_val.json", "missing", "the val split asked for with --split"],
    );

    // Splits of different cameras.
    let tmp = lego();
    let mut doc = split_doc(2, "test", 3);
    doc["camera_angle_x"] = json!(0.9);
    write_doc(tmp.path(), "test", &doc);
    expect_err(
        run(tmp.path()),
        &[
            "transforms_test.json",
            "camera_angle_x = 0.9 in the test split",
            "0.6911112070083618 in the train split",
            "share one camera",
        ],
    );
    let mut doc = split_doc(2, "test", 3);
    doc["fl_x"] = json!(30.0);
    write_doc(tmp.path(), "test", &doc);
    expect_err(
        run(tmp.path()),
        &["transforms_test.json", "fl_x = 30 in the test split", "absent"],
    );

    // Broken JSON, no frames, a frame that is not a pose: each names its split's file.
    let tmp = lego();
    truncate_half(&tmp.path().join("transforms_val.json"));
    expect_err(run(tmp.path()), &["transforms_val.json", "invalid JSON"]);
    write_doc(tmp.path(), "val", &json!({ "camera_angle_x": ANGLE_X, "frames": [] }));
    expect_err(run(tmp.path()), &["transforms_val.json", "no frames"]);
    let mut doc = split_doc(1, "val", 2);
    doc["frames"][1]["transform_matrix"] = rows(gl_look_at_origin(eye(1, 1)) * DMat4::from_scale(DVec3::splat(2.0)));
    write_doc(tmp.path(), "val", &doc);
    expect_err(
        run(tmp.path()),
        &["transforms_val.json", "frames[1]", "./val/r_1", "not rigid"],
    );
    let mut doc = split_doc(1, "val", 2);
    doc["camera_angle_x"] = json!(-1.0);
    write_doc(tmp.path(), "val", &doc);
    write_doc(tmp.path(), "train", &doc);
    write_doc(tmp.path(), "test", &doc);
    expect_err(run(tmp.path()), &["transforms_train.json", "camera_angle_x = -1"]);

    // A split none of whose images exist, and a path that leaves the folder.
    let tmp = lego();
    std::fs::remove_dir_all(tmp.path().join("test")).unwrap();
    expect_err(
        run(tmp.path()),
        &["transforms_test.json", "none of the 3 frames' images exist"],
    );
    let tmp = lego();
    let mut doc = split_doc(0, "train", 4);
    doc["frames"][2]["file_path"] = json!("../../etc/r_2");
    write_doc(tmp.path(), "train", &doc);
    expect_err(
        run(tmp.path()),
        &[
            "transforms_train.json",
            "frames[2].file_path \"../../etc/r_2\" climbs out",
        ],
    );

    // An image of another size.
    let tmp = lego();
    save_rgba(&tmp.path().join("val/r_1.png"), &RgbaImage::new(SIDE + 2, SIDE));
    expect_err(run(tmp.path()), &["r_1.png", "34x32", "32x32"]);
}

#[test]
fn options_that_do_not_apply_are_refused() {
    // --alpha-gt on images without alpha names the image.
    let tmp = lego();
    save_rgb(&tmp.path().join("train/r_3.png"), &pattern_rgb(SIDE, SIDE, 3));
    let opts = ImportOptions {
        alpha_gt: true,
        ..Default::default()
    };
    expect_err(
        run_with(tmp.path(), &opts),
        &[
            "train/r_3.png",
            "--alpha-gt reads ground truth from alpha",
            "no alpha channel",
            "Rgb8",
        ],
    );

    // --split on a single transforms.json folder, --alpha-gt on a 7-Scenes folder.
    let tmp = lego();
    std::fs::copy(
        tmp.path().join("transforms_train.json"),
        tmp.path().join("transforms.json"),
    )
    .unwrap();
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::Transforms);
    let opts = ImportOptions {
        splits: vec![Split::Train],
        ..Default::default()
    };
    expect_err(
        run_with(tmp.path(), &opts),
        &["--split is for NeRF-synthetic split folder", "transforms.json capture"],
    );
    let seven = tempfile::tempdir().unwrap();
    save_rgb(&seven.path().join("frame-000000.color.png"), &pattern_rgb(8, 8, 0));
    let opts = ImportOptions {
        alpha_gt: true,
        ..Default::default()
    };
    expect_err(
        run_with(seven.path(), &opts),
        &["--alpha-gt is for NeRF", "7-scenes capture"],
    );
}
