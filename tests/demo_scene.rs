//! The built-in demo scene: determinism, class coverage, depth that agrees with the geometry,
//! valid poses, a clean archive round trip and errors for bad options.
use std::collections::HashMap;
use std::sync::OnceLock;

use glam::DVec3;
use scribblefield::scene::GT_VOID;
use scribblefield::scene::archive::write_archive_bytes;
use scribblefield::scene::demo::{DEMO_CLASSES, DemoOptions, DemoWorld, demo_scene};
use scribblefield::scene::{Scene, read_archive};

/// The default scene, rendered once for all tests of this file.
fn default_scene() -> &'static Scene {
    static SCENE: OnceLock<Scene> = OnceLock::new();
    SCENE.get_or_init(|| demo_scene(&DemoOptions::default()).expect("default options are valid"))
}

/// Pixels of each class id in one frame's ground truth.
fn class_pixels(scene: &Scene, frame: usize) -> [usize; 256] {
    let mut counts = [0usize; 256];
    for p in scene.frames[frame]
        .gt
        .as_ref()
        .expect("demo frames have ground truth")
        .pixels()
    {
        counts[p.0[0] as usize] += 1;
    }
    counts
}

#[test]
fn same_options_give_identical_scenes_and_other_seeds_differ() {
    let opts = DemoOptions {
        seed: 5,
        width: 64,
        height: 48,
        frames: 8,
    };
    let a = demo_scene(&opts).unwrap();
    let b = demo_scene(&opts).unwrap();
    assert!(a == b, "two renders with the same options differ");
    assert_eq!(write_archive_bytes(&a).unwrap(), write_archive_bytes(&b).unwrap());

    let c = demo_scene(&DemoOptions { seed: 6, ..opts }).unwrap();
    assert_ne!(a.frames[0].pose, c.frames[0].pose, "the seed moves the orbit");
    for (fa, fc) in a.frames.iter().zip(&c.frames) {
        assert_ne!(fa.rgb, fc.rgb);
        assert_ne!(fa.gt, fc.gt);
    }
}

#[test]
fn default_scene_has_the_documented_shape() {
    let scene = default_scene();
    assert_eq!((scene.width, scene.height, scene.frames.len()), (160, 120, 36));
    assert_eq!(scene.depth_scale, 0.001);
    let names: Vec<&str> = scene.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, DEMO_CLASSES);
    assert!(DEMO_CLASSES.len() >= 6, "background, table and at least four objects");
    let mut colours: Vec<[u8; 3]> = scene.classes.iter().map(|c| c.color).collect();
    colours.sort();
    colours.dedup();
    assert_eq!(colours.len(), scene.classes.len(), "class colours must be distinct");
    assert_eq!(scene.provenance.source, "demo scene seed 0");
    assert_eq!(scene.provenance.importer, "demo-scene");
    let k = scene.intrinsics;
    assert_eq!((k.cx, k.cy), (79.5, 59.5));
    let hfov = 2.0 * (80.0 / k.fx).atan().to_degrees();
    assert!((hfov - 60.0).abs() < 1e-9, "horizontal field of view {hfov}");
    scene.bounds.check().unwrap();
    assert!(scene.features.is_none() && scene.labels.is_none());

    let other = demo_scene(&DemoOptions {
        seed: 3,
        width: 64,
        height: 40,
        frames: 24,
    })
    .unwrap();
    assert_eq!((other.width, other.height, other.frames.len()), (64, 40, 24));
    assert!(other.frames.iter().all(|f| f.rgb.dimensions() == (64, 40)));
    assert_eq!(other.provenance.source, "demo scene seed 3");
}

#[test]
fn every_class_is_seen_and_each_object_in_most_frames() {
    let scene = default_scene();
    let n = scene.frames.len();
    let mut frames_with = vec![0usize; DEMO_CLASSES.len()];
    for i in 0..n {
        let counts = class_pixels(scene, i);
        assert_eq!(counts[GT_VOID as usize], 0, "frame {i}: every ray hits the room");
        assert!(
            counts[DEMO_CLASSES.len()..].iter().all(|&c| c == 0),
            "frame {i}: unknown class id"
        );
        for (class, seen) in frames_with.iter_mut().enumerate() {
            // A class counts as visible with enough pixels to scribble on.
            if counts[class] >= 20 {
                *seen += 1;
            }
        }
    }
    for (class, &seen) in frames_with.iter().enumerate() {
        assert!(seen > 0, "class {} never appears", DEMO_CLASSES[class]);
        if class >= 2 {
            assert!(
                seen * 2 >= n,
                "object {} is visible in only {seen} of {n} frames",
                DEMO_CLASSES[class]
            );
        }
    }
}

