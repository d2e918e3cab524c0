//! The parameter layout: every trainable value of the field in one flat `f32` buffer.
//!
//! The CPU reference and the GPU trainer share this layout exactly: the GPU uploads the
//! buffer built by [`ParamLayout::init`] as one storage buffer, writes its gradient into a
//! buffer of the same length, and Adam walks both element by element. In order:
//!
//! 1. `hash_table`: the levels one after the other, level `l` holding
//!    `min((res_l+1)³, 2^log2_table)` entries of `features` values (a coarse level whose vertex
//!    grid fits the table is indexed densely and holds only its vertices), value at
//!    `(level_offset(l) + entry) · features + feature` (`reference::hash_grid::HashGrid`;
//!    `hash_levels` has each level's range). Empty for `FreqOnly`.
//! 2. the density, colour, feature and semantic MLPs, in that order, each layer after the
//!    previous one. A layer mapping `in → out` is a row-major `[out][in]` matrix: weight
//!    `(o, i)` is at `layer_start + o · in + i`. No biases anywhere.
//!
//! Initialisation is deterministic from a seed: the table is uniform in ±1e-4 (instant-ngp's
//! choice: near-zero features so early training is driven by the MLPs; drawn as if every level
//! held a full table, keeping the values of the entries that exist, so a field starts from the
//! values it had before the dense levels shrank and trains exactly as it did), a layer followed by a
//! ReLU is He/Kaiming-uniform (±√(6/in)), and an output layer (no ReLU after it) is
//! LeCun-uniform (±√(3/in)) so outputs start with unit-order variance.
use std::ops::Range;

use super::config::FieldConfig;
use super::reference::hash_grid::HashGrid;
use crate::rng::SplitMix64;

/// Half-width of the uniform initialisation of the hash table.
pub const HASH_INIT_RANGE: f32 = 1e-4;

/// Where one MLP's layers live in the flat buffer.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MlpLayout {
    /// Layer sizes [in, hidden…, out].
    pub dims: Vec<usize>,
    /// Range of every layer's `[out][in]` weight matrix; `layers.len() == dims.len() - 1`.
    pub layers: Vec<Range<usize>>,
}

impl MlpLayout {
    fn new(dims: Vec<usize>, start: &mut usize) -> MlpLayout {
        let layers = dims
            .windows(2)
            .map(|io| {
                let range = *start..*start + io[0] * io[1];
                *start = range.end;
                range
            })
            .collect();
        MlpLayout { dims, layers }
    }

    /// The whole MLP (all layers, contiguous).
    pub fn range(&self) -> Range<usize> {
        let start = self.layers.first().map_or(0, |r| r.start);
        let end = self.layers.last().map_or(start, |r| r.end);
        start..end
    }

    pub fn input_dim(&self) -> usize {
        self.dims[0]
    }

    pub fn output_dim(&self) -> usize {
        self.dims[self.dims.len() - 1]
    }
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamLayout {
    pub hash_table: Range<usize>,
    /// Each level's values within the flat buffer (inside `hash_table`, in order).
    pub hash_levels: Vec<Range<usize>>,
    /// Entries of a hashed level (`2^log2_hash_table_size`) and values per entry.
    pub hash_table_size: usize,
    pub hash_features: usize,
    pub density: MlpLayout,
    pub color: MlpLayout,
    pub feature: MlpLayout,
    pub semantic: MlpLayout,
    /// Length of the flat buffer.
    pub total: usize,
}

impl ParamLayout {
    /// The layout of `cfg` (which should have passed `validate`).
    pub fn new(cfg: &FieldConfig) -> ParamLayout {
        let grid = HashGrid::from_config(cfg);
        let table = grid.param_count();
        let hash_levels = grid
            .level_offsets
            .windows(2)
            .map(|w| w[0] * grid.features..w[1] * grid.features)
            .collect();
        let mut next = table;
        let density = MlpLayout::new(cfg.density_dims(), &mut next);
        let color = MlpLayout::new(cfg.color_dims(), &mut next);
        let feature = MlpLayout::new(cfg.feature_dims(), &mut next);
        let semantic = MlpLayout::new(cfg.semantic_dims(), &mut next);
        ParamLayout {
            hash_table: 0..table,
            hash_levels,
            hash_table_size: grid.table_size,
            hash_features: grid.features,
            density,
            color,
            feature,
            semantic,
            total: next,
        }
    }

