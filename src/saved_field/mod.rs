//! A trained field saved to a file, the trainer's checkpoint: its parameters, both Adam moments and its step count, as a
//! safetensors file (`crate::safetensors`), so any safetensors reader can open it.
//!
//! One F32 tensor per range of the parameter layout, in buffer order: a tensor per hash-grid
//! level, `hash_table.0`, `hash_table.1`, ..., each `[entries, features]` with entries
//! `min((res+1)³, 2^log2_hash_table_size)` (`ParamLayout::hash_levels`; none without a hash
//! grid), then `density.0`, `density.1`, ..., `semantic.1`, each `[out, in]` (row-major, as the
//! layout stores them). The moments follow under the same names prefixed `adam.first_moment.` and
//! `adam.second_moment.`. The header's `__metadata__` says what the file is:
//!
//! | key | value |
//! |---|---|
//! | `format` | `scribblefield-trainer` |
//! | `version` | `2` (version 1 had one `hash_table` tensor `[levels, 2^log2, features]`, every level a full table; it is refused with a message saying so) |
//! | `step` | the trainer's step count (seeds the ray batches, sets Adam's bias corrections) |
//! | `config` | the `FieldConfig` as JSON (the layout follows from it) |
//!
//! and whatever the writer adds (`simulate` adds `round`). The trainer's seed is not in it: it is
//! the trainer's own (it draws the ray batches and jitters the renderer's samples), so a run
//! resumed with the same seed and step draws what it would have drawn. The file before this one
//! (`trainer.bin`, magic `SFTRAIN1`) is recognised and refused with a message saying so.
use std::collections::BTreeMap;
use std::ops::Range;

use crate::field::config::{FieldConfig, LastSample};
use crate::field::gpu::trainer::{Trainer, TrainerState};
use crate::field::params::ParamLayout;
use crate::gpu::GpuError;
use crate::labels::LabelSet;
use crate::safetensors::{SafeTensors, to_bytes_with_metadata};
use crate::scene::Scene;

pub const FORMAT: &str = "scribblefield-trainer";
pub const VERSION: &str = "2";
/// The first bytes of the private format this one replaced.
const OLD_MAGIC: &[u8; 8] = b"SFTRAIN1";
const MOMENTS: [&str; 2] = ["adam.first_moment.", "adam.second_moment."];
/// Metadata keys of the format itself; a writer's own keys must be others.
const RESERVED: [&str; 4] = ["format", "version", "step", "config"];
/// Most parameters a checkpoint's config may ask for. Reading one holds the file and three
/// float copies of the parameters (the parameters and both moments), so 2^25 keeps a hostile
/// file's peak near 800 MB; the default model has 16.7 M at most (16 levels of 2^19 x 2).
pub const MAX_PARAMS: usize = 1 << 25;
/// Largest checkpoint file read: the three copies of [`MAX_PARAMS`] as f32, and room for the
/// header and the metadata (labels among them).
pub const MAX_FILE_BYTES: u64 = 3 * 4 * MAX_PARAMS as u64 + (64 << 20);

/// A checkpoint that cannot be read or does not fit, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct CheckpointError {
    pub file: String,
    pub problem: String,
}

/// A trainer's state with the config it was trained with.
#[derive(Clone, Debug, PartialEq)]
pub struct Checkpoint {
    pub config: FieldConfig,
    pub state: TrainerState,
    /// The writer's own metadata (not the format's keys).
    pub extra: BTreeMap<String, String>,
}

/// Every parameter tensor of `layout`: name, shape, range in the flat buffer.
fn tensors(cfg: &FieldConfig, layout: &ParamLayout) -> Vec<(String, Vec<usize>, Range<usize>)> {
    let mut out = Vec::new();
    let features = cfg.hash_features_per_level as usize;
    for (level, range) in layout.hash_levels.iter().enumerate() {
        out.push((
            format!("hash_table.{level}"),
            vec![range.len() / features, features],
            range.clone(),
        ));
    }
    for (name, range) in layout.named_ranges() {
        if range.is_empty() || name == "hash_table" {
            continue;
        }
        let shape = {
            let (mlp, k) = name.split_once('.').expect("MLP ranges are named mlp.k");
            let k: usize = k.parse().expect("layer index");
            let dims = &layout
                .mlps()
                .into_iter()
                .find(|m| m.0 == mlp)
                .expect("known MLP")
                .1
                .dims;
            vec![dims[k + 1], dims[k]]
        };
        out.push((name, shape, range));
    }
    out
}

