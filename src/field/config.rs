//! The field's configuration: architecture, sampling, losses and optimiser (docs/architecture.md, "The model").
//!
//! Every size the CPU reference and the GPU kernels need is derived from here (see the
//! `*_dims` methods), so the two cannot disagree about a shape. Deserialising fills missing
//! fields with the defaults and rejects unknown ones, so a `--config` file may name only what
//! it changes and a typo fails loudly; `validate` then checks every value.
use serde::{Deserialize, Serialize};

use crate::spread::PropagationOptions;

/// How a normalized position p ∈ [0,1]³ is encoded before the density MLP.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Encoding {
    /// Multiresolution hash grid concatenated with a sin/cos encoding of `frequencies`
    /// octaves (the paper's choice; 16·2 + 6·2 = 44 values by default).
    HashFreq { frequencies: u32 },
    /// Sin/cos encoding only (the NeRF-style baseline; 6·L values).
    FreqOnly { frequencies: u32 },
    /// Hash grid only (the instant-ngp baseline).
    HashOnly,
}

impl Encoding {
    pub fn uses_hash_grid(&self) -> bool {
        !matches!(self, Encoding::FreqOnly { .. })
    }

    /// Octaves of the frequency encoding; 0 when it is not used.
    pub fn frequencies(&self) -> u32 {
        match *self {
            Encoding::HashFreq { frequencies } | Encoding::FreqOnly { frequencies } => frequencies,
            Encoding::HashOnly => 0,
        }
    }

    /// The paper's frequency-only baseline (L = 10).
    pub fn freq_only_baseline() -> Encoding {
        Encoding::FreqOnly { frequencies: 10 }
    }
}

impl Default for Encoding {
    fn default() -> Self {
        Encoding::HashFreq { frequencies: 2 }
    }
}

/// The semantic head's input.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SemanticInput {
    /// `Feature` when feature supervision is on, `FeatureAndGeometry` when it is off.
    #[default]
    Auto,
    /// [relu(f), g]: the paper's head.
    FeatureAndGeometry,
    /// relu(f) alone, so classes follow the rendered features, which feature supervision ties
    /// to the image's codes, and not the shading g carries for the colour head: with it, the
    /// masks were better and far less seed-dependent. Without feature supervision f holds
    /// nothing the codes put there, and this head generalized worse than the paper's, hence
    /// `Auto` (docs/results/measurements.md has the numbers).
    Feature,
}

/// What a ray renders behind its last sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LastSample {
    /// `Opaque` on a capture without dense depth (a photo capture: no depth, or a
    /// reconstruction's sparse points), `Clear` otherwise; the trainer decides from its scene
    /// (`FieldConfig::for_scene`).
    #[default]
    Auto,
    /// The last sample takes all the transmittance the ray has left
    /// (`reference::render::OPAQUE_INTERVAL`), so what lies beyond the scene box (a photo
    /// capture's room, which the box drawn around the reconstruction's points leaves out) is
    /// painted on the samples at the box's far side, without density that would stand in front
    /// of the box's contents in other views. With dense depth everything seen is in the box,
    /// and it made the masks worse (docs/results/quality-log.md, "The room beyond the box").
    Opaque,
    /// Nothing behind the last sample: a ray that meets nothing in the box renders 0.
    Clear,
}

/// Weights of the loss terms (docs/architecture.md, "The model").
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LossWeights {
    pub rgb: f32,
    pub depth: f32,
    pub semantic: f32,
    pub feature: f32,
    /// Where rays end in an opaque sample and the labels name the class of what lies beyond
    /// the scene box (`PropagationCache::far_class`): a labelled ray's transmittance left for
    /// that sample is pulled to 1 when its label is that class and to 0 otherwise
    /// (`reference::loss::opacity_loss`; docs/results/quality-log.md, "The labels say what is empty").
    pub opacity: f32,
}

impl Default for LossWeights {
    fn default() -> Self {
        LossWeights {
            rgb: 1.0,
            depth: 0.1,
            semantic: 1.0,
            feature: 0.5,
            opacity: 1.0,
        }
    }
}

/// Adam with bias correction (see `reference::adam` for the exact update the GPU must match).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdamConfig {
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
    /// Learning rate while warming up on colour, depth and features without labels.
    pub lr_warmup: f32,
    /// Learning rate once the user annotates (smaller, so the geometry learned so far stays).
    pub lr_annotating: f32,
}

