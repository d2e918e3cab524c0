//! The COLMAP importer on a synthetic capture written here (text and binary models, lens
//! distortion, masks, broken inputs) and on the real capture in ../shared/data/alexander-colmap.
mod colmap_fixture;
mod import_common;

use std::collections::HashMap;
use std::path::Path;

use colmap_fixture::*;
use glam::{DVec2, DVec3};
use import_common::*;
use scribblefield::scene::import::{ImportOptions, Imported, Layout, detect_layout, import};
use scribblefield::scene::{Scene, SceneError, read_archive, write_archive};
use tempfile::TempDir;

const PINHOLE: [f64; 4] = [80.0, 82.0, 48.3, 36.2];
/// Barrel distortion strong enough to move the marker by pixels.
const OPENCV: [f64; 8] = [80.0, 82.0, 48.5, 35.5, -0.25, 0.05, 0.002, -0.001];

fn pinhole() -> Synth {
    Synth::new("PINHOLE", PINHOLE.to_vec())
}

fn distorted() -> Synth {
    Synth::new("OPENCV", OPENCV.to_vec())
}

enum Format {
    Text,
    Binary,
}

/// A capture folder holding `synth`'s photos (and masks) and its model in sparse/0.
fn capture(synth: &Synth, format: Format, masks: bool) -> TempDir {
    let tmp = tempfile::tempdir().unwrap();
    synth.write_photos(tmp.path(), masks);
    let model = tmp.path().join("sparse/0");
    match format {
        Format::Text => synth.write_text(&model),
        Format::Binary => synth.write_binary(&model),
    }
    tmp
}

fn run(dir: &Path) -> Result<Imported, SceneError> {
    run_with(dir, &ImportOptions::default())
}

fn run_with(dir: &Path, opts: &ImportOptions) -> Result<Imported, SceneError> {
    import(dir, opts, &mut |_, _| {})
}

/// The pixel (integer centres) where the scene's own pose and intrinsics put a world point, and
/// its depth along the optical axis.
fn project(scene: &Scene, frame: usize, p: DVec3) -> (DVec2, f64) {
    let c = scene.frames[frame].pose.inverse().transform_point(p);
    let k = scene.intrinsics;
    (DVec2::new(k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy), c.z)
}

/// Whether one provenance note mentions all of `needles`.
fn noted(scene: &Scene, needles: &[&str]) -> bool {
    scene
        .provenance
        .notes
        .iter()
        .any(|n| needles.iter().all(|w| n.contains(w)))
}

fn depth_readings(scene: &Scene, frame: usize) -> Vec<(u32, u32, f64)> {
    let d = scene.frames[frame].depth.as_ref().expect("sparse depth");
    d.enumerate_pixels()
        .filter(|(_, _, v)| v.0[0] != 0)
        .map(|(x, y, v)| (x, y, v.0[0] as f64 * scene.depth_scale))
        .collect()
}

