//! The transforms.json importer on small scenes written here (no real one is in ../shared/data).
mod import_common;

use std::path::Path;

use glam::{DMat4, DVec3};
use image::{ImageBuffer, Luma, Rgba, RgbaImage};
use import_common::*;
use scribblefield::scene::import::{ImportOptions, Imported, Layout, detect_layout, import};
use scribblefield::scene::{Pose, read_archive, write_archive};
use serde_json::{Value, json};

const W: u32 = 40;
const H: u32 = 30;
const FRAMES: usize = 6;
const RADIUS: f64 = 2.0;

/// Camera-to-world in OpenGL axes (x right, y up, z backward) at `eye`, looking at the origin,
/// with world +z up as in NeRF's synthetic scenes.
fn gl_look_at_origin(eye: DVec3) -> DMat4 {
    let forward = (-eye).normalize();
    let x = forward.cross(DVec3::Z).normalize();
    let z = -forward;
    let y = z.cross(x);
    DMat4::from_cols(x.extend(0.0), y.extend(0.0), z.extend(0.0), eye.extend(1.0))
}

fn eye(i: usize) -> DVec3 {
    let a = i as f64 * std::f64::consts::TAU / FRAMES as f64;
    DVec3::new(RADIUS * a.cos(), RADIUS * a.sin(), 0.5)
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

/// A scene of FRAMES pattern images on an orbit, with instant-ngp style intrinsics.
fn synth_scene() -> (tempfile::TempDir, Value) {
    let tmp = tempfile::tempdir().unwrap();
    let mut frames = Vec::new();
    for i in 0..FRAMES {
        let path = format!("images/frame_{i:04}.png");
        save_rgb(&tmp.path().join(&path), &pattern_rgb(W, H, i as u32));
        frames.push(json!({ "file_path": path, "transform_matrix": rows(gl_look_at_origin(eye(i))) }));
    }
    let doc = json!({
        "fl_x": 50.0, "fl_y": 52.0, "cx": 20.0, "cy": 15.0, "w": W, "h": H,
        "aabb_scale": 16, "frames": frames,
    });
    write_json(tmp.path(), &doc);
    (tmp, doc)
}

fn write_json(dir: &Path, doc: &Value) {
    write(&dir.join("transforms.json"), serde_json::to_vec_pretty(doc).unwrap());
}

fn run(dir: &Path) -> Result<Imported, scribblefield::scene::SceneError> {
    import(dir, &ImportOptions::default(), &mut |_, _| {})
}

#[test]
fn orbit_scene_imports_with_opencv_poses() {
    let (tmp, _) = synth_scene();
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::Transforms);
    assert_eq!(
        detect_layout(&tmp.path().join("transforms.json")).unwrap(),
        Layout::Transforms
    );
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.layout, Layout::Transforms);
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let s = &imported.scene;
    assert_eq!(s.frames.len(), FRAMES);
    assert_eq!((s.width, s.height), (W, H));
    // transforms.json puts pixel centres at +0.5, the scene at integers.
    let k = s.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (50.0, 52.0, 19.5, 14.5));
    for (i, f) in s.frames.iter().enumerate() {
        // (Within a bit: serde_json parses floats to one unit in the last place by default.)
        assert!(
            f.pose
                .0
                .abs_diff_eq(Pose::from_opengl(gl_look_at_origin(eye(i))).0, 1e-15)
        );
        // OpenCV +z looks forward (at the origin), +y points down (world -z here).
        assert!((f.pose.transform_vector(DVec3::Z) - (-eye(i)).normalize()).length() < 1e-12);
        assert!(f.pose.transform_vector(DVec3::Y).z < 0.0);
        assert!((f.pose.position() - eye(i)).length() < 1e-12);
        assert_eq!(f.rgb, pattern_rgb(W, H, i as u32));
        assert!(f.depth.is_none());
    }
    assert_eq!(s.frames[2].source.as_deref(), Some("images/frame_0002.png"));
    let inside = |p: DVec3| (0..3).all(|i| s.bounds.min[i] < p[i] && p[i] < s.bounds.max[i]);
    assert!(
        (0..FRAMES).all(|i| inside(eye(i))) && inside(DVec3::ZERO),
        "{:?}",
        s.bounds
    );
    assert!(
        (0..3).all(|i| s.bounds.max[i] - s.bounds.min[i] < 6.0 * RADIUS),
        "{:?}",
        s.bounds
    );
    assert_eq!(s.provenance.importer, "transforms.json");
    assert!(s.provenance.notes.iter().any(|n| n.contains("camera positions")));

    let bytes = write_archive(s, std::io::Cursor::new(Vec::new())).unwrap().into_inner();
    let back = read_archive(&bytes, "t.scene.zip").unwrap();
    assert_eq!(back.frames.len(), FRAMES);
    assert_eq!(back.frames[3].rgb, s.frames[3].rgb);
}

