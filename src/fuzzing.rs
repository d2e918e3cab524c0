//! Entry points for the fuzz targets (`fuzz/`, nightly, cargo-fuzz) and for the replay of their
//! seed corpus on stable (`tests/fuzz_corpus.rs`): one function per parser that reads input from
//! outside, fed raw bytes. So the corpus that CI replays goes through exactly the code the fuzzer
//! ran (docs/fuzzing.md).
//!
//! Each function returns `Err` with the crate's own message when the input is refused; that is
//! the expected outcome for almost all fuzzed input. A panic is a finding, and so is an accepted
//! input that breaks a limit of docs/limits.md: after a success each function asserts the
//! limits on what it built, so the fuzzer reports such an input as a crash. Memory and time are
//! bounded by the fuzzer itself (`-rss_limit_mb`, `-malloc_limit_mb`, `-timeout`).
use crate::features::{NpyLayout, parse_npy_map};
use crate::labels::share::decode_labels;
use crate::safetensors::SafeTensors;
use crate::scene::archive::limits as archive_limits;
use crate::scene::import::text_checks;
use crate::scene::label_set::{LabelSet, limits as label_limits};
use crate::scene::{GT_VOID, Scene, read_archive};

mod parsers;
pub use parsers::{
    NEXT_FILE, checkpoint, colmap_binary, field_config, mp4, pack_zip, pickle, pth, scannet_text, stray_text,
};

/// What a target did with one input: accepted, or refused with the crate's message.
pub type Outcome = Result<(), String>;

/// A target's entry point: the bytes the fuzzer made (or a corpus file holds).
pub type Target = fn(&[u8]) -> Outcome;

/// Every target by name: the name is also its folder under `fuzz/corpus/` and its binary in
/// `fuzz/fuzz_targets/`.
pub const TARGETS: &[(&str, Target)] = &[
    ("archive", archive),
    ("archive_entries", archive_entries),
    ("labels_json", labels_json),
    ("share_link", share_link),
    ("npy", npy),
    ("safetensors", safetensors),
    ("transforms_json", transforms_json),
    ("colmap_text", colmap_text),
    ("seven_scenes_text", seven_scenes_text),
    ("pth", pth),
    ("pickle", pickle),
    ("colmap_binary", colmap_binary),
    ("scannet_text", scannet_text),
    ("checkpoint", checkpoint),
    ("field_config", field_config),
    ("pack_zip", pack_zip),
    ("stray_text", stray_text),
    ("mp4", mp4),
];

/// Frames the scene of a fuzzed `labels.json` has: enough for any frame index the corpus uses,
/// few enough that the frame check is exercised.
const LABEL_FRAMES: u32 = 64;
/// Size of the frame that accepted labels are rasterized on: small, so a fuzzed stroke's cost
/// stays bounded by the clipping of the rasterizer rather than by the frame.
const RASTER_SIZE: (u32, u32) = (64, 48);

/// A `*.scene.zip` held in memory, decoded whole.
pub fn archive(data: &[u8]) -> Outcome {
    let scene = read_archive(data, "fuzz.scene.zip").map_err(|e| e.to_string())?;
    assert_scene_within_limits(&scene);
    Ok(())
}

/// Marks the start of an entry in [`archive_entries`] input: `--entry:NAME\n` then its bytes.
pub const ENTRY_MARK: &[u8] = b"--entry:";

/// The entries of a scene archive, zipped here (stored, with correct checksums) and then read
/// like [`archive`]. Mutations of a zip file's bytes mostly break its CRC-32s, which the reader
/// checks first; this target's mutations reach `scene.json`, the image headers and pixels, the
/// labels and the feature codes instead. Input: `--entry:NAME\n` followed by the entry's bytes,
/// repeated (a duplicate name ends the input's use: the zip writer refuses it).
pub fn archive_entries(data: &[u8]) -> Outcome {
    use std::io::Write;
    use zip::write::SimpleFileOptions;

    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let stored = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for part in split_on(data, ENTRY_MARK).skip(1) {
        let (name, content) = match part.iter().position(|&b| b == b'\n') {
            Some(end) => (&part[..end], &part[end + 1..]),
            None => (part, &[][..]),
        };
        let name = std::str::from_utf8(name).map_err(|_| "entry name not UTF-8".to_string())?;
        zip.start_file(name, stored).map_err(|e| format!("zip writer: {e}"))?;
        zip.write_all(content).map_err(|e| format!("zip writer: {e}"))?;
    }
    let bytes = zip.finish().map_err(|e| format!("zip writer: {e}"))?.into_inner();
    archive(&bytes)
}

