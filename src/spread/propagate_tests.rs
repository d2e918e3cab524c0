//! Tests of the walk inside one frame (`propagate`).
use image::{ImageBuffer, Luma, Rgb, RgbImage};

use super::*;
use crate::spread::colour::srgb_to_lab;
use crate::spread::options::GuardedWalks;

/// Left half dark red, right half light grey, 24 x 16.
fn two_regions() -> RgbImage {
    RgbImage::from_fn(24, 16, |x, _| {
        if x < 12 {
            Rgb([120, 20, 20])
        } else {
            Rgb([200, 200, 200])
        }
    })
}

/// Full-height strokes at columns `(x, class)`: a user's stroke across an object.
fn columns(width: u32, height: u32, marks: &[(u32, u16)]) -> Vec<u16> {
    let dots: Vec<(u32, u32, u16)> = marks
        .iter()
        .flat_map(|&(x, c)| (0..height).map(move |y| (x, y, c)))
        .collect();
    strokes_at(width, height, &dots)
}

fn strokes_at(width: u32, height: u32, marks: &[(u32, u32, u16)]) -> Vec<u16> {
    let mut map = vec![UNLABELLED; (width * height) as usize];
    for &(x, y, c) in marks {
        map[(y * width + x) as usize] = c;
    }
    map
}

#[test]
fn two_strokes_fill_their_regions_and_stop_at_the_edge() {
    let rgb = two_regions();
    let strokes = columns(24, 16, &[(3, 0), (20, 1)]);
    let guide = Guide::colour_only(&rgb);
    let map = propagate_frame(&strokes, 2, guide, None, &PropagationOptions::default());
    for y in 0..16 {
        for x in 0..24 {
            let want = if x < 12 { 0 } else { 1 };
            assert_eq!(map[y * 24 + x], want, "pixel ({x}, {y})");
        }
    }
}

/// One colour, and depth that folds at x = 12 with no jump, so only the turn of the normal marks
/// the edge: `valley` (depth rises towards the fold, as where a box stands on a table) folds
/// inward, otherwise (a box's own corner towards the camera) outward. The walk under `options`.
fn walk_over_a_fold(valley: bool, options: &PropagationOptions) -> Vec<u16> {
    let rgb = RgbImage::from_pixel(24, 16, Rgb([150, 150, 150]));
    let depth: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(24, 16, |x, _| {
        let away = 10 * (2 * x as i32 - 23).abs();
        Luma([if valley { 1230 - away } else { 1000 + away } as u16])
    });
    let camera = Intrinsics {
        fx: 20.0,
        fy: 20.0,
        cx: 11.5,
        cy: 7.5,
    };
    let strokes = columns(24, 16, &[(3, 0), (20, 1)]);
    let guide = Guide {
        rgb: &rgb,
        depth: Some(&depth),
        codes: None,
    };
    propagate_frame(&strokes, 2, guide, Some(&camera), options)
}

/// A loose depth sigma and a long reach, so that neither the slope nor the walk's fading
/// decides, and normals left out.
fn without_normals() -> PropagationOptions {
    PropagationOptions {
        depth_sigma: 1.0,
        reach: 4.0,
        normal_sigma: 0.0,
        ..PropagationOptions::default()
    }
}

/// Each stroke's class holds its side of the fold, up to the pixels next to it.
fn assert_split_at_the_fold(map: &[u16]) {
    for x in 4..11 {
        assert_eq!(map[8 * 24 + x], 0, "({x}, 8)");
    }
    for x in 13..20 {
        assert_eq!(map[8 * 24 + x], 1, "({x}, 8)");
    }
}

#[test]
fn an_inward_crease_stops_the_walk_where_colour_and_depth_change_smoothly() {
    let with_normals = PropagationOptions {
        normal_sigma: 0.1,
        ..without_normals()
    };
    for outward_too in [false, true] {
        let options = PropagationOptions {
            inward_creases_only: !outward_too,
            ..with_normals
        };
        assert_split_at_the_fold(&walk_over_a_fold(true, &options));
    }
    let without = walk_over_a_fold(true, &without_normals());
    assert_eq!(without[8 * 24 + 11], UNLABELLED, "no normals: unsure next to the fold");
}