impl Default for AdamConfig {
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.99,
            epsilon: 1e-15,
            lr_warmup: 5e-3,
            lr_annotating: 1e-3,
        }
    }
}

/// The whole model configuration. `Default` is the full model (the `full` preset; hash table 2^19 per level).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FieldConfig {
    pub encoding: Encoding,
    /// Hash-grid levels (ignored by `FreqOnly`).
    pub hash_levels: u32,
    pub hash_features_per_level: u32,
    /// Entries per level = 2^log2_hash_table_size.
    pub log2_hash_table_size: u32,
    /// Cells per axis of the coarsest level.
    pub hash_base_resolution: u32,
    /// Growth of the resolution from one level to the next.
    pub hash_level_scale: f32,
    /// Hidden width and number of hidden layers of the density MLP.
    pub density_width: u32,
    pub density_layers: u32,
    /// Geometry feature passed on from the density MLP (its output is 1 + this: h₀ gives σ).
    pub geometry_dim: u32,
    pub color_width: u32,
    pub color_layers: u32,
    pub feature_width: u32,
    pub feature_layers: u32,
    /// Dimension of the rendered feature f (and of the archive's codes).
    pub feature_dim: u32,
    /// Hidden width of the semantic head (one hidden layer).
    pub semantic_width: u32,
    pub num_classes: u32,
    /// Whether the 0.5·|f̂ − code|₁ term is trained. Off keeps the architecture unchanged
    /// and only drops the loss term, so the ablation measures the supervision alone.
    pub feature_supervision: bool,
    /// Samples spread stratified over the whole clipped ray [near, far].
    pub samples_coarse: u32,
    /// Samples stratified in the band around the measured depth (spread over [near, far] too
    /// when the ray has no valid depth, so every ray has the same sample count).
    pub samples_fine: u32,
    /// Half-width of the band around the measured surface, as a fraction of the scene box
    /// diagonal (0.02 of a 1.5 m box is 3 cm, a few times the sensor noise).
    pub surface_band_fraction: f32,
    pub loss: LossWeights,
    pub adam: AdamConfig,
    pub batch_rays: u32,
    /// How much of the semantic loss's gradient flows from the semantic head into the shared
    /// field (the feature MLP, the density MLP and the encoding): 1 is the paper's model, 0 trains
    /// the head alone on features shaped by colour, depth and feature codes.
    pub semantic_trunk_gradient: f32,
    /// Compositing weight (α·T, as the composite computes it from the density alone) below
    /// which a sample skips the colour, feature and semantic heads: its head outputs count as 0
    /// in the render and it gets no head gradient, while its density still shapes the
    /// transmittance and the depth. Samples far behind a surface or in empty space have weights
    /// far below it, so the heads run on a fraction of the samples. 0 keeps every sample (the
    /// heads see exactly what they would without the rule).
    pub head_weight_threshold: f32,
    /// What a ray renders behind its last sample (see `LastSample`).
    pub last_sample: LastSample,
    /// What the semantic head sees (see `SemanticInput`).
    pub semantic_input: SemanticInput,
    /// How strokes spread inside their own frame before training (`spread::propagate`).
    pub scribble_propagation: PropagationOptions,
}

impl Default for FieldConfig {
    fn default() -> Self {
        FieldConfig {
            encoding: Encoding::default(),
            hash_levels: 16,
            hash_features_per_level: 2,
            log2_hash_table_size: 19,
            hash_base_resolution: 16,
            hash_level_scale: 2.0,
            density_width: 128,
            density_layers: 2,
            geometry_dim: 15,
            color_width: 128,
            color_layers: 2,
            feature_width: 64,
            feature_layers: 2,
            feature_dim: 64,
            semantic_width: 64,
            num_classes: 2,
            feature_supervision: true,
            samples_coarse: 16,
            samples_fine: 48,
            surface_band_fraction: 0.02,
            loss: LossWeights::default(),
            adam: AdamConfig::default(),
            batch_rays: 4096,
            semantic_trunk_gradient: 1.0,
            head_weight_threshold: 1e-4,
            last_sample: LastSample::Auto,
            semantic_input: SemanticInput::Auto,
            scribble_propagation: PropagationOptions::default(),
        }
    }
}

