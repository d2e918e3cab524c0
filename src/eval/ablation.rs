//! The configurations `ablate` compares (the paper's baselines, docs/evaluation.md) and the files it writes from
//! their curves: `ablation.csv`, `table.md` and a plot per scene (`plot-<scene>.svg`).
use std::path::{Path, PathBuf};

use crate::field::{Encoding, FieldConfig};

use super::curves::{MethodCurve, ablation_csv, markdown_tables};
use super::plot::{LinePlot, Series};

/// One configuration of the ablation: a name (used for folders, CSV rows and legends) and the
/// field config it trains.
#[derive(Clone, Debug, PartialEq)]
pub struct Method {
    pub name: String,
    pub config: FieldConfig,
}

/// The encodings (frequency only with L = 10, hash grid only, hash grid + frequency with the
/// base config's octaves) each without feature supervision and, when the scene has feature codes,
/// with it (named `+features(<extractor>)`, the extractor by the first word of the archive's
/// description: `baseline`, `efficientnet-lite0`, `imported`). `base` supplies everything else. Returns the methods
/// and, for a scene without codes, a note saying what was skipped.
pub fn methods(base: &FieldConfig, extractor: Option<&str>) -> (Vec<Method>, Option<String>) {
    let hash_freq = match base.encoding {
        Encoding::HashFreq { frequencies } => Encoding::HashFreq { frequencies },
        _ => Encoding::default(),
    };
    let encodings = [
        ("freq-only", Encoding::freq_only_baseline()),
        ("hash-only", Encoding::HashOnly),
        ("hash+freq", hash_freq),
    ];
    let mut out = Vec::new();
    for supervised in [false, true] {
        if supervised && extractor.is_none() {
            continue;
        }
        for (name, encoding) in encodings {
            let name = match (supervised, extractor) {
                (true, Some(e)) => format!("{name}+features({})", extractor_name(e)),
                _ => name.to_string(),
            };
            out.push(Method {
                name,
                config: FieldConfig {
                    encoding,
                    feature_supervision: supervised,
                    ..base.clone()
                },
            });
        }
    }
    let note = extractor.is_none().then(|| {
        "has no feature codes: skipping the feature-supervised configurations (pack it with features to run them)"
            .to_string()
    });
    (out, note)
}

/// The extractor's short name: the first word of its description (which goes on with its
/// settings, e.g. `baseline colour+gradient statistics, windows of ...`).
fn extractor_name(description: &str) -> String {
    let first = description.split_whitespace().next().unwrap_or("");
    let first = first.trim_end_matches([',', ';', ':']);
    if first.is_empty() {
        "features".to_string()
    } else {
        sanitize(first)
    }
}

/// A name safe for a CSV field, a file name and markdown: letters, digits and `+-_.()`, others
/// become `_`.
pub fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "+-_.()".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The scene's name in tables: the archive's file name without `.scene.zip` (or `.zip`).
pub fn scene_name(archive: &Path) -> String {
    let file = archive.file_name().and_then(|n| n.to_str()).unwrap_or("scene");
    let stem = file
        .strip_suffix(".scene.zip")
        .or_else(|| file.strip_suffix(".zip"))
        .unwrap_or(file);
    sanitize(stem)
}

/// The plot of one scene: mean IoU against labelled clicks, a line per method.
pub fn scene_plot(scene: &str, curves: &[MethodCurve]) -> LinePlot {
    LinePlot {
        title: format!("{scene}: simulated user"),
        x_label: "labelled clicks".into(),
        y_label: "mean IoU".into(),
        y_range: (0.0, 1.0),
        series: curves
            .iter()
            .filter(|c| c.scene == scene)
            .map(|c| Series {
                name: c.method.clone(),
                points: c.points.iter().map(|p| (f64::from(p.clicks), p.mean_iou)).collect(),
            })
            .collect(),
    }
}

/// Writes `ablation.csv`, `table.md` and `plot-<scene>.svg` per scene into `dir`;
/// returns the paths written.
pub fn write_outputs(dir: &Path, curves: &[MethodCurve], header: &str) -> std::io::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    let mut write = |name: String, bytes: &[u8]| -> std::io::Result<()> {
        let path = dir.join(name);
        std::fs::write(&path, bytes)?;
        written.push(path);
        Ok(())
    };
    write("ablation.csv".into(), ablation_csv(curves).as_bytes())?;
    write(
        "table.md".into(),
        format!("{header}{}", markdown_tables(curves)).as_bytes(),
    )?;
    let mut scenes: Vec<&str> = curves.iter().map(|c| c.scene.as_str()).collect();
    scenes.dedup();
    for scene in scenes {
        let plot = scene_plot(scene, curves);
        write(format!("plot-{scene}.svg"), plot.to_svg().as_bytes())?;
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn methods_cover_the_encodings_and_skip_features_without_codes() {
        let base = FieldConfig::small();
        let (m, note) = methods(&base, None);
        let names: Vec<&str> = m.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["freq-only", "hash-only", "hash+freq"]);
        assert!(m.iter().all(|m| !m.config.feature_supervision));
        assert_eq!(m[0].config.encoding, Encoding::FreqOnly { frequencies: 10 });
        assert_eq!(m[2].config.batch_rays, base.batch_rays);
        assert!(note.unwrap().contains("no feature codes"));

        let (m, note) = methods(&base, Some("dino/v2, keys of block 12 on frames upscaled x2"));
        assert_eq!(m.len(), 6);
        assert!(note.is_none());
        assert_eq!(m[5].name, "hash+freq+features(dino_v2)");
        let (m, _) = methods(&base, Some("   "));
        assert_eq!(m[3].name, "freq-only+features(features)");
        assert!(m[5].config.feature_supervision);
    }

    #[test]
    fn scene_names_drop_the_archive_extension() {
        assert_eq!(scene_name(Path::new("/tmp/ycb.scene.zip")), "ycb");
        assert_eq!(scene_name(Path::new("a b.zip")), "a_b");
    }
}