#[test]
fn an_outward_fold_lets_the_walk_through_unless_every_turn_counts() {
    let with_normals = PropagationOptions {
        normal_sigma: 0.1,
        ..without_normals()
    };
    // Every turn counts: the corner stops the walk as the crease does.
    let every_turn = walk_over_a_fold(
        false,
        &PropagationOptions {
            inward_creases_only: false,
            ..with_normals
        },
    );
    assert_split_at_the_fold(&every_turn);
    // Inward creases only: the corner is no edge, so next to it the walk is as unsure as
    // without normals.
    let inward_only = walk_over_a_fold(false, &with_normals);
    assert_eq!(inward_only, walk_over_a_fold(false, &without_normals()));
    assert_eq!(inward_only[8 * 24 + 11], UNLABELLED);
}

#[test]
fn depth_separates_regions_of_one_colour_and_without_it_the_walk_is_unsure() {
    let rgb = RgbImage::from_pixel(24, 16, Rgb([150, 150, 150]));
    let depth: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_fn(24, 16, |x, _| Luma([if x < 12 { 1000 } else { 2000 }]));
    let strokes = columns(24, 16, &[(3, 0), (20, 1)]);
    let options = PropagationOptions::default();
    let with_depth = propagate_frame(
        &strokes,
        2,
        Guide {
            rgb: &rgb,
            depth: Some(&depth),
            codes: None,
        },
        None,
        &options,
    );
    assert_eq!(with_depth[8 * 24 + 10], 0);
    assert_eq!(with_depth[8 * 24 + 13], 1);
    let labelled = |m: &[u16]| m.iter().filter(|&&c| c != UNLABELLED).count();
    assert_eq!(labelled(&with_depth), 24 * 16);
    let without = propagate_frame(&strokes, 2, Guide::colour_only(&rgb), None, &options);
    for x in 9..15 {
        assert_eq!(
            without[8 * 24 + x],
            UNLABELLED,
            "({x}, 8): a uniform image gives no confident label midway between the strokes"
        );
    }
    assert!(labelled(&without) < labelled(&with_depth));
}

#[test]
fn one_class_or_disabled_keeps_the_strokes_and_unknown_classes_are_dropped() {
    let rgb = two_regions();
    let guide = Guide::colour_only(&rgb);
    let one = strokes_at(24, 16, &[(3, 8, 0), (4, 8, 0)]);
    assert_eq!(
        propagate_frame(&one, 2, guide, None, &PropagationOptions::default()),
        one
    );
    let two = strokes_at(24, 16, &[(3, 8, 0), (20, 8, 1), (5, 5, 7)]);
    let off = PropagationOptions {
        enabled: false,
        ..PropagationOptions::default()
    };
    let kept = propagate_frame(&two, 2, guide, None, &off);
    assert_eq!(kept[5 * 24 + 5], UNLABELLED, "class 7 has no logit with 2 classes");
    assert_eq!(kept.iter().filter(|&&c| c != UNLABELLED).count(), 2);
}

#[test]
fn the_cache_walks_again_only_a_frame_whose_strokes_changed() {
    use crate::spread::test_scenes::{classes, dot, small_demo};
    let scene = small_demo(24);
    let mut labels = classes(&["a", "b"]);
    for frame in [0, 2] {
        labels.push_stroke(frame, dot(0, 4.5, 20.5));
        labels.push_stroke(frame, dot(1, 16.5, 4.5));
    }
    let options = PropagationOptions::default();
    let mut cache = PropagationCache::default();
    let first = cache.maps(&scene, &labels, 2, &options);
    assert_eq!(first, propagate_labels(&scene, &labels, 2, &options));
    assert_eq!(first.iter().map(|(f, _)| *f).collect::<Vec<_>>(), vec![0, 2]);
    // Dense depth: every pixel has a reading, so no pixel is far from the points.
    assert_eq!(cache.far_class(), None);
    labels.push_stroke(2, dot(0, 28.5, 20.5));
    let second = cache.maps(&scene, &labels, 2, &options);
    assert_eq!(second[0], first[0], "frame 0 did not change");
    assert_ne!(second[1], first[1], "frame 2 gained a stroke");
    assert_eq!(second, propagate_labels(&scene, &labels, 2, &options));
}