    pub fn mlps(&self) -> [(&'static str, &MlpLayout); 4] {
        [
            ("density", &self.density),
            ("color", &self.color),
            ("feature", &self.feature),
            ("semantic", &self.semantic),
        ]
    }

    /// Every named range in buffer order (`hash_table`, `density.0`, `density.1`, …), for
    /// documentation, debugging and GPU binding offsets.
    pub fn named_ranges(&self) -> Vec<(String, Range<usize>)> {
        let mut out = vec![("hash_table".to_string(), self.hash_table.clone())];
        for (name, mlp) in self.mlps() {
            for (k, r) in mlp.layers.iter().enumerate() {
                out.push((format!("{name}.{k}"), r.clone()));
            }
        }
        out
    }

    /// Deterministic initial parameters (see the module docs for the distributions).
    pub fn init(&self, seed: u64) -> Vec<f32> {
        let mut params = vec![0.0f32; self.total];
        let mut rng = SplitMix64::new(seed);
        // Every level draws a full table's values (level by level, entry by entry, as the
        // layout of one full table per level stored them) and keeps the first ones, those of
        // the entries it has.
        let full_level = self.hash_table_size * self.hash_features;
        for level in &self.hash_levels {
            let mut kept = params[level.clone()].iter_mut();
            for _ in 0..full_level {
                let v = (rng.uniform(-1.0, 1.0) * HASH_INIT_RANGE as f64) as f32;
                if let Some(p) = kept.next() {
                    *p = v;
                }
            }
        }
        for (_, mlp) in self.mlps() {
            let last = mlp.layers.len() - 1;
            for (k, range) in mlp.layers.iter().enumerate() {
                let fan_in = mlp.dims[k] as f64;
                let bound = if k == last {
                    (3.0 / fan_in).sqrt()
                } else {
                    (6.0 / fan_in).sqrt()
                };
                for p in &mut params[range.clone()] {
                    *p = rng.uniform(-bound, bound) as f32;
                }
            }
        }
        params
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_tile_the_buffer_in_order() {
        let layout = ParamLayout::new(&FieldConfig::default());
        let mut end = 0;
        for (name, r) in layout.named_ranges() {
            assert_eq!(r.start, end, "{name} does not follow the previous range");
            end = r.end;
        }
        assert_eq!(end, layout.total);
        // (17³ + 33³ + 65³ + 13 × 2^19) × 2 + density 44·128+128·128+128·16 + colour 31·128+128·128+128·3
        // + feature 15·64+64·64+64·64 + semantic 64·64+64·2 (relu(f) alone; 79·64+64·2 with g).
        assert_eq!(layout.hash_table.len(), 14_262_438);
        assert_eq!(layout.hash_levels.len(), 16);
        assert_eq!(layout.hash_levels[0], 0..4913 * 2);
        assert_eq!(layout.hash_levels[15].end, layout.hash_table.end);
        assert_eq!(layout.total - layout.hash_table.len(), 24_064 + 20_736 + 9_152 + 4_224);
    }

    #[test]
    fn init_keeps_the_values_a_full_table_per_level_had() {
        // Drawn as when every level held 2^log2 entries: the entries that exist keep their
        // values, and the MLPs after the table are drawn from the same place in the stream.
        let cfg = FieldConfig::small();
        let layout = ParamLayout::new(&cfg);
        let params = layout.init(5);
        let mut rng = SplitMix64::new(5);
        let full: Vec<f32> = (0..cfg.hash_levels as usize * cfg.hash_table_size() * 2)
            .map(|_| (rng.uniform(-1.0, 1.0) * HASH_INIT_RANGE as f64) as f32)
            .collect();
        for (level, range) in layout.hash_levels.iter().enumerate() {
            let start = level * cfg.hash_table_size() * 2;
            assert_eq!(
                &params[range.clone()],
                &full[start..start + range.len()],
                "level {level}"
            );
        }
        assert!(
            layout.hash_levels[0].len() < cfg.hash_table_size() * 2,
            "level 0 is dense"
        );
        let first = layout.density.layers[0].clone();
        let bound = (6.0 / cfg.encoding_dim() as f64).sqrt();
        assert_eq!(params[first.start], rng.uniform(-bound, bound) as f32);
    }

    #[test]
    fn init_is_deterministic_and_bounded() {
        let cfg = FieldConfig::small();
        let layout = ParamLayout::new(&cfg);
        let a = layout.init(3);
        assert_eq!(a, layout.init(3));
        assert_ne!(a, layout.init(4));
        assert!(a[layout.hash_table.clone()].iter().all(|v| v.abs() <= HASH_INIT_RANGE));
        let first = &a[layout.density.layers[0].clone()];
        let bound = (6.0f32 / cfg.encoding_dim() as f32).sqrt();
        assert!(first.iter().all(|v| v.abs() <= bound));
        // A uniform ±b has variance b²/3; check the spread is really He's, not something smaller.
        let var = first.iter().map(|v| v * v).sum::<f32>() / first.len() as f32;
        assert!((var / (bound * bound / 3.0) - 1.0).abs() < 0.1, "variance {var}");
    }
}
