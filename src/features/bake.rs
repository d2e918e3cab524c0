//! Making the archive's codes (docs/features.md): every frame's feature map, an autoencoder fitted on
//! all of them, the codes of every cell, and their PCA for display.
use half::f16;

use super::autoencoder::{Autoencoder, AutoencoderConfig, FitReport};
use super::{FeatureError, FeatureMap};
use crate::pause::{NoPause, Pause, run_to_end};
use crate::rng::SplitMix64;
use crate::scene::{FeatureCodes, Pca};

#[derive(Clone, Debug, PartialEq)]
pub struct BakeOptions {
    pub autoencoder: AutoencoderConfig,
    /// Cells sampled (without replacement, seeded) to fit the autoencoder; more cost memory,
    /// not time (the step count fixes that).
    pub max_fit_cells: usize,
    /// The codes are scaled by one factor so their root mean square is this. The trainer's
    /// feature loss is an L1 between rendered features and codes next to a colour loss on
    /// values in [0, 1], and the autoencoder's code scale is arbitrary (its decoder can undo
    /// any scale), so this fixes the balance the loss weight then tunes.
    pub code_rms: f32,
}

impl Default for BakeOptions {
    fn default() -> Self {
        BakeOptions {
            autoencoder: AutoencoderConfig::default(),
            max_fit_cells: 200_000,
            code_rms: 0.25,
        }
    }
}

/// Where baking is, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BakeProgress {
    Extracting { done: usize, total: usize },
    Fitting { step: u32, steps: u32, loss: f64 },
    Encoding,
}

/// What baking produced.
pub struct Baked {
    pub codes: FeatureCodes,
    pub fit: FitReport,
    /// Dimension of the extractor's features before the autoencoder.
    pub input_dim: u32,
}

/// Bakes codes for `frames` frames; `map_of(i)` gives frame i's feature map (all must share
/// grid and dimension). `extractor` describes where the maps came from, for the archive.
pub fn bake(
    frames: usize,
    map_of: impl FnMut(usize) -> Result<FeatureMap, FeatureError>,
    extractor: &str,
    opts: &BakeOptions,
    progress: impl FnMut(BakeProgress),
) -> Result<Baked, FeatureError> {
    run_to_end(bake_pausing(frames, map_of, extractor, opts, progress, &mut NoPause))
}

/// [`bake`] that calls `pause` after each frame's map and each autoencoder step, for the page,
/// which bakes on the thread that also draws (`crate::pause`).
pub async fn bake_pausing(
    frames: usize,
    mut map_of: impl FnMut(usize) -> Result<FeatureMap, FeatureError>,
    extractor: &str,
    opts: &BakeOptions,
    mut progress: impl FnMut(BakeProgress),
    pause: &mut impl Pause,
) -> Result<Baked, FeatureError> {
    let mut maps = Vec::with_capacity(frames);
    for i in 0..frames {
        let map = map_of(i)?;
        if let Some(first) = maps.first() {
            let first: &FeatureMap = first;
            if (map.height, map.width, map.dim) != (first.height, first.width, first.dim) {
                return Err(FeatureError::Frame {
                    frame: i,
                    problem: format!(
                        "feature map is {}x{}x{} but frame 0's is {}x{}x{} (every frame's map must have the same shape)",
                        map.height, map.width, map.dim, first.height, first.width, first.dim
                    ),
                });
            }
        }
        maps.push(map);
        progress(BakeProgress::Extracting {
            done: i + 1,
            total: frames,
        });
        pause.pause().await;
    }
    let Some(first) = maps.first() else {
        return Err(FeatureError::invalid("scene", "no frames to extract features from"));
    };
    let (height, width, dim) = (first.height, first.width, first.dim as usize);
    let cells_per_frame = (height * width) as usize;
    let total_cells = cells_per_frame * frames;

    let fit_cells = sample_cells(total_cells, opts.max_fit_cells, opts.autoencoder.seed);
    let mut fit_rows = Vec::with_capacity(fit_cells.len() * dim);
    for &c in &fit_cells {
        let (f, cell) = (c / cells_per_frame, c % cells_per_frame);
        fit_rows.extend_from_slice(&maps[f].data[cell * dim..(cell + 1) * dim]);
    }
    let (ae, fit) = Autoencoder::fit_pausing(
        &fit_rows,
        dim,
        &opts.autoencoder,
        |step, steps, loss| progress(BakeProgress::Fitting { step, steps, loss }),
        pause,
    )
    .await;
    drop(fit_rows);
    progress(BakeProgress::Encoding);

    let code_dim = ae.code_dim();
    let mut codes: Vec<f32> = Vec::with_capacity(total_cells * code_dim);
    for map in &maps {
        codes.extend(ae.encode(&map.data));
    }
    let rms = (codes.iter().map(|&c| (c as f64) * (c as f64)).sum::<f64>() / codes.len().max(1) as f64).sqrt();
    if rms > 0.0 {
        let scale = (opts.code_rms as f64 / rms) as f32;
        codes.iter_mut().for_each(|c| *c *= scale);
    }
    let pca_cells = sample_cells(total_cells, 20_000, opts.autoencoder.seed ^ 1);
    let mut pca_rows = Vec::with_capacity(pca_cells.len() * code_dim);
    for &c in &pca_cells {
        pca_rows.extend_from_slice(&codes[c * code_dim..(c + 1) * code_dim]);
    }
    let pca = Pca::fit(&pca_rows, code_dim)
        .ok_or_else(|| FeatureError::invalid("scene", "too few feature cells to fit the display PCA"))?;
    Ok(Baked {
        codes: FeatureCodes {
            height,
            width,
            dim: code_dim as u32,
            extractor: format!(
                "{extractor}; autoencoder {dim} -> {} -> {code_dim} (reconstruction MSE {:.3} of standardized features, code sparsity {:.2})",
                opts.autoencoder.hidden, fit.reconstruction_mse, fit.code_sparsity
            ),
            data: codes.iter().map(|&c| f16::from_f32(c)).collect(),
            pca,
        },
        fit,
        input_dim: dim as u32,
    })
}