#[test]
fn camera_angles_and_paths_without_extension() {
    let (tmp, mut doc) = synth_scene();
    let angle = 0.8f64;
    doc = json!({ "camera_angle_x": angle, "frames": doc["frames"].clone() });
    for f in doc["frames"].as_array_mut().unwrap() {
        let p = f["file_path"].as_str().unwrap().trim_end_matches(".png").to_string();
        f["file_path"] = json!(format!("./{p}"));
    }
    write_json(tmp.path(), &doc);
    let s = run(tmp.path()).unwrap().scene;
    let fx = 0.5 * W as f64 / (0.5 * angle).tan();
    let k = s.intrinsics;
    assert!((k.fx - fx).abs() < 1e-9 && (k.fy - fx).abs() < 1e-9, "{k:?}");
    assert_eq!((k.cx, k.cy), (W as f64 / 2.0 - 0.5, H as f64 / 2.0 - 0.5));
    assert_eq!(s.frames.len(), FRAMES);

    doc["camera_angle_y"] = json!(0.6);
    write_json(tmp.path(), &doc);
    let k = run(tmp.path()).unwrap().scene.intrinsics;
    assert!((k.fy - 0.5 * H as f64 / 0.3f64.tan()).abs() < 1e-9, "{k:?}");

    doc["camera_angle_x"] = json!(4.0);
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["transforms.json", "camera_angle_x = 4"]);
}

#[test]
fn missing_images_are_skipped_with_a_warning() {
    let (tmp, _) = synth_scene();
    std::fs::remove_file(tmp.path().join("images/frame_0001.png")).unwrap();
    std::fs::remove_file(tmp.path().join("images/frame_0004.png")).unwrap();
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.scene.frames.len(), FRAMES - 2);
    let w = imported
        .warnings
        .iter()
        .find(|w| w.contains("skipped 2 frames"))
        .expect("a warning");
    assert!(w.contains("frame_0001.png") && w.contains("frame_0004.png"), "{w}");
    assert!(
        imported
            .scene
            .provenance
            .notes
            .iter()
            .any(|n| n.contains("skipped 2 frames"))
    );

    std::fs::remove_dir_all(tmp.path().join("images")).unwrap();
    expect_err(run(tmp.path()), &["transforms.json", "none of the 6 frames"]);
}

#[test]
fn per_frame_intrinsics_must_agree() {
    let (tmp, mut doc) = synth_scene();
    // nerfstudio style: intrinsics only per frame, all equal.
    let frames: Vec<Value> = doc["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            let mut f = f.clone();
            for (key, v) in [("fl_x", 50.0), ("fl_y", 50.0), ("cx", 20.0), ("cy", 15.0)] {
                f[key] = json!(v);
            }
            f
        })
        .collect();
    write_json(tmp.path(), &json!({ "frames": frames.clone() }));
    let k = run(tmp.path()).unwrap().scene.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (50.0, 50.0, 19.5, 14.5));

    doc = json!({ "frames": frames });
    doc["frames"][3]["fl_x"] = json!(60.0);
    write_json(tmp.path(), &doc);
    expect_err(
        run(tmp.path()),
        &["transforms.json", "frames[3]", "fl_x = 60", "per-frame intrinsics"],
    );
}

#[test]
fn image_sizes_must_agree() {
    let (tmp, _) = synth_scene();
    save_rgb(&tmp.path().join("images/frame_0003.png"), &pattern_rgb(W + 2, H, 3));
    expect_err(run(tmp.path()), &["frame_0003.png", "42x30"]);

    let (tmp, mut doc) = synth_scene();
    doc["w"] = json!(80);
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["frame_0000.png", "w = 80"]);

    doc["w"] = json!(40.5);
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["transforms.json", "w = 40.5"]);
}