impl Checkpoint {
    /// The safetensors file.
    pub fn to_bytes(&self) -> Vec<u8> {
        let layout = ParamLayout::new(&self.config);
        let list = tensors(&self.config, &layout);
        let mut names = Vec::new();
        for prefix in [""].into_iter().chain(MOMENTS) {
            for (name, ..) in &list {
                names.push(format!("{prefix}{name}"));
            }
        }
        let mut entries: Vec<(&str, &[usize], &[f32])> = Vec::new();
        let parts = [&self.state.params, &self.state.first_moment, &self.state.second_moment];
        for (p, part) in parts.into_iter().enumerate() {
            for (i, (_, shape, range)) in list.iter().enumerate() {
                entries.push((&names[p * list.len() + i], shape, &part[range.clone()]));
            }
        }
        let mut metadata = self.extra.clone();
        metadata.insert("format".into(), FORMAT.into());
        metadata.insert("version".into(), VERSION.into());
        metadata.insert("step".into(), self.state.step.to_string());
        metadata.insert(
            "config".into(),
            serde_json::to_string(&self.config).expect("a config serializes"),
        );
        to_bytes_with_metadata(&entries, &metadata)
    }

    /// Reads the checkpoint file at `path`: a regular file (a FIFO or device is refused before it
    /// is opened), through a cap of [`MAX_FILE_BYTES`] whatever its size claims.
    pub fn read_file(path: &std::path::Path) -> Result<Self, CheckpointError> {
        let file = path.display().to_string();
        let bytes = crate::bounded_read::read_regular_file(path, MAX_FILE_BYTES).map_err(|e| CheckpointError {
            file: file.clone(),
            problem: format!("cannot read the checkpoint: {e}"),
        })?;
        Self::from_bytes(&file, bytes)
    }

    /// Reads a checkpoint from `bytes`, the content of the file named `file` in messages.
    pub fn from_bytes(file: &str, bytes: Vec<u8>) -> Result<Self, CheckpointError> {
        let bad = |problem: String| CheckpointError {
            file: file.to_string(),
            problem,
        };
        if bytes.starts_with(OLD_MAGIC) {
            return Err(bad(
                "a trainer checkpoint in the old private format (`SFTRAIN1`, before checkpoints were \
                 safetensors files); this version cannot read it: train again"
                    .into(),
            ));
        }
        let st = SafeTensors::from_bytes(file, bytes).map_err(|e| bad(strip_file(e.to_string(), file)))?;
        let meta = st.metadata();
        let get = |key: &str| {
            meta.get(key).ok_or_else(|| {
                bad(format!(
                    "no `{key}` in the safetensors `__metadata__`: not a {FORMAT} checkpoint"
                ))
            })
        };
        let format = get("format")?;
        if format != FORMAT {
            return Err(bad(format!("`__metadata__` format is {format:?}, expected {FORMAT:?}")));
        }
        let version = get("version")?;
        if version == "1" {
            return Err(bad(format!(
                "{FORMAT} version \"1\": its hash table gives every level a full table, this version \
                 sizes a coarse level to its dense grid (version {VERSION:?}) and cannot read it: train again"
            )));
        }
        if version != VERSION {
            return Err(bad(format!(
                "{FORMAT} version {version:?}; this version reads version {VERSION:?}"
            )));
        }
        let step = get("step")?;
        let step: u32 = step
            .parse()
            .map_err(|_| bad(format!("`__metadata__` step {step:?} is not a whole number")))?;
        let config =
            config_of(get("config")?).map_err(|e| bad(format!("`__metadata__` config is not a field config: {e}")))?;
        config.validate().map_err(|e| bad(format!("`__metadata__` {e}")))?;
        let layout = ParamLayout::new(&config);
        if layout.total > MAX_PARAMS {
            return Err(bad(format!(
                "`__metadata__` config has {} parameters, more than the {MAX_PARAMS} a checkpoint may hold \
                 (its host memory would be {} MiB before any tensor is read)",
                layout.total,
                (layout.total as u64 * 12) >> 20
            )));
        }
        let list = tensors(&config, &layout);
        let expected: std::collections::BTreeSet<String> = [""]
            .into_iter()
            .chain(MOMENTS)
            .flat_map(|p| list.iter().map(move |(name, ..)| format!("{p}{name}")))
            .collect();
        if let Some(extra) = st.names().find(|n| !expected.contains(*n)) {
            return Err(bad(format!(
                "tensor `{extra}` is not part of the model its config describes"
            )));
        }
        let read = |prefix: &str| -> Result<Vec<f32>, CheckpointError> {
            let mut out = Vec::new();
            for (name, shape, _) in &list {
                let full = format!("{prefix}{name}");
                let values = st.f32(&full, shape).map_err(|e| bad(strip_file(e.to_string(), file)))?;
                // A field with NaN or infinite weights renders every pixel as class 0 without a
                // word; refused here, by the tensor that has them.
                if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    let bad_count = values.iter().filter(|v| !v.is_finite()).count();
                    return Err(bad(format!(
                        "tensor `{full}` has {bad_count} values that are not finite (the first: {v} at index {i}); \
                         the field it saved had diverged"
                    )));
                }
                out.extend_from_slice(&values);
            }
            Ok(out)
        };
        let state = TrainerState {
            step,
            params: read("")?,
            first_moment: read(MOMENTS[0])?,
            second_moment: read(MOMENTS[1])?,
        };
        let extra = meta
            .iter()
            .filter(|(k, _)| !RESERVED.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        Ok(Checkpoint { config, state, extra })
    }