/// Up to `max` distinct cell indices below `total`, ascending (a seeded partial shuffle).
fn sample_cells(total: usize, max: usize, seed: u64) -> Vec<usize> {
    if total <= max {
        return (0..total).collect();
    }
    let mut idx: Vec<usize> = (0..total).collect();
    let mut rng = SplitMix64::new(seed ^ 0x5eed_ce11);
    for i in 0..max {
        let j = i + rng.below((total - i) as u64) as usize;
        idx.swap(i, j);
    }
    idx.truncate(max);
    idx.sort_unstable();
    idx
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(seed: u64) -> FeatureMap {
        let mut rng = SplitMix64::new(seed);
        let data = (0..6 * 8 * 5).map(|_| rng.next_f32()).collect();
        FeatureMap {
            height: 6,
            width: 8,
            dim: 5,
            data,
        }
    }

    #[test]
    fn baking_gives_scaled_codes_of_every_cell_and_a_pca() {
        let mut opts = BakeOptions::default();
        opts.autoencoder.steps = 20;
        opts.autoencoder.hidden = 16;
        opts.autoencoder.code = 8;
        let mut events = Vec::new();
        let baked = bake(3, |i| Ok(map(i as u64)), "test", &opts, |p| events.push(p)).unwrap();
        let c = &baked.codes;
        assert_eq!((c.height, c.width, c.dim), (6, 8, 8));
        assert_eq!(c.data.len(), 3 * 6 * 8 * 8);
        let rms = (c.data.iter().map(|v| v.to_f32().powi(2)).sum::<f32>() / c.data.len() as f32).sqrt();
        assert!((rms - 0.25).abs() < 0.01, "rms {rms}");
        assert!(c.data.iter().all(|v| v.to_f32() >= 0.0));
        assert_eq!(c.pca.mean.len(), 8);
        assert!(c.extractor.starts_with("test; autoencoder 5 -> 16 -> 8"));
        assert_eq!(events[2], BakeProgress::Extracting { done: 3, total: 3 });
        assert_eq!(*events.last().unwrap(), BakeProgress::Encoding);
    }

    #[test]
    fn a_frame_whose_map_differs_in_shape_is_named() {
        let err = bake(
            2,
            |i| Ok(if i == 0 { map(0) } else { FeatureMap::zeros(6, 7, 5) }),
            "test",
            &BakeOptions::default(),
            |_| {},
        )
        .err()
        .unwrap()
        .to_string();
        assert!(
            err.starts_with("frame 1: feature map is 6x7x5 but frame 0's is 6x8x5"),
            "{err}"
        );
    }

    #[test]
    fn cell_samples_are_distinct_and_bounded() {
        let s = sample_cells(1000, 100, 3);
        assert_eq!(s.len(), 100);
        assert!(s.windows(2).all(|w| w[0] < w[1]) && *s.last().unwrap() < 1000);
        assert_eq!(sample_cells(10, 100, 3), (0..10).collect::<Vec<_>>());
    }
}
