//! What a run is: the settings a folder's run must match to be resumed (scene, field config,
//! seed, schedule, frame split), and the frame split itself.
use serde::{Deserialize, Serialize};

use super::SimulateError;
use crate::field::FieldConfig;
use crate::scene::Scene;

/// Which frames the user clicks on and which are scored.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameSplit {
    pub train: Vec<u32>,
    pub held_out: Vec<u32>,
}

impl FrameSplit {
    /// Every `n`-th frame held out: frames n-1, 2n-1, … (so frame 0 is a training frame).
    pub fn every(frames: u32, n: u32) -> Result<FrameSplit, SimulateError> {
        if n < 2 {
            return Err(SimulateError::Invalid(format!(
                "--held-out-every {n}: must be at least 2 (1 would hold out every frame)"
            )));
        }
        let held_out: Vec<u32> = (0..frames).filter(|i| i % n == n - 1).collect();
        Self::explicit(frames, &held_out).map_err(|e| SimulateError::Invalid(format!("--held-out-every {n}: {e}")))
    }

    /// The given frames held out, the others trained on.
    pub fn explicit(frames: u32, held_out: &[u32]) -> Result<FrameSplit, SimulateError> {
        if let Some(bad) = held_out.iter().find(|&&f| f >= frames) {
            return Err(SimulateError::Invalid(format!(
                "held-out frame {bad} does not exist (the scene has {frames} frames)"
            )));
        }
        let mut held: Vec<u32> = held_out.to_vec();
        held.sort_unstable();
        held.dedup();
        let train: Vec<u32> = (0..frames).filter(|f| !held.contains(f)).collect();
        if held.is_empty() {
            return Err(SimulateError::Invalid(format!(
                "no frame is held out for scoring (the scene has {frames} frames)"
            )));
        }
        if train.is_empty() {
            return Err(SimulateError::Invalid(
                "every frame is held out: none is left to click on".into(),
            ));
        }
        Ok(FrameSplit { train, held_out: held })
    }
}

/// What identifies a scene for resuming: a hash of the archive's bytes and its shape.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneId {
    /// FNV-1a (64 bit) of the archive file, hex.
    pub archive_fnv1a: String,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
}

impl SceneId {
    pub fn new(archive_bytes: &[u8], scene: &Scene) -> SceneId {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        for &b in archive_bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        SceneId {
            archive_fnv1a: format!("{h:016x}"),
            frames: scene.frames.len() as u32,
            width: scene.width,
            height: scene.height,
        }
    }
}

/// Everything that decides a run (a resumed run must have the same).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulateSettings {
    pub scene: SceneId,
    pub config: FieldConfig,
    pub seed: u32,
    pub warmup: u32,
    pub steps_per_round: u32,
    pub clicks_per_round: u32,
    /// Brush radius of a click; 0.5 labels exactly the clicked pixel.
    pub click_radius: f32,
    /// Evaluate every this many rounds (and after the last one).
    pub eval_every: u32,
    pub frames: FrameSplit,
}

impl SimulateSettings {
    pub fn check(&self) -> Result<(), SimulateError> {
        let positive = [
            ("--steps-per-round", self.steps_per_round),
            ("--clicks-per-round", self.clicks_per_round),
            ("--eval-every", self.eval_every),
        ];
        for (flag, v) in positive {
            if v == 0 {
                return Err(SimulateError::Invalid(format!("{flag} 0: must be at least 1")));
            }
        }
        if !(self.click_radius.is_finite() && self.click_radius >= 0.5 && self.click_radius <= 64.0) {
            return Err(SimulateError::Invalid(format!(
                "--click-radius {}: must be between 0.5 (one pixel) and 64",
                self.click_radius
            )));
        }
        self.config
            .validate()
            .map_err(|e| SimulateError::Invalid(e.to_string()))
    }

    /// Names the settings that differ from `other`, as "name: this vs other" (config fields one
    /// level down, e.g. `config.batch_rays`).
    pub fn differences(&self, other: &SimulateSettings) -> Vec<String> {
        let (a, b) = (
            serde_json::to_value(self).expect("settings serialize"),
            serde_json::to_value(other).expect("settings serialize"),
        );
        let mut out = Vec::new();
        diff_values("", &a, &b, 2, &mut out);
        out
    }
}

fn diff_values(prefix: &str, a: &serde_json::Value, b: &serde_json::Value, depth: u32, out: &mut Vec<String>) {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(ma), Value::Object(mb)) if depth > 0 => {
            let mut keys: Vec<&String> = ma.keys().chain(mb.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                let name = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                let null = Value::Null;
                diff_values(
                    &name,
                    ma.get(k).unwrap_or(&null),
                    mb.get(k).unwrap_or(&null),
                    depth - 1,
                    out,
                );
            }
        }
        _ if a != b => out.push(format!("{prefix}: {a} vs {b}")),
        _ => {}
    }
}