#[test]
fn pinhole_model_imports_poses_depth_and_bounds() {
    let synth = pinhole();
    let tmp = capture(&synth, Format::Text, false);
    assert_eq!(detect_layout(tmp.path()).unwrap(), Layout::Colmap);
    let imported = run(tmp.path()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let s = &imported.scene;
    assert_eq!(s.provenance.importer, "colmap");
    assert_eq!((s.frames.len(), s.width, s.height), (PHOTOS, W, H));
    // COLMAP puts the top-left pixel's centre at 0.5, the scene at 0.
    let k = s.intrinsics;
    assert_eq!((k.fx, k.fy, k.cx, k.cy), (80.0, 82.0, 48.3 - 0.5, 36.2 - 0.5));
    for (i, f) in s.frames.iter().enumerate() {
        assert_eq!(f.source.as_deref(), Some(format!("photo_{i:02}.png").as_str()));
        assert!((f.pose.position() - eye(i)).length() < 1e-9, "{}", f.pose.position());
        // OpenCV axes: +z looks at the origin.
        assert!((f.pose.transform_vector(DVec3::Z) - (-eye(i)).normalize()).length() < 1e-9);
        // A pinhole photo is copied, not resampled.
        let photo = image::open(tmp.path().join("images").join(f.source.as_ref().unwrap())).unwrap();
        assert_eq!(f.rgb, photo.into_rgb8());
    }
    // Every observed point projects through the scene's camera onto its keypoint, and its depth
    // is stored there.
    let mut observed = 0;
    for (i, image) in synth.images.iter().enumerate() {
        for (kp, id) in image.keypoints.iter().filter(|(_, id)| *id >= 0) {
            let point = synth.points.iter().find(|p| p.id == *id as u64).unwrap();
            let (px, z) = project(s, i, point.xyz);
            assert!((px - (*kp - DVec2::splat(0.5))).length() < 1e-9, "{px} vs {kp}");
            // Points seen by one photo only are not trusted; of two on one pixel the nearer stays.
            if point.track.len() >= 2 {
                let d = s.depth_m(i, px.x.round() as u32, px.y.round() as u32);
                assert!(
                    d.is_some_and(|d| d <= z + s.depth_scale),
                    "frame {i}: {d:?}, not {z} at {px}"
                );
                observed += 1;
            }
        }
        for (x, y, d) in depth_readings(s, i) {
            assert!(d > 2.0 && d < 4.0, "frame {i} ({x}, {y}): {d}");
        }
    }
    let readings: usize = (0..PHOTOS).map(|i| depth_readings(s, i).len()).sum();
    assert!(
        readings > observed * 9 / 10 && readings <= observed,
        "{readings} of {observed}"
    );
    assert!(s.depth_scale > 0.0 && s.depth_scale < 1e-3, "{}", s.depth_scale);
    // Bounds: the grid (±0.5) with some padding, not the camera orbit (radius 3).
    for p in grid_points() {
        assert!(
            (0..3).all(|a| s.bounds.min[a] <= p[a] && p[a] <= s.bounds.max[a]),
            "{p} {:?}",
            s.bounds
        );
    }
    assert!(
        (0..3).all(|a| s.bounds.max[a] - s.bounds.min[a] < 1.5),
        "{:?}",
        s.bounds
    );
    assert!(noted(s, &["percentile"]));
    assert!(s.classes.is_empty() && s.frames.iter().all(|f| f.gt.is_none()));

    let bytes = write_archive(s, std::io::Cursor::new(Vec::new())).unwrap().into_inner();
    let back = read_archive(&bytes, "c.scene.zip").unwrap();
    assert_eq!(back.frames[2].depth, s.frames[2].depth);
    assert_eq!(back.depth_scale, s.depth_scale);
}

#[test]
fn text_and_binary_models_give_the_same_scene() {
    let synth = distorted();
    let text = run(capture(&synth, Format::Text, true).path()).unwrap().scene;
    let binary = run(capture(&synth, Format::Binary, true).path()).unwrap().scene;
    assert_eq!(text.intrinsics, binary.intrinsics);
    assert_eq!(text.bounds, binary.bounds);
    assert_eq!(text.depth_scale, binary.depth_scale);
    assert_eq!(text.classes.len(), 2);
    assert_eq!(text.classes, binary.classes);
    for (a, b) in text.frames.iter().zip(&binary.frames) {
        assert_eq!(a.pose, b.pose);
        assert_eq!(a.rgb, b.rgb);
        assert_eq!(a.depth, b.depth);
        assert_eq!(a.gt, b.gt);
        assert_eq!(a.source, b.source);
    }
}

/// Brightness-weighted centre of the white dot (integer pixel centres).
fn dot_centre(rgb: &image::RgbImage) -> DVec2 {
    let (mut sum, mut weight) = (DVec2::ZERO, 0.0);
    for (x, y, p) in rgb.enumerate_pixels() {
        let w = (p.0[1] as f64 - 40.0).max(0.0);
        sum += DVec2::new(x as f64, y as f64) * w;
        weight += w;
    }
    sum / weight
}

#[test]
fn undistortion_moves_a_distorted_point_to_its_pinhole_position() {
    let synth = distorted();
    let cam = synth.camera();
    let distorted_at = cam.project(MARKER_CAM) - DVec2::splat(0.5);
    let pinhole_at = cam.project_pinhole(MARKER_CAM) - DVec2::splat(0.5);
    assert!((distorted_at - pinhole_at).length() > 2.0, "the lens must move the dot");
    let tmp = capture(&synth, Format::Text, false);
    let photo = image::open(tmp.path().join("images/photo_00.png")).unwrap().into_rgb8();
    assert!((dot_centre(&photo) - distorted_at).length() < 0.2);

    let imported = run(tmp.path()).unwrap();
    let s = &imported.scene;
    for f in &s.frames {
        let got = dot_centre(&f.rgb);
        assert!((got - pinhole_at).length() < 0.25, "dot at {got}, pinhole {pinhole_at}");
    }
    // Keypoints are undistorted too: depth sits where the pinhole camera sees the point.
    for (i, image) in synth.images.iter().enumerate() {
        for (_, id) in image.keypoints.iter().filter(|(_, id)| *id >= 0) {
            let point = synth.points.iter().find(|p| p.id == *id as u64).unwrap();
            let (px, _) = project(s, i, point.xyz);
            assert!(s.depth_m(i, px.x.round() as u32, px.y.round() as u32).is_some());
        }
    }
    assert!(noted(s, &["1 OPENCV", "pinhole", "; 0 pixels"]));
}

#[test]
fn pincushion_distortion_leaves_black_void_corners() {
    let mut params = OPENCV.to_vec();
    params[4] = 0.4;
    let synth = Synth::new("OPENCV", params);
    let s = run(capture(&synth, Format::Binary, true).path()).unwrap().scene;
    for f in &s.frames {
        assert_eq!(f.rgb.get_pixel(0, 0).0, [0, 0, 0]);
        assert_eq!(f.gt.as_ref().unwrap().get_pixel(W - 1, H - 1).0[0], 255);
        assert_eq!(f.gt.as_ref().unwrap().get_pixel(W / 2, 2).0[0], 0);
    }
    assert!(!noted(&s, &["; 0 pixels"]) && noted(&s, &["fell outside"]));
}

#[test]
fn a_model_without_points_has_camera_bounds_and_no_depth() {
    let mut synth = pinhole();
    synth.points.clear();
    for image in &mut synth.images {
        image.keypoints.iter_mut().for_each(|k| k.1 = -1);
    }
    let imported = run(capture(&synth, Format::Text, false).path()).unwrap();
    assert!(
        imported.warnings.iter().any(|w| w.contains("no 3D points")),
        "{:?}",
        imported.warnings
    );
    let s = imported.scene;
    assert!(s.frames.iter().all(|f| f.depth.is_none()));
    assert!((0..PHOTOS).all(|i| (0..3).all(|a| s.bounds.min[a] < eye(i)[a] && eye(i)[a] < s.bounds.max[a])));
}

#[test]
fn masks_become_two_class_ground_truth() {
    let synth = distorted();
    let tmp = capture(&synth, Format::Text, true);
    let opts = ImportOptions {
        mask_classes: ["room".into(), "statue".into()],
        ..Default::default()
    };
    let s = run_with(tmp.path(), &opts).unwrap().scene;
    let names: Vec<&str> = s.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, ["room", "statue"]);
    for (i, f) in s.frames.iter().enumerate() {
        let gt = f.gt.as_ref().expect("ground truth");
        assert!(gt.pixels().all(|p| p.0[0] <= 1), "barrel distortion leaves no void");
        let (centre, _) = project(&s, i, DVec3::ZERO);
        assert_eq!(gt.get_pixel(centre.x.round() as u32, centre.y.round() as u32).0[0], 1);
        assert_eq!(gt.get_pixel(0, 0).0[0], 0);
        let fg = gt.pixels().filter(|p| p.0[0] == 1).count();
        assert!(fg > 400 && fg < 1000, "{fg}");
    }

    // A mask of another size but the same aspect is resampled; the --masks folder is used.
    let elsewhere = tmp.path().join("elsewhere");
    std::fs::rename(tmp.path().join("masks"), &elsewhere).unwrap();
    let half = image::open(elsewhere.join("photo_01.png")).unwrap().resize_exact(
        W / 2,
        H / 2,
        image::imageops::FilterType::Nearest,
    );
    half.save(elsewhere.join("photo_01.png")).unwrap();
    let opts = ImportOptions {
        masks: Some(elsewhere.clone()),
        ..Default::default()
    };
    let s = run_with(tmp.path(), &opts).unwrap().scene;
    assert_eq!(s.classes[1].name, "object");
    assert!(s.frames[1].gt.as_ref().unwrap().pixels().any(|p| p.0[0] == 1));
    // Without --masks and without masks/ there is no ground truth.
    assert!(run(tmp.path()).unwrap().scene.frames[0].gt.is_none());

    image::GrayImage::new(W, W)
        .save(elsewhere.join("photo_01.png"))
        .unwrap();
    expect_err(run_with(tmp.path(), &opts), &["photo_01.png", "mask is 96x96"]);
    std::fs::remove_file(elsewhere.join("photo_01.png")).unwrap();
    expect_err(
        run_with(tmp.path(), &opts),
        &["photo_01.png", "missing", "mask of photo", "1 of 5"],
    );
    // No mask at all for the imported photos: a warning, no ground truth.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let imported = run_with(
        tmp.path(),
        &ImportOptions {
            masks: Some(empty),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        imported.warnings.iter().any(|w| w.contains("no mask for any")),
        "{:?}",
        imported.warnings
    );
    assert!(imported.scene.classes.is_empty());
}

