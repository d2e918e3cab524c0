//! Every format of an export read back the way its users read it: masks by frame name, the
//! CVAT / PASCAL VOC layout (palette indices as VOC loaders read them, colours mapped back
//! through labelmap.txt as CVAT does), COCO's RLE decoded to class maps, the point cloud's
//! points where the depth puts them, and the object-count cleanup applied to all of them.
use std::collections::BTreeMap;
use std::io::Cursor;

use glam::DMat4;
use image::{GrayImage, Luma, Rgb, RgbImage};

use super::coco::Coco;
use super::ply::read_ply;
use super::{ExportOptions, Format, MaskSet, MasksManifest, objects, rle};
use crate::labels::ClassInfo;
use crate::scene::demo::{DemoOptions, demo_scene};
use crate::scene::{Bounds, DepthImage, Frame, Intrinsics, Pose, Provenance, Scene};

fn demo() -> Scene {
    demo_scene(&DemoOptions {
        seed: 2,
        width: 40,
        height: 30,
        frames: 24,
    })
    .unwrap()
}

fn gt_masks(scene: &Scene) -> MaskSet {
    MaskSet {
        classes: scene.classes.clone(),
        masks: scene.frames.iter().map(|f| f.gt.clone().unwrap()).collect(),
    }
}

fn export(set: &MaskSet, options: &ExportOptions, scene: &Scene) -> BTreeMap<String, Vec<u8>> {
    set.files(None, options, Some(scene)).unwrap().into_iter().collect()
}

#[test]
fn masks_are_named_after_their_frames_too() {
    let scene = demo();
    let set = gt_masks(&scene);
    let files = export(&set, &ExportOptions::default(), &scene);
    let manifest: MasksManifest = serde_json::from_slice(&files["classes.json"]).unwrap();
    assert_eq!(manifest.by_name.len(), 24);
    for (i, mask) in set.masks.iter().enumerate() {
        let name = format!("by-name/demo-{i:03}.png");
        assert_eq!(manifest.by_name[i], name);
        assert_eq!(&image::load_from_memory(&files[&name]).unwrap().into_luma8(), mask);
        assert_eq!(files[&name], files[&manifest.files[i]]);
    }
}

/// labelmap.txt as Datumaro (CVAT's importer) parses it: name and colour of each line.
fn parse_labelmap(text: &str) -> Vec<(String, [u8; 3])> {
    text.lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let fields: Vec<&str> = l.split(':').collect();
            assert_eq!(fields.len(), 4, "{l}");
            let c: Vec<u8> = fields[1].split(',').map(|v| v.parse().unwrap()).collect();
            (fields[0].to_string(), [c[0], c[1], c[2]])
        })
        .collect()
}

#[test]
fn the_voc_layout_reads_back_by_index_and_by_colour() {
    let scene = demo();
    let set = gt_masks(&scene);
    let files = export(&set, &ExportOptions::with(&[Format::Voc], None), &scene);
    let text = std::str::from_utf8(&files["voc/labelmap.txt"]).unwrap();
    assert!(text.starts_with("# label:color_rgb:parts:actions\n"), "{text}");
    let labels = parse_labelmap(text);
    let want: Vec<(String, [u8; 3])> = scene.classes.iter().map(|c| (c.name.clone(), c.color)).collect();
    assert_eq!(labels, want);
    let list = std::str::from_utf8(&files["voc/ImageSets/Segmentation/default.txt"]).unwrap();
    let items: Vec<&str> = list.lines().collect();
    assert_eq!(items.len(), 24);
    for (i, item) in items.iter().enumerate() {
        assert_eq!(*item, format!("demo-{i:03}"));
        let bytes = &files[&format!("voc/SegmentationClass/{item}.png")];
        // A PASCAL VOC loader: the palette index is the class id.
        let mut reader = png::Decoder::new(Cursor::new(bytes)).read_info().unwrap();
        let palette: Vec<u8> = labels.iter().flat_map(|(_, c)| *c).collect();
        assert_eq!(reader.info().palette.as_deref(), Some(palette.as_slice()));
        let mut ids = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut ids).unwrap();
        assert_eq!(ids, set.masks[i].as_raw().as_slice(), "frame {i}");
        // CVAT: colours, mapped back to classes through labelmap.txt.
        let rgb = image::load_from_memory(bytes).unwrap().into_rgb8();
        let by_colour = GrayImage::from_fn(rgb.width(), rgb.height(), |x, y| {
            let c = rgb.get_pixel(x, y).0;
            Luma([labels.iter().position(|(_, k)| *k == c).unwrap() as u8])
        });
        assert_eq!(by_colour, set.masks[i], "frame {i}");
    }
}