/// Objects never touch, so pixels of two different objects side by side mean one hides part
/// of the other.
#[test]
fn objects_hide_each_other_in_some_views() {
    let scene = default_scene();
    let mut frames_with_occlusion = 0;
    for frame in &scene.frames {
        let gt = frame.gt.as_ref().unwrap();
        let depth = frame.depth.as_ref().unwrap();
        let occludes = (0..gt.height()).any(|y| {
            (1..gt.width()).any(|x| {
                let (a, b) = (gt.get_pixel(x - 1, y).0[0], gt.get_pixel(x, y).0[0]);
                let depth_step = depth.get_pixel(x - 1, y).0[0].abs_diff(depth.get_pixel(x, y).0[0]);
                a >= 2 && b >= 2 && a != b && depth_step > 20
            })
        });
        frames_with_occlusion += occludes as usize;
    }
    assert!(
        frames_with_occlusion >= 2,
        "objects overlap in only {frames_with_occlusion} views"
    );
}

/// Colour alone must not separate the classes: textured objects share colours.
#[test]
fn objects_are_textured_and_share_colours() {
    let scene = default_scene();
    // Coarse colour bins (4 bits per channel) per class over all frames.
    let mut bins: Vec<HashMap<[u8; 3], usize>> = vec![HashMap::new(); DEMO_CLASSES.len()];
    for frame in &scene.frames {
        for (c, g) in frame.rgb.pixels().zip(frame.gt.as_ref().unwrap().pixels()) {
            *bins[g.0[0] as usize].entry(c.0.map(|v| v >> 4)).or_default() += 1;
        }
    }
    for (class, hist) in bins.iter().enumerate() {
        let total: usize = hist.values().sum();
        let top = hist.values().max().copied().unwrap_or(0);
        assert!(
            top * 10 < total * 6,
            "{} is nearly one flat colour ({top} of {total} pixels)",
            DEMO_CLASSES[class]
        );
    }
    let shared = |a: usize, b: usize| {
        bins[a]
            .iter()
            .filter(|&(bin, &count)| count >= 20 && bins[b].get(bin).is_some_and(|&c| c >= 20))
            .count()
    };
    let (box_, mug, ball) = (2, 3, 4);
    assert!(shared(box_, ball) > 0, "the ball and the box share their red");
    assert!(shared(box_, mug) > 0, "the mug and the box share their cream");
}