/// The pieces of `data` between occurrences of `mark` (the first one before the first mark).
fn split_on<'a>(data: &'a [u8], mark: &'a [u8]) -> impl Iterator<Item = &'a [u8]> {
    let mut rest = Some(data);
    std::iter::from_fn(move || {
        let r = rest?;
        match r.windows(mark.len()).position(|w| w == mark) {
            Some(at) => {
                rest = Some(&r[at + mark.len()..]);
                Some(&r[..at])
            }
            None => {
                rest = None;
                Some(r)
            }
        }
    })
}

/// A `labels.json` for a scene of [`LABEL_FRAMES`] frames; accepted labels are rasterized.
pub fn labels_json(data: &[u8]) -> Outcome {
    let labels = LabelSet::from_json(data, "labels.json", LABEL_FRAMES).map_err(|e| e.to_string())?;
    assert_labels_within_limits(&labels);
    rasterize_all(&labels);
    Ok(())
}

/// A share link's code (the text after `#labels=`), decoded, then checked as the page checks it.
pub fn share_link(data: &[u8]) -> Outcome {
    let code = std::str::from_utf8(data).map_err(|_| "not UTF-8".to_string())?;
    let labels = decode_labels(code).map_err(|e| e.to_string())?;
    // The decoder refuses over-limit counts while decoding; whatever it returns is within them.
    assert_labels_within_limits(&labels);
    labels.check("share link", LABEL_FRAMES).map_err(|e| e.to_string())?;
    rasterize_all(&labels);
    Ok(())
}

/// A `.npy` feature map, read in both axis orders.
pub fn npy(data: &[u8]) -> Outcome {
    let mut refused = Vec::new();
    for layout in [NpyLayout::Hwc, NpyLayout::Chw] {
        match parse_npy_map(data, "fuzz.npy", layout) {
            Ok(map) => {
                let values = map.height as u64 * map.width as u64 * map.dim as u64;
                assert_eq!(values, map.data.len() as u64, "a map's data must be its shape");
                // A map comes from a file holding its values: never more values than bytes.
                assert!(map.data.len() <= data.len(), "more values than the file has bytes");
            }
            Err(e) => refused.push(e.to_string()),
        }
    }
    if refused.len() == 2 {
        Err(refused.join("; "))
    } else {
        Ok(())
    }
}

/// A safetensors file: the header, then every tensor read as f32 at its stated shape.
pub fn safetensors(data: &[u8]) -> Outcome {
    let file = SafeTensors::from_bytes("fuzz.safetensors", data.to_vec()).map_err(|e| e.to_string())?;
    let names: Vec<String> = file.names().map(String::from).collect();
    let mut refused = Vec::new();
    for name in &names {
        let Some(info) = file.info(name) else { continue };
        let shape = info.shape.clone();
        match file.f32(name, &shape) {
            Ok(values) => assert!(
                values.len() <= data.len(),
                "tensor {name}: {} values from a {}-byte file",
                values.len(),
                data.len()
            ),
            Err(e) => refused.push(e.to_string()),
        }
    }
    if refused.is_empty() {
        Ok(())
    } else {
        Err(refused.join("; "))
    }
}