/// A configuration value that cannot work, named by its field.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("field config: `{field}` = {value}: {problem}")]
pub struct ConfigError {
    pub field: &'static str,
    pub value: String,
    pub problem: String,
}

/// Finest hash-grid resolution allowed: cell coordinates must stay exact in f32 positions
/// (p·res keeps ~2^-4 of a cell at 2^20) and in u32 hash arithmetic.
const MAX_HASH_RESOLUTION: f64 = (1u32 << 20) as f64;

/// Size of the output of the first density layer etc. is bounded so a bad config fails here
/// rather than as an allocation failure on the GPU.
const MAX_WIDTH: u32 = 1024;

impl FieldConfig {
    pub fn hash_table_size(&self) -> usize {
        1usize << self.log2_hash_table_size
    }

    pub fn samples_per_ray(&self) -> usize {
        (self.samples_coarse + self.samples_fine) as usize
    }

    /// Values produced by the hash grid (0 without one).
    pub fn hash_encoding_dim(&self) -> usize {
        if self.encoding.uses_hash_grid() {
            (self.hash_levels * self.hash_features_per_level) as usize
        } else {
            0
        }
    }

    /// Values produced by the frequency encoding: sin and cos per octave per axis.
    pub fn frequency_encoding_dim(&self) -> usize {
        6 * self.encoding.frequencies() as usize
    }

    /// Input of the density MLP: [hash grid values, frequency values].
    pub fn encoding_dim(&self) -> usize {
        self.hash_encoding_dim() + self.frequency_encoding_dim()
    }

    /// Layer sizes [in, hidden…, out] of the density MLP; out = [h₀, geometry feature].
    pub fn density_dims(&self) -> Vec<usize> {
        mlp_dims(
            self.encoding_dim(),
            self.density_width,
            self.density_layers,
            1 + self.geometry_dim as usize,
        )
    }

    /// Colour MLP: [SH degree 4 (16), geometry feature] → hidden… → 3.
    pub fn color_dims(&self) -> Vec<usize> {
        mlp_dims(16 + self.geometry_dim as usize, self.color_width, self.color_layers, 3)
    }

    /// Feature MLP: geometry feature → hidden… → f.
    pub fn feature_dims(&self) -> Vec<usize> {
        mlp_dims(
            self.geometry_dim as usize,
            self.feature_width,
            self.feature_layers,
            self.feature_dim as usize,
        )
    }

    /// Whether rays end in an opaque sample; `LastSample::Auto` counts as `Clear` here (the
    /// trainer resolves it first, `for_scene`).
    pub fn opaque_last_sample(&self) -> bool {
        self.last_sample == LastSample::Opaque
    }

    /// This config with what it leaves to the scene decided for `scene`: `LastSample::Auto`.
    pub fn for_scene(&self, scene: &crate::scene::Scene) -> FieldConfig {
        let mut cfg = self.clone();
        if cfg.last_sample == LastSample::Auto {
            cfg.last_sample = if scene.lacks_dense_depth() {
                LastSample::Opaque
            } else {
                LastSample::Clear
            };
        }
        cfg
    }

    /// Columns of the geometry feature in the semantic head's input (0 or `geometry_dim`).
    pub fn semantic_geometry_dim(&self) -> usize {
        let with_geometry = match self.semantic_input {
            SemanticInput::Auto => !self.feature_supervision,
            SemanticInput::FeatureAndGeometry => true,
            SemanticInput::Feature => false,
        };
        if with_geometry { self.geometry_dim as usize } else { 0 }
    }

    /// Semantic head: [relu(f), geometry feature (see `semantic_input`)] → width → classes.
    pub fn semantic_dims(&self) -> Vec<usize> {
        mlp_dims(
            self.feature_dim as usize + self.semantic_geometry_dim(),
            self.semantic_width,
            1,
            self.num_classes as usize,
        )
    }