#[test]
fn pixels_beyond_the_reach_of_every_stroke_stay_unlabelled() {
    // A dark red block with a stroke of class 0 at the left end of a long grey strip whose
    // near end has a stroke of class 1: the far end is grey like class 1's stroke, but 75
    // pixels away.
    let rgb = RgbImage::from_fn(96, 8, |x, _| {
        if x < 8 {
            Rgb([120, 20, 20])
        } else {
            Rgb([150, 150, 150])
        }
    });
    let strokes = strokes_at(96, 8, &[(2, 4, 0), (12, 4, 1)]);
    let guide = Guide::colour_only(&rgb);
    let short = propagate_frame(&strokes, 2, guide, None, &PropagationOptions::default());
    assert_eq!(short[4 * 96 + 20], 1, "near the stroke");
    assert_eq!(short[4 * 96 + 90], UNLABELLED, "48 pixels of reach do not get there");
    let long = PropagationOptions {
        reach: 4.0,
        ..PropagationOptions::default()
    };
    assert_eq!(propagate_frame(&strokes, 2, guide, None, &long)[4 * 96 + 90], 1);
}

#[test]
fn bad_options_are_named() {
    let bad = PropagationOptions {
        min_margin: 1.5,
        ..PropagationOptions::default()
    };
    assert!(bad.validate().unwrap_err().contains("min_margin"));
    let bad = PropagationOptions {
        colour_sigma: 0.0,
        ..PropagationOptions::default()
    };
    assert!(bad.validate().unwrap_err().contains("colour_sigma"));
    for (bad, name) in [
        (
            PropagationOptions {
                feature_sigma: f32::NAN,
                ..PropagationOptions::default()
            },
            "feature_sigma",
        ),
        (
            PropagationOptions {
                edge_margin: 0.5,
                ..PropagationOptions::default()
            },
            "edge_margin",
        ),
        (
            PropagationOptions {
                undrawn_margin: -0.01,
                ..PropagationOptions::default()
            },
            "undrawn_margin",
        ),
    ] {
        assert!(bad.validate().unwrap_err().contains(name), "{name}");
    }
    PropagationOptions::default().validate().unwrap();
}

#[test]
fn lab_of_white_black_and_red() {
    let close = |a: [f32; 3], b: [f32; 3]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 0.5);
    assert!(close(srgb_to_lab([255, 255, 255]), [100.0, 0.0, 0.0]));
    assert!(close(srgb_to_lab([0, 0, 0]), [0.0, 0.0, 0.0]));
    assert!(close(srgb_to_lab([255, 0, 0]), [53.24, 80.09, 67.20]));
}

#[test]
fn the_plane_the_objects_stand_on_takes_the_class_its_strokes_give_where_the_walk_fades() {
    use crate::labels::synthetic::{ScribbleOptions, scribble_frames};
    use crate::scene::demo::{DemoOptions, demo_scene};
    let scene = demo_scene(&DemoOptions {
        width: 80,
        height: 60,
        frames: 24,
        ..DemoOptions::default()
    })
    .unwrap();
    let classes = scene.classes.len();
    let labels = scribble_frames(&scene, &[0], &ScribbleOptions::default());
    let count = |options: &PropagationOptions| {
        let maps = propagate_labels(&scene, &labels, classes, options);
        let gt = scene.frames[0].gt.as_ref().unwrap();
        let (mut background, mut right, mut labelled) = (0, 0, 0);
        for (&label, truth) in maps[0].1.iter().zip(gt.pixels()) {
            if label != UNLABELLED && truth.0[0] != 255 {
                labelled += 1;
                right += usize::from(label == u16::from(truth.0[0]));
                background += usize::from(label == 0);
            }
        }
        (background, right as f64 / labelled as f64)
    };
    // Walks that fade soon leave most of the floor to the plane.
    let on = PropagationOptions {
        support_plane: true,
        reach: 0.1,
        ..PropagationOptions::default()
    };
    let off = PropagationOptions {
        support_plane: false,
        ..on
    };
    let ((with_plane, right_with), (without, right_without)) = (count(&on), count(&off));
    // The demo's floor is background: the strokes on it say so, and all of it is labelled.
    assert!(
        with_plane > without + 200,
        "{with_plane} against {without} background labels"
    );
    assert!(
        right_with > 0.98 && right_without > 0.98,
        "{right_with}, {right_without}"
    );
}