/// Back-projects stored depth and checks the point lies on a surface of the class the ground
/// truth names, using the scene's signed distances (independent of the ray-tracing code), and
/// that nothing lies between the camera and that point (sphere tracing the same distances).
#[test]
fn depth_and_ground_truth_agree_with_the_geometry() {
    let scene = default_scene();
    let world = DemoWorld::generate(0);
    let k = scene.intrinsics;
    let mut checked = 0;
    for (i, frame) in scene.frames.iter().enumerate() {
        let depth = frame.depth.as_ref().unwrap();
        let gt = frame.gt.as_ref().unwrap();
        let eye = frame.pose.position();
        for y in (0..scene.height).step_by(4) {
            for x in (0..scene.width).step_by(4) {
                let stored = depth.get_pixel(x, y).0[0];
                assert_ne!(stored, 0, "frame {i} ({x}, {y}): no depth inside a closed room");
                let z = stored as f64 * scene.depth_scale;
                let ray = k.ray_dir(x as f64, y as f64);
                let point = frame.pose.transform_point(ray * z);
                let class = gt.get_pixel(x, y).0[0];
                // Rounding to whole millimetres moves the point up to 0.5 mm in z.
                let tolerance = 0.0005 * ray.length() + 1e-9;
                let off = world.distance_to_class(class, point);
                assert!(
                    off <= tolerance,
                    "frame {i} ({x}, {y}): point is {off} m off the {}",
                    DEMO_CLASSES[class as usize]
                );

                // March by the distance to the nearest surface, but at least 20 um so a ray
                // grazing past an edge moves on; no step can land inside a solid before the hit.
                let dir = frame.pose.transform_vector(ray).normalize();
                let length = (point - eye).length();
                let mut t = 0.0;
                while t < length - 0.002 {
                    let gap = world.distance(eye + dir * t);
                    assert!(
                        gap > -1e-7,
                        "frame {i} ({x}, {y}): a surface at {t} m hides the one at {length} m"
                    );
                    t += gap.max(2e-5);
                }

                let hit = world.cast(eye, frame.pose.transform_vector(ray)).unwrap();
                assert!(
                    (hit.t - z).abs() <= 0.0005 + 1e-9,
                    "frame {i} ({x}, {y}): re-traced depth {} vs {z}",
                    hit.t
                );
                assert_eq!(hit.class, class);
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 36 * 40 * 30);
}

#[test]
fn poses_are_rigid_and_look_at_the_table_from_inside_the_room() {
    let scene = default_scene();
    let world = DemoWorld::generate(0);
    let target = world.look_target();
    for (i, frame) in scene.frames.iter().enumerate() {
        frame.pose.check().unwrap_or_else(|p| panic!("frame {i}: {p}"));
        let in_camera = frame.pose.inverse().transform_point(target);
        assert!(
            in_camera.z > 0.5 && in_camera.truncate().length() < 1e-9,
            "frame {i}: target not on the axis"
        );
        let eye = frame.pose.position();
        let (lo, hi) = (DVec3::from_array(scene.bounds.min), DVec3::from_array(scene.bounds.max));
        assert!(
            eye.cmpgt(lo).all() && eye.cmplt(hi).all(),
            "frame {i}: camera outside the bounds"
        );
        assert!(
            frame.pose.transform_vector(DVec3::Y).z < 0.0,
            "frame {i}: image is upside down"
        );
    }
    let first = scene.frames[0].pose.position();
    assert!(
        scene.frames[1..]
            .iter()
            .all(|f| (f.pose.position() - first).length() > 0.05),
        "views repeat"
    );
}

#[test]
fn scene_survives_an_archive_round_trip() {
    let scene = default_scene();
    let bytes = write_archive_bytes(scene).unwrap();
    let mut back = read_archive(&bytes, "demo.scene.zip").unwrap();
    // serde_json parses floats to within one unit in the last place unless its
    // `float_roundtrip` feature is on, so poses are compared to that precision, all else exactly.
    for (i, (read, written)) in back.frames.iter_mut().zip(&scene.frames).enumerate() {
        let (a, b) = (read.pose.to_row_major(), written.pose.to_row_major());
        let ulps = a
            .iter()
            .zip(&b)
            .map(|(x, y)| x.to_bits().abs_diff(y.to_bits()))
            .max()
            .unwrap();
        assert!(
            ulps <= 1,
            "frame {i}: pose read back differs by {ulps} units in the last place"
        );
        read.pose = written.pose;
    }
    assert!(back == *scene, "the scene read back differs from the one written");
}

#[test]
fn bad_options_are_refused_with_the_option_named() {
    let ok = DemoOptions {
        seed: 1,
        width: 32,
        height: 24,
        frames: 2,
    };
    let cases = [
        (DemoOptions { frames: 0, ..ok }, "frames = 0"),
        (DemoOptions { frames: 721, ..ok }, "frames = 721"),
        (DemoOptions { width: 15, ..ok }, "width = 15"),
        (DemoOptions { width: 2049, ..ok }, "width = 2049"),
        (DemoOptions { height: 0, ..ok }, "height = 0"),
        (
            DemoOptions {
                width: 2048,
                height: 2048,
                frames: 720,
                ..ok
            },
            "720 frames of 2048 x 2048",
        ),
    ];
    for (opts, expected) in cases {
        let err = demo_scene(&opts).expect_err(expected).to_string();
        assert!(err.contains(expected), "{err:?} should mention {expected:?}");
        assert!(err.contains("demo scene options"), "{err:?}");
    }
    let edge = demo_scene(&DemoOptions {
        width: 16,
        height: 16,
        frames: 1,
        ..ok
    })
    .unwrap();
    assert_eq!(edge.frames.len(), 1);
}