#[test]
fn distortion_is_reported_as_ignored() {
    let (tmp, mut doc) = synth_scene();
    doc["camera_model"] = json!("OPENCV");
    doc["k1"] = json!(0.0);
    write_json(tmp.path(), &doc);
    assert!(run(tmp.path()).unwrap().warnings.is_empty());

    doc["camera_model"] = json!("OPENCV_FISHEYE");
    doc["k1"] = json!(0.02);
    write_json(tmp.path(), &doc);
    let imported = run(tmp.path()).unwrap();
    assert!(
        imported
            .warnings
            .iter()
            .any(|w| w.contains("OPENCV_FISHEYE") && w.contains("distortion is ignored"))
    );

    doc["camera_model"] = json!("EQUIRECTANGULAR");
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["transforms.json", "EQUIRECTANGULAR"]);
}

#[test]
fn bad_transforms_are_named() {
    let (tmp, mut doc) = synth_scene();
    let scaled = gl_look_at_origin(eye(2)) * DMat4::from_scale(DVec3::splat(1.5));
    doc["frames"][2]["transform_matrix"] = rows(scaled);
    write_json(tmp.path(), &doc);
    expect_err(
        run(tmp.path()),
        &["transforms.json", "frames[2]", "frame_0002.png", "not rigid"],
    );

    let (tmp, mut doc) = synth_scene();
    doc["frames"][1]["transform_matrix"] = json!([[1, 0, 0], [0, 1, 0], [0, 0, 1]]);
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["frames[1]", "found 9 numbers"]);

    let (tmp, mut doc) = synth_scene();
    doc["frames"][1]["transform_matrix"] = json!("identity");
    write_json(tmp.path(), &doc);
    expect_err(run(tmp.path()), &["transforms.json", "invalid JSON"]);
}

#[test]
fn paths_outside_the_capture_folder_are_refused() {
    let (tmp, mut doc) = synth_scene();
    // A real image one level above the capture, which `..` would otherwise pack.
    let capture = tmp.path().join("capture");
    for i in 0..FRAMES {
        let from = tmp.path().join(format!("images/frame_{i:04}.png"));
        let to = capture.join(format!("images/frame_{i:04}.png"));
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::rename(from, to).unwrap();
    }
    save_rgb(&tmp.path().join("secret.png"), &pattern_rgb(W, H, 9));

    doc["frames"][3]["file_path"] = json!("../secret.png");
    write_json(&capture, &doc);
    expect_err(
        run(&capture),
        &[
            "transforms.json",
            "frames[3].file_path \"../secret.png\" climbs out with ..",
            "outside the capture folder",
        ],
    );
    let allowed = ImportOptions {
        allow_outside_paths: true,
        ..Default::default()
    };
    assert_eq!(
        import(&capture, &allowed, &mut |_, _| {}).unwrap().scene.frames.len(),
        FRAMES
    );

    let secret = tmp.path().join("secret.png").display().to_string();
    doc["frames"][3]["file_path"] = json!(secret);
    write_json(&capture, &doc);
    expect_err(run(&capture), &[&format!("frames[3].file_path {secret:?} is absolute")]);

    // Refused even when the file is absent, and for frames that would not be kept.
    doc["frames"][3]["file_path"] = json!("images/frame_0003.png");
    doc["frames"][5]["depth_file_path"] = json!("depth/../../../x.png");
    write_json(&capture, &doc);
    let opts = ImportOptions {
        max_frames: Some(1),
        ..Default::default()
    };
    expect_err(
        import(&capture, &opts, &mut |_, _| {}),
        &["frames[5].depth_file_path \"depth/../../../x.png\" climbs out"],
    );

    // `./` and a detour that stays inside are fine.
    doc["frames"][5]["depth_file_path"] = Value::Null;
    doc["frames"][0]["file_path"] = json!("./images/../images/frame_0000.png");
    write_json(&capture, &doc);
    assert_eq!(run(&capture).unwrap().scene.frames.len(), FRAMES);
}

#[test]
fn intrinsics_that_vanish_or_overflow_as_f32_are_refused() {
    let (tmp, mut doc) = synth_scene();
    doc["fl_x"] = json!(1e-300);
    write_json(tmp.path(), &doc);
    expect_err(
        run(tmp.path()),
        &[
            "transforms.json",
            "intrinsics fx = 1e-300 is too small for a 32-bit float",
        ],
    );
    doc["fl_x"] = json!(50.0);
    doc["cx"] = json!(1e301);
    write_json(tmp.path(), &doc);
    expect_err(
        run(tmp.path()),
        &[
            "transforms.json",
            "intrinsics cx = 1e301 is outside the 32-bit float range",
        ],
    );
}