#[test]
fn feature_codes_stop_the_walk_where_colour_cannot() {
    // One grey everywhere; the feature codes (a 12 x 8 grid, two values per cell) change at
    // pixel column 12. The strokes sit at columns 3 and 14, so by distance alone column 10 is
    // nearer class 1's.
    let rgb = RgbImage::from_pixel(24, 16, Rgb([150, 150, 150]));
    let values: Vec<half::f16> = (0..12 * 8)
        .flat_map(|cell| {
            let v = if cell % 12 < 6 { 0.0 } else { 1.0 };
            [half::f16::from_f32(v), half::f16::from_f32(-v)]
        })
        .collect();
    let codes = crate::scene::guide::FrameCodes {
        width: 12,
        height: 8,
        dim: 2,
        values: &values,
    };
    let strokes = columns(24, 16, &[(3, 0), (14, 1)]);
    let with = PropagationOptions {
        feature_sigma: 0.5,
        edge_margin: 0.0,
        guarded_walks: GuardedWalks::Every,
        ..PropagationOptions::default()
    };
    let guide = Guide {
        rgb: &rgb,
        depth: None,
        codes: Some(codes),
    };
    let map = propagate_frame(&strokes, 2, guide, None, &with);
    for y in 0..16 {
        for x in 0..24 {
            let want = match x {
                0..=10 => Some(0),
                13.. => Some(1),
                _ => None,
            };
            if let Some(want) = want {
                assert_eq!(map[y * 24 + x], want, "pixel ({x}, {y}) with features");
            }
        }
    }
    let off = PropagationOptions {
        feature_sigma: 0.0,
        ..with
    };
    let without = propagate_frame(&strokes, 2, guide, None, &off);
    assert_ne!(
        without[8 * 24 + 10],
        0,
        "colour alone gives column 10 to the nearer stroke"
    );
}

#[test]
fn codes_are_interpolated_between_cell_centres() {
    let values: Vec<half::f16> = [0.0f32, 2.0].iter().map(|&v| half::f16::from_f32(v)).collect();
    let codes = crate::scene::guide::FrameCodes {
        width: 2,
        height: 1,
        dim: 1,
        values: &values,
    };
    // Four pixels over two cells: cell centres at pixels 0.5 and 2.5.
    assert_eq!(codes.upsampled(4, 1), vec![0.0, 0.5, 1.5, 2.0]);
}

#[test]
fn a_margin_leaves_the_pixels_along_the_walks_edge_to_the_field() {
    let rgb = two_regions();
    let strokes = columns(24, 16, &[(3, 0), (20, 1)]);
    let guide = Guide::colour_only(&rgb);
    // 0.035 of the 24 x 16 frame's diagonal is one pixel.
    let options = PropagationOptions {
        edge_margin: 0.035,
        guarded_walks: GuardedWalks::Every,
        ..PropagationOptions::default()
    };
    let map = propagate_frame(&strokes, 2, guide, None, &options);
    for y in 0..16 {
        for x in 0..24 {
            let want = match x {
                11 | 12 => UNLABELLED,
                x if x < 11 => 0,
                _ => 1,
            };
            // The frame's border has no pixel beyond it: its labels stay.
            assert_eq!(map[y * 24 + x], want, "pixel ({x}, {y})");
        }
    }
}

#[test]
fn only_walks_on_colour_alone_among_three_classes_are_guarded_by_default() {
    let guard = PropagationOptions::default().guarded_walks;
    assert!(guard.guards(false, 3), "no depth, three classes");
    assert!(!guard.guards(false, 2), "an object on its backdrop");
    assert!(!guard.guards(true, 6), "with depth");
    assert!(GuardedWalks::Every.guards(true, 2));
    // Unguarded, the defaults walk exactly as with both terms off.
    let rgb = two_regions();
    let strokes = columns(24, 16, &[(3, 0), (20, 1)]);
    let guide = Guide::colour_only(&rgb);
    let off = PropagationOptions {
        feature_sigma: 0.0,
        edge_margin: 0.0,
        ..PropagationOptions::default()
    };
    assert_eq!(
        propagate_frame(&strokes, 2, guide, None, &PropagationOptions::default()),
        propagate_frame(&strokes, 2, guide, None, &off)
    );
}
