//! Writing a scene archive: the manifest that describes a scene as laid out, and the zip.
use std::io::{Cursor, Seek, Write};
use std::path::Path;

use image::{DynamicImage, ImageFormat};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipWriter};

use super::{check_gt_classes, check_manifest};
use crate::scene::decoded::Scene;
use crate::scene::error::{Result, SceneError};
use crate::scene::manifest::{FeatureEntry, FrameEntry, MANIFEST_FILE, Manifest, SCENE_FORMAT, SCENE_VERSION};

/// Entry names used by the writer.
fn frame_entry(dir: &str, i: usize) -> String {
    format!("{dir}/{i:05}.png")
}

/// Builds the manifest that describes `scene` as the writer lays it out.
pub fn manifest_of(scene: &Scene) -> Manifest {
    let frames = scene
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| FrameEntry {
            rgb: frame_entry("rgb", i),
            depth: f.depth.as_ref().map(|_| frame_entry("depth", i)),
            gt: f.gt.as_ref().map(|_| frame_entry("gt", i)),
            pose: f.pose.to_row_major(),
            source: f.source.clone(),
        })
        .collect();
    Manifest {
        format: SCENE_FORMAT.into(),
        version: SCENE_VERSION,
        frame_count: scene.frames.len() as u32,
        width: scene.width,
        height: scene.height,
        intrinsics: scene.intrinsics,
        depth_scale: scene.depth_scale,
        bounds: scene.bounds,
        frames,
        features: scene.features.as_ref().map(|f| FeatureEntry {
            file: "features.f16".into(),
            height: f.height,
            width: f.width,
            dim: f.dim,
            extractor: f.extractor.clone(),
            pca: f.pca.clone(),
        }),
        classes: scene.classes.clone(),
        labels: scene.labels.as_ref().map(|_| "labels.json".into()),
        provenance: scene.provenance.clone(),
    }
}

fn encode_png(img: &DynamicImage) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png)
        .expect("PNG encoding into memory cannot fail");
    out.into_inner()
}

/// Writes `scene` as an archive into any seekable writer. The scene is checked first, so a
/// written archive always reads back.
pub fn write_archive<W: Write + Seek>(scene: &Scene, out: W) -> Result<W> {
    let manifest = manifest_of(scene);
    check_manifest(&manifest, "scene to write")?;
    for (i, f) in scene.frames.iter().enumerate() {
        f.pose
            .check()
            .map_err(|p| SceneError::invalid("scene to write", format!("frame {i}: {p}")))?;
        let dims_ok = f.rgb.dimensions() == (scene.width, scene.height)
            && f.depth
                .as_ref()
                .is_none_or(|d| d.dimensions() == (scene.width, scene.height))
            && f.gt
                .as_ref()
                .is_none_or(|g| g.dimensions() == (scene.width, scene.height));
        if !dims_ok {
            return Err(SceneError::invalid(
                "scene to write",
                format!("frame {i}: image sizes differ from the scene's"),
            ));
        }
        if let Some(g) = &f.gt {
            check_gt_classes(g, scene.classes.len(), "scene to write", i)?;
        }
    }
    if let Some(f) = &scene.features
        && f.data.len() != f.values_per_frame() * scene.frames.len()
    {
        return Err(SceneError::invalid(
            "scene to write",
            "feature codes do not match frames x grid x dim",
        ));
    }
    if let Some(l) = &scene.labels {
        l.check("scene to write: labels", scene.frames.len() as u32)?;
    }

    let zip_err = |source| SceneError::Zip {
        file: "scene to write".into(),
        source,
    };
    let io_err = |e| SceneError::io("scene to write", e);
    let mut zip = ZipWriter::new(out);
    let stored = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .large_file(false);
    let deflated = SimpleFileOptions::default().compression_method(CompressionMethod::Deflated);

    let json = serde_json::to_vec_pretty(&manifest).expect("manifest always serializes");
    zip.start_file(MANIFEST_FILE, deflated).map_err(zip_err)?;
    zip.write_all(&json).map_err(io_err)?;
    for (f, fe) in scene.frames.iter().zip(&manifest.frames) {
        zip.start_file(fe.rgb.as_str(), stored).map_err(zip_err)?;
        zip.write_all(&encode_png(&DynamicImage::ImageRgb8(f.rgb.clone())))
            .map_err(io_err)?;
        if let (Some(d), Some(name)) = (&f.depth, &fe.depth) {
            zip.start_file(name.as_str(), stored).map_err(zip_err)?;
            zip.write_all(&encode_png(&DynamicImage::ImageLuma16(d.clone())))
                .map_err(io_err)?;
        }
        if let (Some(g), Some(name)) = (&f.gt, &fe.gt) {
            zip.start_file(name.as_str(), stored).map_err(zip_err)?;
            zip.write_all(&encode_png(&DynamicImage::ImageLuma8(g.clone())))
                .map_err(io_err)?;
        }
    }
    if let (Some(f), Some(fe)) = (&scene.features, &manifest.features) {
        zip.start_file(
            fe.file.as_str(),
            deflated.large_file(f.data.len() * 2 >= u32::MAX as usize),
        )
        .map_err(zip_err)?;
        let bytes: Vec<u8> = f.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        zip.write_all(&bytes).map_err(io_err)?;
    }
    if let (Some(l), Some(name)) = (&scene.labels, &manifest.labels) {
        zip.start_file(name.as_str(), deflated).map_err(zip_err)?;
        zip.write_all(l.to_json().as_bytes()).map_err(io_err)?;
    }
    zip.finish().map_err(zip_err)
}

/// Writes `scene` to a file, through a temporary sibling so a failed write never leaves a
/// half-written archive where a good one was.
pub fn write_archive_path(scene: &Scene, path: &Path) -> Result<()> {
    let tmp = path.with_extension("zip.partial");
    let file = std::fs::File::create(&tmp).map_err(|e| SceneError::io(&tmp, e))?;
    let result = write_archive(scene, std::io::BufWriter::new(file)).and_then(|w| {
        w.into_inner()
            .map_err(|e| SceneError::io(&tmp, e.into_error()))
            .map(drop)
    });
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| SceneError::io(path, e))
}

/// Writes to memory (the browser's download path, and tests).
pub fn write_archive_bytes(scene: &Scene) -> Result<Vec<u8>> {
    Ok(write_archive(scene, Cursor::new(Vec::new()))?.into_inner())
}