#[test]
fn broken_or_empty_json_is_named() {
    let (tmp, _) = synth_scene();
    truncate_half(&tmp.path().join("transforms.json"));
    expect_err(run(tmp.path()), &["transforms.json", "invalid JSON"]);

    write_json(tmp.path(), &json!({ "fl_x": 50.0, "frames": [] }));
    expect_err(run(tmp.path()), &["transforms.json", "no frames"]);

    write_json(tmp.path(), &json!({ "fl_x": 50.0 }));
    expect_err(run(tmp.path()), &["transforms.json", "frames"]);

    let (tmp, doc) = synth_scene();
    write_json(tmp.path(), &json!({ "frames": doc["frames"].clone() }));
    expect_err(run(tmp.path()), &["transforms.json", "fl_x", "camera_angle_x"]);
}

#[test]
fn nerfstudio_depth_is_read_in_millimetres() {
    let (tmp, mut doc) = synth_scene();
    for i in 0..FRAMES {
        let path = format!("depth/frame_{i:04}.png");
        // A wall 1.5 m in front of every camera (minus a hole).
        let mut d = ImageBuffer::<Luma<u16>, Vec<u16>>::from_pixel(W, H, Luma([1500]));
        d.put_pixel(0, 0, Luma([0]));
        save_gray16(&tmp.path().join(&path), &d);
        doc["frames"][i]["depth_file_path"] = json!(path);
    }
    write_json(tmp.path(), &doc);
    let s = run(tmp.path()).unwrap().scene;
    assert_metres(s.depth_m(0, 20, 15), 1.5);
    assert_eq!(s.depth_m(0, 0, 0), None);
    assert!(s.provenance.notes.iter().any(|n| n.contains("back-projected depth")));
    // The wall points of camera 0 lie inside the bounds.
    let p = s.frames[0].pose.transform_point(s.intrinsics.ray_dir(20.0, 15.0) * 1.5);
    assert!((0..3).all(|i| s.bounds.min[i] < p[i] && p[i] < s.bounds.max[i]));

    std::fs::remove_file(tmp.path().join("depth/frame_0002.png")).unwrap();
    expect_err(run(tmp.path()), &["frame_0002.png", "missing", "depth"]);
}

#[test]
fn transparent_pixels_are_composited_over_white() {
    let (tmp, _) = synth_scene();
    let mut rgba = RgbaImage::from_pixel(W, H, Rgba([10, 20, 30, 255]));
    rgba.put_pixel(1, 1, Rgba([0, 0, 0, 0]));
    rgba.put_pixel(2, 1, Rgba([0, 0, 0, 128]));
    save_rgba(&tmp.path().join("images/frame_0000.png"), &rgba);
    let s = run(tmp.path()).unwrap().scene;
    let rgb = &s.frames[0].rgb;
    assert_eq!(rgb.get_pixel(0, 0).0, [10, 20, 30]);
    assert_eq!(rgb.get_pixel(1, 1).0, [255, 255, 255]);
    assert_eq!(rgb.get_pixel(2, 1).0, [127, 127, 127]);
}

#[test]
fn downscaling_and_frame_selection() {
    let (tmp, _) = synth_scene();
    let opts = ImportOptions {
        max_size: Some(20),
        every: 2,
        max_frames: Some(2),

        ..Default::default()
    };
    let mut seen = Vec::new();
    let s = import(tmp.path(), &opts, &mut |done, total| seen.push((done, total)))
        .unwrap()
        .scene;
    assert_eq!(seen, [(0, 2), (1, 2), (2, 2)]);
    assert_eq!(s.frames.len(), 2);
    assert_eq!(s.frames[1].source.as_deref(), Some("images/frame_0002.png"));
    assert_eq!((s.width, s.height), (20, 15));
    assert_eq!(s.frames[0].rgb.dimensions(), (20, 15));
    let k = s.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (25.0, 26.0, 9.5, 7.0));
}

#[test]
fn layout_detection_prefers_full_autolabel_scenes() {
    let (tmp, _) = synth_scene();
    // Images in a folder called rgb/ do not make an autolabel scene...
    std::fs::create_dir(tmp.path().join("rgb")).unwrap();
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::Transforms);
    // ...but rgb/ with autolabel's camera files does, even with a transforms.json beside it.
    write(&tmp.path().join("intrinsics.txt"), "50 0 20\n0 50 15\n0 0 1\n");
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::Autolabel);
}