    /// How `config` differs from the checkpoint's in what the parameters depend on (the
    /// layout), as `field: here vs file` items; empty when the checkpoint fits.
    pub fn layout_differences(&self, config: &FieldConfig) -> Vec<String> {
        if ParamLayout::new(config) == ParamLayout::new(&self.config) {
            return Vec::new();
        }
        let (here, file) = (
            serde_json::to_value(config).expect("a config serializes"),
            serde_json::to_value(&self.config).expect("a config serializes"),
        );
        let (Some(here), Some(file)) = (here.as_object(), file.as_object()) else {
            return vec!["config".into()];
        };
        here.iter()
            .filter(|(k, v)| file.get(*k) != Some(v))
            .map(|(k, v)| {
                format!(
                    "{k}: {v} here vs {} in the file",
                    file.get(k).unwrap_or(&serde_json::Value::Null)
                )
            })
            .collect()
    }
}

/// Metadata keys `segment --save-checkpoint` adds ([`TrainedOn`]).
pub mod trained_on_keys {
    /// `segment`: which command wrote the file.
    pub const WRITTEN_BY: &str = "written_by";
    /// The archive's file name as it was given (for messages only).
    pub const ARCHIVE: &str = "archive";
    pub const FRAMES: &str = "archive_frames";
    /// `WxH`.
    pub const SIZE: &str = "archive_size";
    /// [`super::scene_fingerprints`]: size, intrinsics, depth scale, bounds and every pose.
    pub const CAMERAS: &str = "archive_cameras";
    /// [`super::scene_fingerprints`]: every frame's colour and depth pixels.
    pub const IMAGES: &str = "archive_images";
    /// The trainer's seed (it jitters the renderer's samples, so the masks depend on it).
    pub const SEED: &str = "seed";
    /// The `labels.json` the field was trained with (its classes name the class ids).
    pub const LABELS: &str = "labels";
    pub const ALL: [&str; 8] = [WRITTEN_BY, ARCHIVE, FRAMES, SIZE, CAMERAS, IMAGES, SEED, LABELS];
}

/// What a field was trained on, kept in its checkpoint's metadata by `segment --save-checkpoint`
/// so that `export` renders the same masks without training: the archive (by name, frame count,
/// size and two fingerprints of its content), the trainer's seed and the labels.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainedOn {
    pub archive: String,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub cameras: String,
    pub images: String,
    pub seed: u32,
    pub labels: LabelSet,
}

/// 64-bit FNV-1a, fed piece by piece.
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    fn f64s(&mut self, values: &[f64]) {
        for v in values {
            self.bytes(&v.to_le_bytes());
        }
    }
    fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

