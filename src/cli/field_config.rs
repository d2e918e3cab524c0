//! `--preset` and `--config` of `segment`, `bench`, `simulate` and `ablate`: one way to say which
//! field config a command trains.
use std::path::{Path, PathBuf};

use clap::Args;
use scribblefield::bounded_read::read_regular_text;
use scribblefield::field::{FieldConfig, Preset, Runner, finish};
use scribblefield::gpu::GpuContext;
use scribblefield::scene::Scene;

#[derive(Args, Clone, Debug)]
pub struct FieldConfigArgs {
    /// Base field config, from `field::Preset`: tiny, small, budget (a CPU device's budget, as
    /// the quality tests train) or full (the full model, for a real GPU; `default` is its older
    /// name). Default: by adapter (budget on a CPU device, full on a discrete GPU, small on
    /// other GPUs), said at the start. `--config` overrides fields of it.
    #[arg(long, value_parser = parse_preset)]
    pub preset: Option<Preset>,
    /// Field config as JSON, inline (`'{"feature_supervision": true}'`) or a file: fields given
    /// replace the preset's (`adam`, `loss` and `scribble_propagation` field by field, `encoding`
    /// as a whole); see `FieldConfig`. Unknown fields are an error.
    #[arg(long)]
    pub config: Option<String>,
}

impl FieldConfigArgs {
    /// Chooses the preset by `ctx`'s adapter when `--preset` was not given, and says which and
    /// why on stderr (a run of the full model on a CPU device takes hours: the user must see the
    /// choice before it starts).
    pub fn settle(&mut self, ctx: &GpuContext) {
        let (preset, why) = match self.preset {
            Some(p) => (p, "--preset".to_string()),
            None => {
                let (p, why) = Preset::for_adapter(&ctx.adapter_info, Runner::Headless);
                (p, format!("{why} (--preset to choose)"))
            }
        };
        eprintln!("preset {}: {why}", preset.name());
        self.preset = Some(preset);
    }

    /// The preset given or settled; before [`FieldConfigArgs::settle`] without `--preset`, an error.
    fn preset(&self) -> Result<Preset, String> {
        self.preset
            .ok_or_else(|| "no preset chosen yet: the adapter decides it (FieldConfigArgs::settle)".into())
    }

    /// Reads and applies `--config` to the preset given (or `full` when the adapter will choose),
    /// without validating: a typo or a broken file is named before the GPU opens.
    pub fn check(&self) -> Result<(), Box<dyn std::error::Error>> {
        let probe = FieldConfigArgs {
            preset: Some(self.preset.unwrap_or(Preset::Full)),
            config: self.config.clone(),
        };
        probe.resolve().map(|_| ())
    }

    /// The preset with `--config` applied, not yet finished for a scene ([`Self::resolve_for`])
    /// nor validated: callers may change more fields first.
    pub fn resolve(&self) -> Result<FieldConfig, Box<dyn std::error::Error>> {
        let preset = self.preset()?.config();
        let cfg = match &self.config {
            Some(arg) => {
                let (text, source) = config_text(arg)?;
                let changes: serde_json::Value =
                    serde_json::from_str(&text).map_err(|e| format!("--config {source}: {e}"))?;
                apply_config_changes(&preset, &changes).map_err(|e| format!("--config {source}: {e}"))?
            }
            None => preset,
        };
        Ok(cfg)
    }

    /// [`Self::resolve`] finished for `scene` (from `archive`) and `classes` classes
    /// (`field::finish`); what the scene changed is said on stderr. Not validated.
    pub fn resolve_for(
        &self,
        scene: &Scene,
        classes: usize,
        archive: &Path,
    ) -> Result<FieldConfig, Box<dyn std::error::Error>> {
        let finished = finish(self.resolve()?, scene, classes);
        for note in &finished.notes {
            eprintln!("note: {}: {note}", archive.display());
        }
        Ok(finished.config)
    }

    /// How the config was chosen, for reports: `budget` or `budget with cfg.json`.
    pub fn describe(&self) -> String {
        let preset = self.preset.map_or("(by adapter)", Preset::name);
        match &self.config {
            Some(arg) if is_inline(arg) => format!("{preset} with {}", arg.trim()),
            Some(path) => format!("{preset} with {path}"),
            None => preset.to_string(),
        }
    }
}