#[test]
fn coco_rle_decodes_back_to_every_mask() {
    let scene = demo();
    let set = gt_masks(&scene);
    let files = export(&set, &ExportOptions::with(&[Format::Coco], None), &scene);
    let coco: Coco = serde_json::from_slice(&files["coco.json"]).unwrap();
    let names: Vec<&str> = coco.categories.iter().map(|c| c.name.as_str()).collect();
    let want: Vec<&str> = scene.classes.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names, want);
    assert!(coco.categories.iter().enumerate().all(|(i, c)| c.id == i as u64 + 1));
    assert_eq!(coco.images.len(), 24);
    let mut ids = std::collections::HashSet::new();
    for (i, image) in coco.images.iter().enumerate() {
        assert_eq!((image.id, image.width, image.height), (i as u64 + 1, 40, 30));
        assert_eq!(image.file_name, format!("demo-{i:03}"));
        let mut decoded = vec![u8::MAX; 40 * 30];
        let mask = &set.masks[i];
        let present: std::collections::BTreeSet<u8> = mask.pixels().map(|p| p.0[0]).collect();
        let anns: Vec<_> = coco.annotations.iter().filter(|a| a.image_id == image.id).collect();
        assert_eq!(anns.len(), present.len(), "frame {i}: one annotation per class present");
        for a in anns {
            assert!(ids.insert(a.id), "annotation ids are unique");
            assert_eq!((a.segmentation.size, a.iscrowd), ([30, 40], 0));
            let at = format!("coco.json annotation {}", a.id);
            let counts = rle::from_string(&a.segmentation.counts, &at).unwrap();
            let bits = rle::decode(&counts, 40, 30, &at).unwrap();
            let class = (a.category_id - 1) as u8;
            let area = bits.iter().filter(|&&b| b == 1).count() as u64;
            assert_eq!(a.area, area);
            let is = |x: u32, y: u32| mask.get_pixel(x, y).0[0] == class;
            assert_eq!(a.bbox, rle::bbox(40, 30, is));
            for (p, &b) in bits.iter().enumerate() {
                if b == 1 {
                    assert_eq!(decoded[p], u8::MAX, "frame {i}: pixel {p} in two annotations");
                    decoded[p] = class;
                }
            }
        }
        assert_eq!(decoded.as_slice(), mask.as_raw().as_slice(), "frame {i}");
    }
}

/// One 8 x 6 frame looking down +z at a wall 2 m away, the left half of class 0, the right of
/// class 1, and a scene box small enough that every pixel gets a cell of its own.
fn wall() -> (Scene, GrayImage) {
    let (w, h) = (8, 6);
    let k = Intrinsics {
        fx: 4.0,
        fy: 4.0,
        cx: 3.5,
        cy: 2.5,
    };
    // Camera 1 m along x from the origin.
    let pose = Pose(DMat4::from_translation(glam::DVec3::new(1.0, 0.0, 0.0)));
    let scene = Scene {
        width: w,
        height: h,
        intrinsics: k,
        depth_scale: 0.001,
        bounds: Bounds {
            min: [-1.0, -1.0, 0.0],
            max: [3.0, 1.0, 3.0],
        },
        frames: vec![Frame {
            pose,
            rgb: RgbImage::from_pixel(w, h, Rgb([9, 9, 9])),
            // One pixel without a reading.
            depth: Some(DepthImage::from_fn(w, h, |x, y| {
                Luma([if (x, y) == (0, 0) { 0 } else { 2000 }])
            })),
            gt: None,
            source: Some("wall.png".into()),
        }],
        classes: vec![
            ClassInfo {
                name: "left".into(),
                color: [255, 0, 0],
            },
            ClassInfo {
                name: "right\nside".into(),
                color: [0, 0, 255],
            },
        ],
        features: None,
        labels: None,
        provenance: Provenance::default(),
    };
    // Masks at twice the depth's size: each depth pixel takes the mask pixel at its centre.
    let mask = GrayImage::from_fn(2 * w, 2 * h, |x, _| Luma([u8::from(x >= w)]));
    (scene, mask)
}

