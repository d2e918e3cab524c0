//! The named field configs, in one table: the CLI's `--preset` and the page's `#model=` choose
//! from it by the same names, and [`Preset::for_adapter`] is the one rule for which an adapter
//! gets when none is named. `num_classes` and `feature_dim` are left at their defaults:
//! `run_config::finish` sets them from the scene.
use super::config::{AdamConfig, FieldConfig};

/// Where a field trains, which decides the preset an adapter gets when none is named: a page
/// gets far fewer steps from the same device than a headless run (it shares it with drawing and
/// repaints), so it starts smaller.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Runner {
    /// The web page.
    Page,
    /// The command line and the evaluation: `segment`, `simulate`, `bench`, `ablate`.
    Headless,
}

impl Runner {
    /// Whether a run of `preset` here trains on the archive's feature codes. The page's `tiny`
    /// model does not: on a CPU rasterizer a page gets a few dozen steps in a minute, and there
    /// the 64-d feature branch and its loss cost more time than they give back in quality
    /// (docs/results/measurements.md).
    pub fn trains_on_codes(self, preset: Preset) -> bool {
        !(self == Runner::Page && preset == Preset::Tiny)
    }
}

/// Smallest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// For software rasterizers (the page on SwiftShader): 128 rays, widths 16, 4 + 8 samples
    /// per ray, and larger learning rates, since few steps happen there.
    Tiny,
    /// Laptops, integrated GPUs, tests: 8 levels, 2^14 table, widths 32, 1024 rays.
    Small,
    /// A CPU device's budget (lavapipe, about 0.2-0.5 s a step on 2 cores), used by the
    /// quality suite: `small` with 256 rays of 4 + 12 samples and annotating learning rate 5e-3;
    /// feature supervision where the archive has codes, as the suite decides its defaults with
    /// (`run_config::finish` turns it off where there are none).
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

    /// The preset to train when none is named, for the adapter the work runs on and where it
    /// runs, and why (for the user: "adapter llvmpipe is a CPU device ..."). A CPU device gets
    /// `budget` headless and `tiny` in a page, which gets far fewer steps from it; a discrete GPU
    /// gets the full model headless; any other GPU (integrated, virtual, unknown), and every GPU
    /// in a page, `small` (the page's `#model=full` asks for more).
    pub fn for_adapter(info: &wgpu::AdapterInfo, runner: Runner) -> (Preset, String) {
        let name = &info.name;
        if crate::gpu::DeviceProfile::of_adapter(info).software {
            return match runner {
                Runner::Headless => (
                    Preset::Budget,
                    format!(
                        "adapter {name} is a CPU device (a software rasterizer): the budget the quality tests train"
                    ),
                ),
                Runner::Page => (
                    Preset::Tiny,
                    format!("adapter {name} is a CPU device (a software rasterizer): the tiny model"),
                ),
            };
        }
        let kind = match info.device_type {
            wgpu::DeviceType::DiscreteGpu if runner == Runner::Headless => {
                return (
                    Preset::Full,
                    format!("adapter {name} is a discrete GPU: the full model"),
                );
            }
            wgpu::DeviceType::DiscreteGpu => "a discrete GPU shared with the page's drawing",
            wgpu::DeviceType::IntegratedGpu => "an integrated GPU",
            wgpu::DeviceType::VirtualGpu => "a virtual GPU",
            _ => "a GPU of unknown type",
        };
        (
            Preset::Small,
            format!("adapter {name} is {kind}; the full model wants a discrete GPU to itself"),
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
                // The page trains `tiny` without the archive's codes (`Runner::trains_on_codes`):
                // the feature branch then only feeds the semantic head, and a narrow one costs
                // less. Where codes are supervised, `run_config::finish` widens it to theirs.
                feature_dim: 8,
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

impl FieldConfig {
    /// A small model for tests and quick browser sessions: 2^14 entries, 8 levels, width 32
    /// (the `small` preset).
    pub fn small() -> FieldConfig {
        Preset::Small.config()
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
        let (p, why) = Preset::for_adapter(
            &info("llvmpipe (LLVM 19.1.7, 256 bits)", wgpu::DeviceType::Cpu),
            Runner::Headless,
        );
        assert_eq!(p, Preset::Budget);
        assert!(
            why.starts_with("adapter llvmpipe") && why.contains("CPU device"),
            "{why}"
        );
        // Browsers often report no device type: the name tells.
        let swiftshader = info("SwiftShader Device", wgpu::DeviceType::Other);
        assert_eq!(Preset::for_adapter(&swiftshader, Runner::Headless).0, Preset::Budget);
        let h200 = info("NVIDIA H200", wgpu::DeviceType::DiscreteGpu);
        let (p, why) = Preset::for_adapter(&h200, Runner::Headless);
        assert_eq!(p, Preset::Full);
        assert!(why.contains("discrete GPU"), "{why}");
        let iris = info("Intel Iris Xe", wgpu::DeviceType::IntegratedGpu);
        let (p, why) = Preset::for_adapter(&iris, Runner::Headless);
        assert_eq!(p, Preset::Small);
        assert!(why.contains("integrated GPU"), "{why}");
        // A page gets fewer steps from the same device: one size smaller.
        assert_eq!(Preset::for_adapter(&swiftshader, Runner::Page).0, Preset::Tiny);
        assert_eq!(Preset::for_adapter(&h200, Runner::Page).0, Preset::Small);
        assert_eq!(Preset::for_adapter(&iris, Runner::Page).0, Preset::Small);
    }
}