    /// This config with the fields of the JSON object `changes` replaced: nested objects (`adam`,
    /// `loss`, `scribble_propagation`) field by field, `encoding` (a tagged choice) as a whole.
    /// Unknown fields are an error. Not validated: callers may change more fields first.
    pub fn with_changes(&self, changes: &serde_json::Value) -> Result<FieldConfig, String> {
        use serde_json::Value;
        let Value::Object(changes) = changes else {
            return Err("must be a JSON object of FieldConfig fields".into());
        };
        let mut merged = serde_json::to_value(self).map_err(|e| e.to_string())?;
        let Value::Object(fields) = &mut merged else {
            return Err("a config serializes to an object".into());
        };
        for (key, value) in changes {
            match (fields.get_mut(key), value) {
                (Some(Value::Object(inner)), Value::Object(new)) if key != "encoding" => {
                    for (k, v) in new {
                        inner.insert(k.clone(), v.clone());
                    }
                }
                _ => {
                    fields.insert(key.clone(), value.clone());
                }
            }
        }
        serde_json::from_value(merged).map_err(|e| e.to_string())
    }

    /// Checks every value; the error names the first bad field and its value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let c = self;
        match c.encoding {
            Encoding::HashFreq { frequencies } | Encoding::FreqOnly { frequencies } => {
                in_range("encoding.frequencies", frequencies, 1, 16)?
            }
            Encoding::HashOnly => {}
        }
        // Checked without a hash grid too: the table's size is computed from it either way.
        in_range("log2_hash_table_size", c.log2_hash_table_size, 4, 24)?;
        if c.encoding.uses_hash_grid() {
            in_range("hash_levels", c.hash_levels, 1, 32)?;
            in_range("hash_features_per_level", c.hash_features_per_level, 1, 8)?;
            in_range("hash_base_resolution", c.hash_base_resolution, 1, 1 << 16)?;
            if !(c.hash_level_scale.is_finite() && c.hash_level_scale >= 1.0) {
                return Err(bad(
                    "hash_level_scale",
                    c.hash_level_scale,
                    "must be a finite number >= 1",
                ));
            }
            let finest = c.hash_base_resolution as f64 * (c.hash_level_scale as f64).powi(c.hash_levels as i32 - 1);
            if finest > MAX_HASH_RESOLUTION {
                return Err(bad(
                    "hash_levels",
                    c.hash_levels,
                    &format!(
                        "finest level would have {finest:.0} cells per axis, above the limit {MAX_HASH_RESOLUTION}"
                    ),
                ));
            }
        }
        in_range("density_width", c.density_width, 1, MAX_WIDTH)?;
        in_range("density_layers", c.density_layers, 1, 8)?;
        in_range("geometry_dim", c.geometry_dim, 1, MAX_WIDTH)?;
        in_range("color_width", c.color_width, 1, MAX_WIDTH)?;
        in_range("color_layers", c.color_layers, 1, 8)?;
        in_range("feature_width", c.feature_width, 1, MAX_WIDTH)?;
        in_range("feature_layers", c.feature_layers, 1, 8)?;
        in_range("feature_dim", c.feature_dim, 1, MAX_WIDTH)?;
        in_range("semantic_width", c.semantic_width, 1, MAX_WIDTH)?;
        // Class ids share u8 masks with the void id 255.
        in_range("num_classes", c.num_classes, 1, 255)?;
        in_range("samples_coarse", c.samples_coarse, 1, 1024)?;
        in_range("samples_fine", c.samples_fine, 0, 1024)?;
        if !(c.surface_band_fraction.is_finite() && c.surface_band_fraction > 0.0 && c.surface_band_fraction < 1.0) {
            return Err(bad(
                "surface_band_fraction",
                c.surface_band_fraction,
                "must be in (0, 1)",
            ));
        }
        if !(c.semantic_trunk_gradient.is_finite() && (0.0..=1.0).contains(&c.semantic_trunk_gradient)) {
            return Err(bad(
                "semantic_trunk_gradient",
                c.semantic_trunk_gradient,
                "must be in [0, 1]",
            ));
        }
        if !(c.head_weight_threshold.is_finite() && (0.0..1.0).contains(&c.head_weight_threshold)) {
            return Err(bad(
                "head_weight_threshold",
                c.head_weight_threshold,
                "must be in [0, 1)",
            ));
        }
        let weights = [
            ("loss.rgb", c.loss.rgb),
            ("loss.depth", c.loss.depth),
            ("loss.semantic", c.loss.semantic),
            ("loss.feature", c.loss.feature),
            ("loss.opacity", c.loss.opacity),
        ];
        for (field, w) in weights {
            if !(w.is_finite() && w >= 0.0) {
                return Err(bad(field, w, "must be a finite number >= 0"));
            }
        }
        for (field, beta) in [("adam.beta1", c.adam.beta1), ("adam.beta2", c.adam.beta2)] {
            if !(0.0..1.0).contains(&beta) {
                return Err(bad(field, beta, "must be in [0, 1)"));
            }
        }
        let positive = [
            ("adam.epsilon", c.adam.epsilon),
            ("adam.lr_warmup", c.adam.lr_warmup),
            ("adam.lr_annotating", c.adam.lr_annotating),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(field, v, "must be a finite number > 0"));
            }
        }
        in_range("batch_rays", c.batch_rays, 1, 1 << 22)?;
        c.scribble_propagation.validate().map_err(|problem| ConfigError {
            field: "scribble_propagation",
            value: format!("{:?}", c.scribble_propagation),
            problem,
        })?;
        Ok(())
    }
}