/// The animation has a frame per mask, each the frame's colour with its mask over it: read back,
/// the demo's ground truth blended over its frames.
#[test]
fn the_animation_shows_every_mask_over_its_frame() {
    let scene = demo();
    let set = gt_masks(&scene);
    let files = export(&set, &ExportOptions::with(&[Format::Animation], None), &scene);
    let mut reader = png::Decoder::new(std::io::Cursor::new(files["masks.apng"].clone()))
        .read_info()
        .unwrap();
    let (w, h) = (reader.info().width, reader.info().height);
    assert_eq!((w, h), (scene.width, scene.height), "the demo is smaller than the cap");
    let frames = reader.info().animation_control.map(|c| c.num_frames);
    assert_eq!(frames, Some(scene.frames.len() as u32));
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    for (i, (frame, mask)) in scene.frames.iter().zip(&set.masks).enumerate() {
        reader.next_frame(&mut buf).unwrap();
        for (x, y) in [(3, 4), (w / 2, h / 2), (w - 1, h - 1)] {
            let at = ((y * w + x) * 3) as usize;
            let colour = set.classes[mask.get_pixel(x, y).0[0] as usize].color;
            let p = frame.rgb.get_pixel(x, y).0;
            for c in 0..3 {
                let want = ((p[c] as f32 + colour[c] as f32) / 2.0).round() as i32;
                assert!((buf[at + c] as i32 - want).abs() <= 1, "frame {i} at ({x}, {y})");
            }
        }
    }
}

#[test]
fn the_point_cloud_puts_each_depth_pixel_where_it_is_with_its_class() {
    let (scene, mask) = wall();
    let set = MaskSet {
        classes: scene.classes.clone(),
        masks: vec![mask],
    };
    let files = export(&set, &ExportOptions::with(&[Format::Ply], None), &scene);
    let bytes = &files["points.ply"];
    let header = String::from_utf8_lossy(&bytes[..300]);
    assert!(header.contains("comment class 1 right side\n"), "{header}");
    let points = read_ply(bytes, "points.ply").unwrap();
    assert_eq!(points.len(), 8 * 6 - 1);
    let mut pixels = std::collections::BTreeSet::new();
    for p in &points {
        // Back to the pixel it came from: x = 1 + (u - 3.5) / 4 * 2.
        let u = (p.position[0] as f64 - 1.0) / 2.0 * 4.0 + 3.5;
        let v = p.position[1] as f64 / 2.0 * 4.0 + 2.5;
        assert!((u - u.round()).abs() < 1e-4 && (v - v.round()).abs() < 1e-4, "{p:?}");
        pixels.insert((u.round() as i64, v.round() as i64));
        assert!((p.position[2] - 2.0).abs() < 1e-6, "{p:?}");
        let want = u8::from(u.round() >= 4.0);
        assert_eq!(p.label, want, "{p:?}");
        assert_eq!(p.color, scene.classes[want as usize].color);
    }
    // Every pixel once, but the one without a reading.
    assert_eq!(pixels.len(), 8 * 6 - 1);
    assert!(!pixels.contains(&(0, 0)));
}

#[test]
fn the_demo_point_cloud_fuses_frames_and_agrees_with_ground_truth() {
    let scene = demo();
    let set = gt_masks(&scene);
    let files = export(&set, &ExportOptions::with(&[Format::Ply], None), &scene);
    let points = read_ply(&files["points.ply"], "points.ply").unwrap();
    let pixels: usize = scene
        .frames
        .iter()
        .map(|f| f.depth.as_ref().unwrap().pixels().filter(|d| d.0[0] > 0).count())
        .sum();
    assert!(
        points.len() > 1000 && points.len() < pixels,
        "{} of {pixels}",
        points.len()
    );
    // Each point seen from frame 0, where it lies on the surface that frame sees, has the class
    // frame 0's ground truth gives it (cells straddling an edge may vote otherwise).
    let k = scene.intrinsics;
    let frame = &scene.frames[0];
    let to_camera = frame.pose.inverse().0;
    let (mut seen, mut agree) = (0, 0);
    for p in &points {
        let c = to_camera.transform_point3(glam::DVec3::new(
            p.position[0] as f64,
            p.position[1] as f64,
            p.position[2] as f64,
        ));
        if c.z <= 0.0 {
            continue;
        }
        let (u, v) = (k.fx * c.x / c.z + k.cx, k.fy * c.y / c.z + k.cy);
        let (x, y) = (u.round(), v.round());
        if x < 0.0 || y < 0.0 || x >= 40.0 || y >= 30.0 {
            continue;
        }
        let Some(d) = scene.depth_m(0, x as u32, y as u32) else {
            continue;
        };
        if (d - c.z).abs() > 0.01 {
            continue;
        }
        seen += 1;
        agree += usize::from(frame.gt.as_ref().unwrap().get_pixel(x as u32, y as u32).0[0] == p.label);
    }
    assert!(seen > 200, "{seen}");
    assert!(agree as f64 > 0.9 * seen as f64, "{agree} of {seen}");
}