/// Two fingerprints of `scene` (hex): its cameras (size, intrinsics, depth scale, bounds, every
/// frame's pose) and its images (every frame's colour and depth). A field renders what it was
/// trained on only through the same cameras, and is refined with the same images.
pub fn scene_fingerprints(scene: &Scene) -> (String, String) {
    let mut cameras = Fnv::new();
    cameras.bytes(&scene.width.to_le_bytes());
    cameras.bytes(&scene.height.to_le_bytes());
    let k = &scene.intrinsics;
    cameras.f64s(&[k.fx, k.fy, k.cx, k.cy, scene.depth_scale]);
    cameras.f64s(&scene.bounds.min);
    cameras.f64s(&scene.bounds.max);
    let mut images = Fnv::new();
    for f in &scene.frames {
        cameras.f64s(&f.pose.to_row_major());
        images.bytes(f.rgb.as_raw());
        match &f.depth {
            Some(d) => {
                images.bytes(&[1]);
                for v in d.as_raw() {
                    images.bytes(&v.to_le_bytes());
                }
            }
            None => images.bytes(&[0]),
        }
    }
    (cameras.hex(), images.hex())
}

impl TrainedOn {
    /// `scene` (read from `archive`), trained with `seed` on `labels`.
    pub fn of_scene(archive: &str, scene: &Scene, seed: u32, labels: &LabelSet) -> Self {
        let (cameras, images) = scene_fingerprints(scene);
        TrainedOn {
            archive: archive.to_string(),
            frames: scene.frames.len() as u32,
            width: scene.width,
            height: scene.height,
            cameras,
            images,
            seed,
            labels: labels.clone(),
        }
    }

    /// The checkpoint metadata (`Trainer::checkpoint`'s `extra`).
    pub fn to_extra(&self) -> BTreeMap<String, String> {
        use trained_on_keys::*;
        BTreeMap::from(
            [
                (WRITTEN_BY, "segment".to_string()),
                (ARCHIVE, self.archive.clone()),
                (FRAMES, self.frames.to_string()),
                (SIZE, format!("{}x{}", self.width, self.height)),
                (CAMERAS, self.cameras.clone()),
                (IMAGES, self.images.clone()),
                (SEED, self.seed.to_string()),
                (LABELS, self.labels.to_json()),
            ]
            .map(|(k, v)| (k.to_string(), v)),
        )
    }

    /// Reads it back from `checkpoint` (read from `file`); a checkpoint written by something other
    /// than `segment --save-checkpoint` (`simulate`'s) lacks it, and says so.
    pub fn from_checkpoint(file: &str, checkpoint: &Checkpoint) -> Result<Self, CheckpointError> {
        use trained_on_keys::*;
        let bad = |problem: String| CheckpointError {
            file: file.to_string(),
            problem,
        };
        let get = |key: &str| {
            checkpoint.extra.get(key).ok_or_else(|| {
                bad(format!(
                    "no `{key}` in the safetensors `__metadata__`: a {FORMAT} checkpoint, but not one written by \
                     `segment --save-checkpoint`, which records the archive and labels the field was trained on"
                ))
            })
        };
        let number = |key: &str| -> Result<u32, CheckpointError> {
            let text = get(key)?;
            text.parse()
                .map_err(|_| bad(format!("`__metadata__` {key} {text:?} is not a whole number")))
        };
        get(WRITTEN_BY)?;
        let size = get(SIZE)?;
        let (width, height) = size
            .split_once('x')
            .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
            .ok_or_else(|| bad(format!("`__metadata__` {SIZE} {size:?} is not WIDTHxHEIGHT")))?;
        let frames = number(FRAMES)?;
        let labels = LabelSet::from_json(get(LABELS)?.as_bytes(), "`__metadata__` labels", frames)
            .map_err(|e| bad(e.to_string()))?;
        let classes = labels.classes.len();
        if classes != checkpoint.config.num_classes as usize {
            return Err(bad(format!(
                "`__metadata__` labels define {classes} classes, but its field config has num_classes {}",
                checkpoint.config.num_classes
            )));
        }
        Ok(TrainedOn {
            archive: get(ARCHIVE)?.clone(),
            frames,
            width,
            height,
            cameras: get(CAMERAS)?.clone(),
            images: get(IMAGES)?.clone(),
            seed: number(SEED)?,
            labels,
        })
    }

