//! Which field the page trains: sized to the device, since the same page runs on a discrete GPU
//! and on a CPU rasterizer (SwiftShader in headless browsers, where one dense layer of width 32
//! over a thousand rays takes tens of milliseconds).
use crate::field::{FieldConfig, Preset};
use crate::scene::Scene;

/// The choices, by name in the page's `#model=` fragment key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModelSize {
    /// The `tiny` preset (`field::Preset`), for software rasterizers.
    Tiny,
    /// The `small` preset: laptops and integrated GPUs.
    Small,
    /// The `full` preset.
    Full,
}

impl ModelSize {
    pub fn parse(name: &str) -> Option<ModelSize> {
        match name {
            "tiny" => Some(ModelSize::Tiny),
            "small" => Some(ModelSize::Small),
            "full" => Some(ModelSize::Full),
            _ => None,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            ModelSize::Tiny => "tiny",
            ModelSize::Small => "small",
            ModelSize::Full => "full",
        }
    }

    /// The default for an adapter: tiny on software rasterizers, small elsewhere (the full
    /// model wants a desktop GPU; the user can ask for it).
    pub fn for_adapter(info: &wgpu::AdapterInfo) -> ModelSize {
        if crate::gpu::context::is_software_adapter(info) {
            ModelSize::Tiny
        } else {
            ModelSize::Small
        }
    }

    /// Whether this model trains on the scene's feature codes. The tiny model does not: on a CPU
    /// rasterizer a page gets a few dozen steps in a minute, and there the 64-d feature branch
    /// and its loss cost more time than they give back in quality (docs/results/measurements.md).
    pub fn trains_on_feature_codes(self) -> bool {
        self != ModelSize::Tiny
    }

    /// The field config for `scene` with `classes` classes (a scene for the tiny model comes
    /// without codes, see [`ModelSize::trains_on_feature_codes`]).
    pub fn config(self, scene: &Scene, classes: usize) -> FieldConfig {
        let mut cfg = match self {
            ModelSize::Tiny => Preset::Tiny,
            ModelSize::Small => Preset::Small,
            ModelSize::Full => Preset::Full,
        }
        .config();
        cfg.num_classes = classes.max(2) as u32;
        match &scene.features {
            Some(f) => cfg.feature_dim = f.dim,
            None => {
                // Without codes to match, the feature branch only feeds the semantic head: a
                // narrow one costs less.
                cfg.feature_supervision = false;
                if self == ModelSize::Tiny {
                    cfg.feature_dim = 8;
                }
            }
        }
        cfg
    }
}