fn parse_preset(name: &str) -> Result<Preset, String> {
    Preset::parse(name).ok_or_else(|| {
        let names: Vec<&str> = Preset::ALL.iter().map(|p| p.name()).collect();
        format!("unknown preset {name:?}: one of {}", names.join(", "))
    })
}

/// A `--config` argument that is JSON itself rather than a file name.
fn is_inline(arg: &str) -> bool {
    arg.trim_start().starts_with('{')
}

/// Largest `--config` file read: a whole config is about 2 KB; `--config /dev/zero` or a FIFO
/// must end in an error, not fill memory or wait.
const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// The JSON text of a `--config` argument and how to name it in errors: the argument itself when
/// inline, else the file it names.
pub(super) fn config_text(arg: &str) -> Result<(String, String), String> {
    if is_inline(arg) {
        return Ok((arg.to_string(), "(inline JSON)".into()));
    }
    let path = PathBuf::from(arg);
    let text = read_regular_text(&path, MAX_CONFIG_BYTES).map_err(|e| {
        format!(
            "--config {arg}: {e} (give a JSON file, or the JSON itself such as '{{\"feature_supervision\": true}}')"
        )
    })?;
    Ok((text, path.display().to_string()))
}

/// `base` with the fields of the JSON object `changes` replaced (`FieldConfig::with_changes`).
pub fn apply_config_changes(base: &FieldConfig, changes: &serde_json::Value) -> Result<FieldConfig, String> {
    base.with_changes(changes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(unix)]
    #[test]
    fn a_config_that_is_no_regular_file_is_refused_unread() {
        let e = config_text("/dev/zero").unwrap_err();
        assert!(
            e.contains("/dev/zero") && e.contains("a character device, not a regular file"),
            "{e}"
        );
    }

    #[test]
    fn config_changes_replace_fields_of_the_preset() {
        let base = FieldConfig {
            num_classes: 6,
            ..Preset::Budget.config()
        };
        let changes =
            serde_json::json!({"batch_rays": 128, "adam": {"lr_warmup": 1e-2}, "encoding": {"kind": "hash_only"}});
        let c = apply_config_changes(&base, &changes).unwrap();
        assert_eq!(c.batch_rays, 128);
        assert_eq!(c.adam.lr_warmup, 1e-2);
        assert_eq!(c.adam.lr_annotating, base.adam.lr_annotating);
        assert_eq!(c.encoding, scribblefield::field::Encoding::HashOnly);
        assert_eq!(c.samples_fine, base.samples_fine);
        let e = apply_config_changes(&base, &serde_json::json!({"batch_ray": 1})).unwrap_err();
        assert!(e.contains("batch_ray"), "{e}");
        assert!(apply_config_changes(&base, &serde_json::json!([1])).is_err());
    }

    #[test]
    fn config_is_inline_json_or_a_file() {
        let args = |config: &str| FieldConfigArgs {
            preset: Some(Preset::Budget),
            config: Some(config.into()),
        };
        let inline = args(r#" {"feature_supervision": true, "scribble_propagation": {"min_margin": 0.9}}"#);
        let cfg = inline.resolve().unwrap();
        assert!(cfg.feature_supervision);
        assert_eq!(cfg.scribble_propagation.min_margin, 0.9);
        assert_eq!(
            cfg.scribble_propagation.reach,
            FieldConfig::default().scribble_propagation.reach
        );
        assert!(inline.describe().starts_with("budget with {"), "{}", inline.describe());
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("c.json");
        std::fs::write(&file, r#"{"batch_rays": 64}"#).unwrap();
        assert_eq!(args(file.to_str().unwrap()).resolve().unwrap().batch_rays, 64);
        let missing = args("nope.json").resolve().unwrap_err().to_string();
        assert!(
            missing.contains("--config nope.json") && missing.contains("the JSON itself"),
            "{missing}"
        );
        let broken = args(r#"{"batch_rays": }"#).resolve().unwrap_err().to_string();
        assert!(broken.contains("(inline JSON)"), "{broken}");
        // Before the adapter chose a preset, a typo is still found; resolving is refused.
        let unsettled = FieldConfigArgs {
            preset: None,
            config: Some(r#"{"batch_ray": 1}"#.into()),
        };
        assert!(unsettled.check().unwrap_err().to_string().contains("batch_ray"));
        assert!(unsettled.resolve().is_err());
    }
}