#[test]
fn downscaled_depth_lands_on_the_scaled_pixel_nearest_first() {
    let mut synth = pinhole();
    // A second point behind grid point 14 (the origin) on camera 0's ray, also seen by camera 1.
    let behind = eye(0) + (DVec3::ZERO - eye(0)) * 1.2;
    synth.add_point(1000, behind, &[0, 1]);
    let tmp = capture(&synth, Format::Binary, false);
    let opts = ImportOptions {
        max_size: Some(W / 4),
        ..Default::default()
    };
    let s = run_with(tmp.path(), &opts).unwrap().scene;
    assert_eq!((s.width, s.height), (W / 4, H / 4));
    let (origin, z) = project(&s, 0, DVec3::ZERO);
    let stored = s.depth_m(0, origin.x.round() as u32, origin.y.round() as u32).unwrap();
    assert!((stored - z).abs() <= s.depth_scale, "nearest kept: {stored} vs {z}");
    // Every reading is one point's depth at that point's scaled pixel, never a blend.
    for i in 0..PHOTOS {
        for (x, y, d) in depth_readings(&s, i) {
            let matches = synth.points.iter().any(|p| {
                let (px, pz) = project(&s, i, p.xyz);
                (px - DVec2::new(x as f64, y as f64)).abs().max_element() < 0.5 + 1e-9
                    && (pz - d).abs() <= s.depth_scale
            });
            assert!(matches, "frame {i} ({x}, {y}) = {d} is no point's depth");
        }
    }
}