/// A `transforms.json`, checked without its images.
pub fn transforms_json(data: &[u8]) -> Outcome {
    text_checks::transforms_json(data)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// A COLMAP text model: `cameras.txt`, `images.txt` and `points3D.txt` in one input, separated
/// by NUL bytes (missing parts are empty files).
pub fn colmap_text(data: &[u8]) -> Outcome {
    let text = std::str::from_utf8(data).map_err(|_| "not UTF-8".to_string())?;
    let mut parts = text.splitn(3, '\0');
    let cameras = parts.next().unwrap_or("");
    let images = parts.next().unwrap_or("");
    let points = parts.next().unwrap_or("");
    text_checks::colmap_text(cameras, images, points)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// One 7-Scenes text file, read both as a pose and as intrinsics (the two text formats of the
/// layout; a file is at most one of them).
pub fn seven_scenes_text(data: &[u8]) -> Outcome {
    let pose = text_checks::pose_text(data).map_err(|e| e.to_string());
    let k = text_checks::intrinsics_text(data).map_err(|e| e.to_string());
    if let Ok(k) = &k {
        // The scene computes in f32: accepted intrinsics must survive the conversion.
        for v in [k.fx, k.fy, k.cx, k.cy] {
            assert!((v as f32).is_finite(), "intrinsics {v} not finite as f32");
        }
        assert!(k.fx as f32 > 0.0 && k.fy as f32 > 0.0, "focal length zero as f32");
    }
    match (pose, k) {
        (Err(a), Err(b)) => Err(format!("{a}; {b}")),
        _ => Ok(()),
    }
}

/// The archive limits of docs/limits.md, asserted on a scene that was accepted.
fn assert_scene_within_limits(scene: &Scene) {
    assert!(scene.frames.len() as u64 <= u64::from(archive_limits::MAX_FRAMES));
    assert!(scene.width <= archive_limits::MAX_SIDE && scene.height <= archive_limits::MAX_SIDE);
    assert!(scene.classes.len() <= archive_limits::MAX_CLASSES);
    let pixels = scene.width as u64 * scene.height as u64;
    let mut decoded = 0u64;
    for (i, frame) in scene.frames.iter().enumerate() {
        assert_eq!(
            frame.rgb.dimensions(),
            (scene.width, scene.height),
            "frame {i} colour size"
        );
        decoded += pixels * 3;
        if let Some(depth) = &frame.depth {
            assert_eq!(depth.dimensions(), (scene.width, scene.height), "frame {i} depth size");
            decoded += pixels * 2;
        }
        if let Some(gt) = &frame.gt {
            assert_eq!(
                gt.dimensions(),
                (scene.width, scene.height),
                "frame {i} ground truth size"
            );
            decoded += pixels;
            let classes = scene.classes.len();
            assert!(
                gt.as_raw().iter().all(|&id| usize::from(id) < classes || id == GT_VOID),
                "frame {i}: a ground-truth id outside the {classes} classes was accepted"
            );
        }
    }
    if let Some(f) = &scene.features {
        assert!(f.dim <= archive_limits::MAX_FEATURE_DIM);
        decoded += f.data.len() as u64 * 2;
    }
    assert!(
        decoded <= archive_limits::MAX_DECODED_BYTES,
        "accepted a scene of {decoded} decoded bytes, over the budget of {}",
        archive_limits::MAX_DECODED_BYTES
    );
    if let Some(labels) = &scene.labels {
        assert_labels_within_limits(labels);
    }
}

/// The label limits of docs/limits.md, asserted on labels that were accepted.
fn assert_labels_within_limits(labels: &LabelSet) {
    let mut total = 0usize;
    for f in &labels.frames {
        for s in &f.strokes {
            assert!(
                s.radius > 0.0 && s.radius <= label_limits::MAX_RADIUS,
                "frame {}: accepted radius {}",
                f.frame,
                s.radius
            );
            assert!(s.points.len() <= label_limits::MAX_POINTS_PER_STROKE);
            total += s.points.len();
        }
    }
    assert!(total <= label_limits::MAX_TOTAL_POINTS, "accepted {total} points");
}

/// Rasterizes every labelled frame at [`RASTER_SIZE`], as the page does on load.
fn rasterize_all(labels: &LabelSet) {
    for f in &labels.frames {
        let mask = crate::scene::label_set::rasterize_frame(Some(f), RASTER_SIZE.0, RASTER_SIZE.1);
        assert_eq!(mask.len(), (RASTER_SIZE.0 * RASTER_SIZE.1) as usize);
    }
}
