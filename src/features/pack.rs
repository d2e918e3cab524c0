//! Packing a capture held in memory into a scene archive, as `pack` does on the command line:
//! the same importers (reading the files given instead of the disk), the weight-free baseline
//! features and their autoencoder, the same archive writer. The page runs this on its one thread
//! with a pause that gives the thread back ([`crate::pause`]): after every frame imported, every
//! frame's features and every autoencoder step.
use std::rc::Rc;

use super::bake::{BakeOptions, BakeProgress, bake_pausing};
use super::{Baseline, Extractor, FeatureError};
use crate::pause::Pause;
use crate::scene::SceneError;
use crate::scene::archive::write_archive_bytes;
use crate::scene::import::{ImportOptions, Layout, MemoryFiles, import_files};

/// What to pack, besides the capture's own files.
#[derive(Clone, Debug, PartialEq)]
pub struct PackOptions {
    /// Which frames, at what size (`pack --max-size`, `--every`, `--max-frames`, ...).
    pub import: ImportOptions,
    /// Baseline feature codes (`pack --features baseline`), or none.
    pub features: Option<BaselineFeatures>,
}

/// `pack --features baseline --feature-stride S --autoencoder-steps N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BaselineFeatures {
    pub stride: u32,
    pub autoencoder_steps: u32,
}

/// Where packing is, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PackProgress {
    /// Frames decoded (ScanNet counts colour and depth separately: `total` is twice its frames).
    Importing {
        done: usize,
        total: usize,
    },
    Features(BakeProgress),
    Writing,
}

/// A packed capture.
pub struct Packed {
    /// The `.scene.zip`'s bytes, as `pack -o` would write them.
    pub archive: Vec<u8>,
    pub layout: Layout,
    /// What the importer guessed, ignored or skipped (`pack` prints them as warnings).
    pub warnings: Vec<String>,
    /// What the user should see without asking (`pack` prints these lines).
    pub report: Vec<String>,
    /// The scene's summary (`pack` and `info` print it).
    pub summary: String,
    /// The features line `pack` prints, when there are features.
    pub features: Option<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("features: {0}")]
    Features(#[from] FeatureError),
}

/// Packs the capture in `files` (its root folder; see [`MemoryFiles::root`]).
pub async fn pack_files<P: Pause>(
    files: Rc<MemoryFiles>,
    opts: &PackOptions,
    mut progress: impl FnMut(PackProgress),
    pause: &mut P,
) -> Result<Packed, PackError> {
    let imported = import_files(
        files,
        &opts.import,
        &mut |done, total| progress(PackProgress::Importing { done, total }),
        pause,
    )
    .await?;
    let mut scene = imported.scene;
    let mut features = None;
    if let Some(f) = opts.features {
        let extractor = Baseline::with_stride(f.stride);
        let mut bake = BakeOptions::default();
        bake.autoencoder.steps = f.autoencoder_steps.max(1);
        let frames = &scene.frames;
        let baked = bake_pausing(
            frames.len(),
            |i| extractor.extract(&frames[i].rgb).map_err(|e| e.at_frame(i)),
            &extractor.describe(),
            &bake,
            |p| progress(PackProgress::Features(p)),
            pause,
        )
        .await?;
        features = Some(format!(
            "features: {} -> {} dims on a {} x {} grid; autoencoder reconstruction MSE {:.3} (mean predictor: {:.3}), \
             code sparsity {:.2}",
            baked.input_dim,
            baked.codes.dim,
            baked.codes.width,
            baked.codes.height,
            baked.fit.reconstruction_mse,
            baked.fit.baseline_mse,
            baked.fit.code_sparsity
        ));
        scene.features = Some(baked.codes);
    }
    progress(PackProgress::Writing);
    pause.pause().await;
    let archive = write_archive_bytes(&scene)?;
    Ok(Packed {
        archive,
        layout: imported.layout,
        warnings: imported.warnings,
        report: imported.report,
        summary: scene.summary(),
        features,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pause::{CountPauses, run_to_end};
    use crate::scene::read_archive;

    /// A transforms.json capture of `n` 16x12 frames, in memory.
    fn capture(n: usize) -> MemoryFiles {
        let mut files = MemoryFiles::new();
        let mut frames = Vec::new();
        for i in 0..n {
            let img = image::RgbImage::from_fn(16, 12, |x, y| {
                image::Rgb([(x * 15) as u8, (y * 20) as u8, (i * 40) as u8])
            });
            let mut png = Vec::new();
            img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
                .unwrap();
            files.add(&format!("cap/images/{i}.png"), png).unwrap();
            frames.push(serde_json::json!({
                "file_path": format!("images/{i}.png"),
                "transform_matrix": [[1, 0, 0, i as f64 * 0.1], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]],
            }));
        }
        let json = serde_json::json!({ "camera_angle_x": 0.8, "frames": frames });
        files
            .add("cap/transforms.json", serde_json::to_vec(&json).unwrap())
            .unwrap();
        files
    }

    #[test]
    fn a_capture_in_memory_packs_with_features_pausing_as_it_goes() {
        let opts = PackOptions {
            import: ImportOptions {
                max_size: Some(8),
                ..Default::default()
            },
            features: Some(BaselineFeatures {
                stride: 2,
                autoencoder_steps: 30,
            }),
        };
        let mut events = Vec::new();
        let mut pauses = CountPauses::default();
        let packed = run_to_end(pack_files(Rc::new(capture(3)), &opts, |p| events.push(p), &mut pauses)).unwrap();
        assert_eq!(packed.layout, Layout::Transforms);
        // A pause per frame imported, per frame's features, per autoencoder step, and before writing.
        assert_eq!(pauses.0, 3 + 3 + 30 + 1);
        assert!(events.contains(&PackProgress::Importing { done: 3, total: 3 }));
        assert!(events.contains(&PackProgress::Features(BakeProgress::Extracting { done: 3, total: 3 })));
        assert_eq!(events.last(), Some(&PackProgress::Writing));
        let scene = read_archive(&packed.archive, "packed").unwrap();
        assert_eq!((scene.width, scene.height, scene.frames.len()), (8, 6, 3));
        let codes = scene.features.unwrap();
        assert_eq!((codes.width, codes.height), (4, 3));
        assert_eq!(scene.provenance.source, "cap");
        assert!(
            packed
                .features
                .unwrap()
                .starts_with("features: 30 -> 64 dims on a 4 x 3 grid")
        );
    }

    #[test]
    fn a_folder_of_no_known_layout_gets_the_command_lines_error() {
        let mut files = MemoryFiles::new();
        files.add("holiday/photo.jpg", vec![1, 2, 3]).unwrap();
        let opts = PackOptions {
            import: ImportOptions::default(),
            features: None,
        };
        let err = run_to_end(pack_files(Rc::new(files), &opts, |_| {}, &mut CountPauses::default()))
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.starts_with("holiday: not a capture layout scribblefield knows; expected one of: an autolabel"),
            "{err}"
        );
    }

    #[test]
    fn a_bad_file_is_named_as_on_the_command_line() {
        let mut broken = MemoryFiles::new();
        broken.add("cap/transforms.json", b"{\"frames\": 3}".to_vec()).unwrap();
        let opts = PackOptions {
            import: ImportOptions::default(),
            features: None,
        };
        let err = run_to_end(pack_files(Rc::new(broken), &opts, |_| {}, &mut CountPauses::default()))
            .err()
            .unwrap()
            .to_string();
        assert!(err.starts_with("cap/transforms.json: "), "{err}");
    }
}