#[test]
fn unregistered_and_missing_photos_are_counted() {
    let synth = pinhole();
    let tmp = capture(&synth, Format::Text, false);
    save_rgb(&tmp.path().join("images/unposed.jpg"), &pattern_rgb(W, H, 1));
    save_rgb(&tmp.path().join("images/sub/unposed.png"), &pattern_rgb(W, H, 2));
    std::fs::remove_file(tmp.path().join("images/photo_03.png")).unwrap();
    let imported = run(tmp.path()).unwrap();
    assert_eq!(imported.scene.frames.len(), PHOTOS - 1);
    let w = imported.warnings.join("\n");
    assert!(w.contains("skipped 2 photos that the model does not register"), "{w}");
    assert!(
        w.contains("1 registered photos are missing") && w.contains("photo_03.png"),
        "{w}"
    );
}

#[test]
fn frame_selection_and_other_layouts() {
    let tmp = capture(&pinhole(), Format::Text, false);
    let opts = ImportOptions {
        every: 2,
        max_frames: Some(2),
        ..Default::default()
    };
    let s = run_with(tmp.path(), &opts).unwrap().scene;
    let names: Vec<_> = s.frames.iter().map(|f| f.source.clone().unwrap()).collect();
    assert_eq!(names, ["photo_00.png", "photo_02.png"]);
    // A model directly in sparse/ is found too.
    std::fs::rename(tmp.path().join("sparse/0"), tmp.path().join("model")).unwrap();
    std::fs::remove_dir(tmp.path().join("sparse")).unwrap();
    std::fs::rename(tmp.path().join("model"), tmp.path().join("sparse")).unwrap();
    assert_eq!(run(tmp.path()).unwrap().scene.frames.len(), PHOTOS);
    // --masks only means something for COLMAP captures.
    let other = tempfile::tempdir().unwrap();
    write(&other.path().join("transforms.json"), "{}");
    let opts = ImportOptions {
        masks: Some(other.path().to_path_buf()),
        ..Default::default()
    };
    expect_err(
        run_with(other.path(), &opts),
        &["--masks is for COLMAP", "transforms.json"],
    );
}

#[path = "import_colmap/errors.rs"]
mod errors;
#[path = "import_colmap/real.rs"]
mod real;

/// Spreading strokes over a capture with sparse depth gives its thread back between the
/// iterations of its walks (the page draws on that thread: `pause`), gives the labels it
/// gives without pauses, and does no walk again for labels it has already spread.
#[test]
fn spreading_over_sparse_depth_pauses_and_gives_the_same_labels() {
    use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frames};
    use scribblefield::pause::{CountPauses, run_to_end};
    use scribblefield::spread::{PropagationCache, PropagationOptions};
    let tmp = capture(&pinhole(), Format::Text, true);
    let scene = run(tmp.path()).unwrap().scene;
    assert!(scene.has_sparse_depth());
    let labels = scribble_frames(&scene, &[0], &ScribbleOptions::default());
    let options = PropagationOptions::default();
    let straight = PropagationCache::default().maps(&scene, &labels, 2, &options);
    let mut cache = PropagationCache::default();
    let mut pauses = CountPauses::default();
    let paused = run_to_end(cache.maps_pausing(&scene, &labels, 2, &options, &mut pauses));
    assert_eq!(paused, straight);
    // A pause before each frame's view of the points is built, and before each iteration.
    assert!(pauses.0 > scene.frames.len(), "{} pauses", pauses.0);
    let mut again = CountPauses::default();
    assert_eq!(
        run_to_end(cache.maps_pausing(&scene, &labels, 2, &options, &mut again)),
        straight
    );
    assert_eq!(again.0, 0, "unchanged labels walk nothing again");
}
