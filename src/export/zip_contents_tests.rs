//! What the browser's masks download holds, entry by entry: the layout users and scripts
//! rely on (class-id PNGs by index and by frame name, colour previews, the class manifest, the
//! annotations, and the formats asked for).
use std::io::{Cursor, Read};

use image::GrayImage;

use super::{ExportOptions, Format, MaskSet, MasksManifest};
use crate::labels::{ClassInfo, LabelSet, Stroke};
use crate::scene::Scene;
use crate::scene::demo::{DemoOptions, demo_scene};

/// A two-frame scene the masks are of (at three times their size): its frames are named `demo-000`
/// and `demo-001`.
fn scene() -> Scene {
    demo_scene(&DemoOptions {
        seed: 0,
        width: 24,
        height: 18,
        frames: 2,
    })
    .unwrap()
}

fn entries(zip: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut archive = zip::ZipArchive::new(Cursor::new(zip)).unwrap();
    (0..archive.len())
        .map(|i| {
            let mut f = archive.by_index(i).unwrap();
            let mut data = Vec::new();
            f.read_to_end(&mut data).unwrap();
            (f.name().unwrap().to_string(), data)
        })
        .collect()
}

#[test]
fn the_download_holds_masks_previews_manifest_and_labels() {
    let classes = vec![
        ClassInfo {
            name: "floor".into(),
            color: [10, 20, 30],
        },
        ClassInfo {
            name: "chair".into(),
            color: [200, 100, 0],
        },
    ];
    let masks: Vec<GrayImage> = (0..2)
        .map(|f| GrayImage::from_fn(8, 6, |x, _| image::Luma([u8::from(x >= 4 + f)])))
        .collect();
    let mut labels = LabelSet::new(classes.clone());
    labels.push_stroke(
        1,
        Stroke {
            class: Some(1),
            radius: 1.5,
            points: vec![[6.5, 2.5], [7.5, 3.0]],
        },
    );
    let set = MaskSet {
        classes: classes.clone(),
        masks: masks.clone(),
    };
    let scene = scene();
    let zip = set
        .to_zip(Some(&labels), &ExportOptions::default(), Some(&scene))
        .unwrap();
    let files = entries(&zip);
    let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "00000.png",
            "preview/00000.png",
            "by-name/demo-000.png",
            "00001.png",
            "preview/00001.png",
            "by-name/demo-001.png",
            "classes.json",
            "labels.json"
        ]
    );
    let get = |name: &str| &files.iter().find(|(n, _)| n == name).unwrap().1;
    let manifest: MasksManifest = serde_json::from_slice(get("classes.json")).unwrap();
    assert_eq!((manifest.frames, manifest.width, manifest.height), (2, 8, 6));
    assert_eq!(manifest.classes, classes);
    let mask = image::load_from_memory(get("00001.png")).unwrap().into_luma8();
    assert_eq!(mask, masks[1]);
    let preview = image::load_from_memory(get("preview/00001.png")).unwrap().into_rgb8();
    assert_eq!(preview.get_pixel(7, 0).0, [200, 100, 0]);
    assert_eq!(preview.get_pixel(0, 0).0, [10, 20, 30]);
    assert_eq!(get("by-name/demo-001.png"), get("00001.png"));
    assert_eq!(manifest.by_name, ["by-name/demo-000.png", "by-name/demo-001.png"]);
    let back = LabelSet::from_json(get("labels.json"), "labels.json", 2).unwrap();
    assert_eq!(back, labels);

    // Every format asked for: each frame's VOC mask after its other files, the files that
    // cover all frames at the end. (What each holds: formats_tests.rs.)
    let all = ExportOptions::with(&Format::ALL, Some(3));
    let zip = set.to_zip(Some(&labels), &all, Some(&scene)).unwrap();
    let files = entries(&zip);
    let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "00000.png",
            "preview/00000.png",
            "by-name/demo-000.png",
            "voc/SegmentationClass/demo-000.png",
            "00001.png",
            "preview/00001.png",
            "by-name/demo-001.png",
            "voc/SegmentationClass/demo-001.png",
            "classes.json",
            "labels.json",
            "voc/labelmap.txt",
            "voc/ImageSets/Segmentation/default.txt",
            "coco.json",
            "points.ply",
            "masks.apng"
        ]
    );
}