#[test]
fn the_object_cleanup_reaches_every_format() {
    let scene = demo();
    let set = gt_masks(&scene);
    // Specks of class 2 in every frame: a second region of it.
    let specked = MaskSet {
        classes: set.classes.clone(),
        masks: set
            .masks
            .iter()
            .map(|m| {
                let mut m = m.clone();
                m.put_pixel(0, 0, Luma([2]));
                m.put_pixel(39, 29, Luma([2]));
                m
            })
            .collect(),
    };
    let options = ExportOptions::with(&Format::ALL, Some(1));
    let files = export(&specked, &options, &scene);
    let manifest: MasksManifest = serde_json::from_slice(&files["classes.json"]).unwrap();
    assert_eq!(manifest.objects, Some(1));
    let coco: Coco = serde_json::from_slice(&files["coco.json"]).unwrap();
    for (i, m) in specked.masks.iter().enumerate() {
        let mut cleaned = m.clone();
        objects::keep_largest(&mut cleaned, 1);
        assert_ne!(&cleaned, m);
        let written = image::load_from_memory(&files[&format!("{i:05}.png")])
            .unwrap()
            .into_luma8();
        assert_eq!(written, cleaned, "frame {i}");
        let voc = image::load_from_memory(&files[&format!("voc/SegmentationClass/demo-{i:03}.png")])
            .unwrap()
            .into_rgb8();
        assert_eq!(
            voc.get_pixel(0, 0).0,
            scene.classes[cleaned.get_pixel(0, 0).0[0] as usize].color
        );
        let class2 = coco
            .annotations
            .iter()
            .find(|a| a.image_id == i as u64 + 1 && a.category_id == 3);
        let area2 = cleaned.pixels().filter(|p| p.0[0] == 2).count() as u64;
        assert_eq!(class2.map_or(0, |a| a.area), area2, "frame {i}");
    }
}

#[test]
fn what_cannot_be_written_is_refused_by_name() {
    let scene = demo();
    let set = gt_masks(&scene);
    let err = |options: ExportOptions, set: &MaskSet, scene: Option<&Scene>| {
        set.files(None, &options, scene).unwrap_err().to_string()
    };
    let e = err(ExportOptions::with(&[], Some(0)), &set, Some(&scene));
    assert!(e.contains("(--objects): 0 keeps no region"), "{e}");
    let mut shared = set.clone();
    shared.classes[3].color = shared.classes[1].color;
    let e = err(ExportOptions::with(&[Format::Voc], None), &shared, Some(&scene));
    assert!(
        e.contains(&format!("{:?} and {:?}", set.classes[1].name, set.classes[3].name)),
        "{e}"
    );
    let e = err(ExportOptions::with(&[Format::Ply], None), &set, None);
    assert!(e.contains("needs the scene"), "{e}");
    let e = err(ExportOptions::with(&[Format::Animation], None), &set, None);
    assert!(e.contains("animation (.apng): needs the scene"), "{e}");
    let mut flat = scene.clone();
    flat.frames.iter_mut().for_each(|f| f.depth = None);
    let e = err(ExportOptions::with(&[Format::Ply], None), &set, Some(&flat));
    assert!(e.contains("no frame of the scene has depth"), "{e}");
    let mut unknown = set.clone();
    unknown.masks[5].put_pixel(3, 4, Luma([200]));
    let e = err(ExportOptions::with(&[Format::Coco], None), &unknown, Some(&scene));
    assert!(e.contains("frame 5: class id 200 at pixel (3, 4)"), "{e}");
    let mut fewer = set.clone();
    fewer.masks.pop();
    let e = err(ExportOptions::default(), &fewer, Some(&scene));
    assert!(e.contains("23 masks for a scene of 24 frames"), "{e}");
}