fn mlp_dims(input: usize, width: u32, hidden_layers: u32, output: usize) -> Vec<usize> {
    let mut dims = vec![input];
    dims.extend(std::iter::repeat_n(width as usize, hidden_layers as usize));
    dims.push(output);
    dims
}

fn bad(field: &'static str, value: impl std::fmt::Display, problem: &str) -> ConfigError {
    ConfigError {
        field,
        value: value.to_string(),
        problem: problem.to_string(),
    }
}

fn in_range(field: &'static str, value: u32, min: u32, max: u32) -> Result<(), ConfigError> {
    if value < min || value > max {
        return Err(bad(field, value, &format!("must be between {min} and {max}")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_the_design() {
        let c = FieldConfig::default();
        c.validate().unwrap();
        assert_eq!(c.encoding_dim(), 44);
        assert_eq!(c.density_dims(), vec![44, 128, 128, 16]);
        assert_eq!(c.color_dims(), vec![31, 128, 128, 3]);
        assert_eq!(c.feature_dims(), vec![15, 64, 64, 64]);
        assert_eq!(c.semantic_dims(), vec![64, 64, 2]);
        let papers = FieldConfig {
            semantic_input: SemanticInput::FeatureAndGeometry,
            ..FieldConfig::default()
        };
        assert_eq!(papers.semantic_dims(), vec![79, 64, 2]);
        let unsupervised = FieldConfig {
            feature_supervision: false,
            ..FieldConfig::default()
        };
        assert_eq!(
            unsupervised.semantic_dims(),
            vec![79, 64, 2],
            "Auto keeps g without codes"
        );
        FieldConfig::small().validate().unwrap();
    }

    #[test]
    fn baseline_encodings_change_the_input_width() {
        let freq = FieldConfig {
            encoding: Encoding::freq_only_baseline(),
            ..FieldConfig::default()
        };
        assert_eq!(freq.encoding_dim(), 60);
        let hash = FieldConfig {
            encoding: Encoding::HashOnly,
            ..FieldConfig::default()
        };
        assert_eq!(hash.encoding_dim(), 32);
    }

    #[test]
    fn partial_json_fills_defaults_and_typos_fail() {
        let c: FieldConfig =
            serde_json::from_str(r#"{"log2_hash_table_size": 14, "encoding": {"kind": "hash_only"}}"#).unwrap();
        assert_eq!(c.log2_hash_table_size, 14);
        assert_eq!(c.encoding, Encoding::HashOnly);
        assert_eq!(c.density_width, 128);
        let back: FieldConfig = serde_json::from_str(&serde_json::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
        assert!(serde_json::from_str::<FieldConfig>(r#"{"hash_level": 3}"#).is_err());
    }

    #[test]
    fn errors_name_the_field_and_value() {
        let c = FieldConfig {
            num_classes: 0,
            ..FieldConfig::default()
        };
        let e = c.validate().unwrap_err();
        assert_eq!(e.field, "num_classes");
        assert!(e.to_string().contains("`num_classes` = 0"), "{e}");
        let c = FieldConfig {
            hash_levels: 24,
            ..FieldConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "hash_levels");
        let c = FieldConfig {
            adam: AdamConfig {
                beta2: 1.0,
                ..AdamConfig::default()
            },
            ..FieldConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "adam.beta2");
        let c = FieldConfig {
            encoding: Encoding::FreqOnly { frequencies: 0 },
            ..FieldConfig::default()
        };
        assert_eq!(c.validate().unwrap_err().field, "encoding.frequencies");
    }
}
