//! The named field configs, in one table: the CLI's `--preset` and the page's `#model=` choose
//! from it by the same names. `num_classes` and `feature_dim` are left at their defaults; the
//! caller sets them from the scene.
use super::config::{AdamConfig, FieldConfig};

/// Smallest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// For software rasterizers (the page on SwiftShader): 128 rays, widths 16, 4 + 8 samples
    /// per ray, and larger learning rates, since few steps happen there.
    Tiny,
    /// Laptops, integrated GPUs, tests: 8 levels, 2^14 table, widths 32, 1024 rays.
    Small,
    /// A CPU device's budget (lavapipe, about 0.2-0.5 s a step on 2 cores), used by the
    /// quality tests: `small` with 256 rays of 4 + 12 samples, no feature supervision,
    /// annotating learning rate 5e-3.
    Budget,
    /// The full model (`FieldConfig::default()`, hash table 2^19, widths 128, 4096 rays): for a
    /// real GPU.
    Full,
}

impl Preset {
    pub const ALL: [Preset; 4] = [Preset::Tiny, Preset::Small, Preset::Budget, Preset::Full];

    pub fn name(self) -> &'static str {
        match self {
            Preset::Tiny => "tiny",
            Preset::Small => "small",
            Preset::Budget => "budget",
            Preset::Full => "full",
        }
    }

    /// By name; `default` is an older name of `full` (the CLI's `--preset default`).
    pub fn parse(name: &str) -> Option<Preset> {
        match name {
            "default" => Some(Preset::Full),
            _ => Preset::ALL.into_iter().find(|p| p.name() == name),
        }
    }

    /// The preset to train when none is named, for the adapter the work runs on, and why (for
    /// the user: "adapter llvmpipe is a CPU device ..."). The page makes the same split by
    /// `gpu::context::is_software_adapter` (`app::model_size`), with `tiny` there since a
    /// browser gets far fewer steps than a headless run: a CPU device gets `budget`, a discrete
    /// GPU the full model, any other GPU (integrated, virtual, unknown) `small`.
    pub fn for_adapter(info: &wgpu::AdapterInfo) -> (Preset, String) {
        let name = &info.name;
        if crate::gpu::context::is_software_adapter(info) {
            return (
                Preset::Budget,
                format!("adapter {name} is a CPU device (a software rasterizer): the budget the quality tests train"),
            );
        }
        let kind = match info.device_type {
            wgpu::DeviceType::DiscreteGpu => {
                return (
                    Preset::Full,
                    format!("adapter {name} is a discrete GPU: the full model"),
                );
            }
            wgpu::DeviceType::IntegratedGpu => "an integrated GPU",
            wgpu::DeviceType::VirtualGpu => "a virtual GPU",
            _ => "a GPU of unknown type",
        };
        (
            Preset::Small,
            format!("adapter {name} is {kind}; the full model wants a discrete GPU"),
        )
    }

    pub fn config(self) -> FieldConfig {
        match self {
            Preset::Tiny => FieldConfig {
                hash_levels: 6,
                log2_hash_table_size: 12,
                density_width: 16,
                color_width: 16,
                feature_width: 16,
                semantic_width: 16,
                samples_coarse: 4,
                samples_fine: 8,
                batch_rays: 128,
                // Few steps happen on a CPU rasterizer: larger steps than the interactive
                // default so scribbles show in the masks within a minute.
                adam: AdamConfig {
                    lr_warmup: 1e-2,
                    lr_annotating: 1e-2,
                    ..AdamConfig::default()
                },
                ..Preset::Small.config()
            },
            Preset::Small => FieldConfig {
                hash_levels: 8,
                log2_hash_table_size: 14,
                density_width: 32,
                color_width: 32,
                feature_width: 32,
                semantic_width: 32,
                samples_coarse: 8,
                samples_fine: 24,
                batch_rays: 1024,
                ..FieldConfig::default()
            },
            // At short budgets the interactive default learning rate learns labels too slowly,
            // and a larger one than this overshoots (docs/results/measurements.md).
            Preset::Budget => FieldConfig {
                batch_rays: 256,
                samples_coarse: 4,
                samples_fine: 12,
                feature_supervision: false,
                adam: AdamConfig {
                    lr_annotating: 5e-3,
                    ..AdamConfig::default()
                },
                ..Preset::Small.config()
            },
            Preset::Full => FieldConfig::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_is_valid_and_found_by_its_name() {
        for p in Preset::ALL {
            let mut cfg = p.config();
            cfg.num_classes = 3;
            cfg.validate().unwrap_or_else(|e| panic!("{}: {e}", p.name()));
            assert_eq!(Preset::parse(p.name()), Some(p));
        }
        assert_eq!(Preset::parse("default"), Some(Preset::Full));
        assert_eq!(Preset::parse("huge"), None);
    }

    #[test]
    fn adapters_pick_presets_and_say_why() {
        let info = |name: &str, device_type| wgpu::AdapterInfo {
            name: name.into(),
            device_type,
            ..wgpu::AdapterInfo::new(wgpu::DeviceType::Other, wgpu::Backend::Noop)
        };
        let (p, why) = Preset::for_adapter(&info("llvmpipe (LLVM 19.1.7, 256 bits)", wgpu::DeviceType::Cpu));
        assert_eq!(p, Preset::Budget);
        assert!(
            why.starts_with("adapter llvmpipe") && why.contains("CPU device"),
            "{why}"
        );
        // Browsers often report no device type: the name tells.
        let (p, _) = Preset::for_adapter(&info("SwiftShader Device", wgpu::DeviceType::Other));
        assert_eq!(p, Preset::Budget);
        let (p, why) = Preset::for_adapter(&info("NVIDIA H200", wgpu::DeviceType::DiscreteGpu));
        assert_eq!(p, Preset::Full);
        assert!(why.contains("discrete GPU"), "{why}");
        let (p, why) = Preset::for_adapter(&info("Intel Iris Xe", wgpu::DeviceType::IntegratedGpu));
        assert_eq!(p, Preset::Small);
        assert!(why.contains("integrated GPU"), "{why}");
    }
}