    /// Whether `scene`, read from `archive`, is the archive the field in checkpoint `file` (of
    /// config `config`) was trained on: the same frame count, size, cameras and images, and
    /// feature codes (if any) of the width the field renders. Errors name the checkpoint, the
    /// archive and the two values.
    pub fn check_scene(
        &self,
        file: &str,
        config: &FieldConfig,
        archive: &str,
        scene: &Scene,
    ) -> Result<(), CheckpointError> {
        let trained = format!(
            "{} ({} frames of {} x {})",
            self.archive, self.frames, self.width, self.height
        );
        let bad = |problem: String| CheckpointError {
            file: file.to_string(),
            problem: format!("the field was trained on {trained}, {problem}"),
        };
        if scene.frames.len() != self.frames as usize {
            return Err(bad(format!("but {archive} has {} frames", scene.frames.len())));
        }
        if (scene.width, scene.height) != (self.width, self.height) {
            return Err(bad(format!(
                "but {archive}'s frames are {} x {}",
                scene.width, scene.height
            )));
        }
        if let Some(codes) = &scene.features
            && codes.dim != config.feature_dim
        {
            return Err(bad(format!(
                "its config has feature_dim {}, but {archive}'s feature codes have {} dims",
                config.feature_dim, codes.dim
            )));
        }
        let (cameras, images) = scene_fingerprints(scene);
        if cameras != self.cameras {
            return Err(bad(format!(
                "but {archive} has other cameras (poses, intrinsics or bounds: fingerprint {cameras}, the \
                 checkpoint's {}); was it packed again, or from another capture?",
                self.cameras
            )));
        }
        if images != self.images {
            return Err(bad(format!(
                "but {archive} has other images with the same cameras (fingerprint {images}, the checkpoint's {}); \
                 was it packed again with other settings?",
                self.images
            )));
        }
        Ok(())
    }

    /// Whether `labels` (read from `labels_file`) name the field's classes as the labels it was
    /// trained with do (`file`'s): the same class names in the same order; colours may differ.
    pub fn check_labels(&self, file: &str, labels: &LabelSet, labels_file: &str) -> Result<(), CheckpointError> {
        let names = |l: &LabelSet| l.classes.iter().map(|c| c.name.clone()).collect::<Vec<_>>();
        let (given, trained) = (names(labels), names(&self.labels));
        if given != trained {
            return Err(CheckpointError {
                file: file.to_string(),
                problem: format!(
                    "the field was trained on {} classes {trained:?}, but {labels_file} defines {} classes {given:?}",
                    trained.len(),
                    given.len()
                ),
            });
        }
        Ok(())
    }
}

/// The safetensors reader names the file first; the checkpoint's error does too, once.
fn strip_file(message: String, file: &str) -> String {
    message
        .strip_prefix(&format!("{file}: "))
        .map(String::from)
        .unwrap_or(message)
}

impl Trainer {
    /// The trainer's checkpoint (reads the GPU's buffers back), with the writer's `extra`
    /// metadata; the keys of the format itself are refused.
    pub async fn checkpoint(&self, extra: BTreeMap<String, String>) -> Result<Checkpoint, GpuError> {
        if let Some(key) = extra.keys().find(|k| RESERVED.contains(&k.as_str())) {
            return Err(GpuError::invalid_argument(
                "checkpoint metadata",
                format!("`{key}` is the format's own key"),
            ));
        }
        Ok(Checkpoint {
            config: self.config().clone(),
            state: self.read_state().await?,
            extra,
        })
    }

    /// Continues from `checkpoint` (read from `file`, named in errors): parameters, moments and
    /// step count. Its config must give this trainer's parameter layout; the rest of the config
    /// (loss weights, batch size, ...) is this trainer's own.
    pub fn restore_checkpoint(&mut self, file: &str, checkpoint: &Checkpoint) -> Result<(), CheckpointError> {
        let diff = checkpoint.layout_differences(self.config());
        if !diff.is_empty() {
            return Err(CheckpointError {
                file: file.to_string(),
                problem: format!("written for another model ({})", diff.join("; ")),
            });
        }
        self.restore_state(&checkpoint.state).map_err(|e| CheckpointError {
            file: file.to_string(),
            problem: e.to_string(),
        })
    }
}

/// A checkpoint's config. One written before `last_sample` existed was trained with nothing
/// behind the last sample, so it renders that way too.
fn config_of(json: &str) -> Result<FieldConfig, serde_json::Error> {
    let written_with_it = serde_json::from_str::<serde_json::Value>(json)?
        .get("last_sample")
        .is_some();
    let mut config: FieldConfig = serde_json::from_str(json)?;
    if !written_with_it {
        config.last_sample = LastSample::Clear;
    }
    Ok(config)
}

#[cfg(test)]
mod tests;
