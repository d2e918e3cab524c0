//! The run's folder: saving and loading the resume state, labels, curve and the trainer's
//! checkpoint (`trainer.safetensors`, `saved_field`).
use std::collections::BTreeMap;
use std::path::Path;

use super::{
    CURVE_FILE, LABELS_FILE, OLD_TRAINER_FILE, STATE_FILE, STATE_FORMAT, STATE_VERSION, SimulateError,
    SimulateSettings, SimulateState, TRAINER_FILE, io_error,
};
use crate::eval::curves::curve_csv;
use crate::field::gpu::trainer::Trainer;
use crate::labels::LabelSet;
use crate::saved_field::Checkpoint;

/// The checkpoint's metadata key for the round it was saved after.
const ROUND_KEY: &str = "round";

/// Writes `path` through a temporary file and a rename, so a crash leaves the old or the new.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), SimulateError> {
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, bytes).map_err(io_error(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io_error(path))
}

pub(super) fn save(
    out: &Path,
    state: &SimulateState,
    labels: &LabelSet,
    trainer: &Trainer,
) -> Result<(), SimulateError> {
    let extra = BTreeMap::from([(ROUND_KEY.to_string(), state.rounds.to_string())]);
    let checkpoint = pollster::block_on(trainer.checkpoint(extra))?;
    write_atomic(&out.join(TRAINER_FILE), &checkpoint.to_bytes())?;
    write_atomic(&out.join(LABELS_FILE), labels.to_json().as_bytes())?;
    write_atomic(&out.join(CURVE_FILE), curve_csv(&state.curve).as_bytes())?;
    let json = serde_json::to_string_pretty(state).expect("state serializes");
    write_atomic(&out.join(STATE_FILE), json.as_bytes())
}

/// The saved run in `out`, if any, checked against `settings`.
pub(super) fn load_state(
    out: &Path,
    settings: &SimulateSettings,
) -> Result<Option<(SimulateState, LabelSet, Checkpoint)>, SimulateError> {
    let path = out.join(STATE_FILE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read(&path).map_err(io_error(&path))?;
    let damaged = |problem: String| SimulateError::Output {
        path: path.clone(),
        problem: format!("{problem}; pass --restart to start over"),
    };
    let state: SimulateState =
        serde_json::from_slice(&text).map_err(|e| damaged(format!("not a simulate state: {e}")))?;
    if state.format != STATE_FORMAT || state.version != STATE_VERSION {
        return Err(damaged(format!(
            "format {:?} version {} (expected {STATE_FORMAT:?} version {STATE_VERSION})",
            state.format, state.version
        )));
    }
    let diff = state.settings.differences(settings);
    if !diff.is_empty() {
        return Err(SimulateError::Output {
            path,
            problem: format!(
                "holds a run with other settings (saved vs now: {}); use another output folder or --restart",
                diff.join("; ")
            ),
        });
    }
    let labels_path = out.join(LABELS_FILE);
    let text = std::fs::read(&labels_path).map_err(io_error(&labels_path))?;
    let labels = LabelSet::from_json(&text, &labels_path.display().to_string(), settings.scene.frames)
        .map_err(|e| SimulateError::Invalid(e.to_string()))?;
    let mut trainer_path = out.join(TRAINER_FILE);
    let old_path = out.join(OLD_TRAINER_FILE);
    if !trainer_path.exists() && old_path.exists() {
        // A run saved before checkpoints were safetensors: the reader says so.
        trainer_path = old_path;
    }
    let bytes = std::fs::read(&trainer_path).map_err(io_error(&trainer_path))?;
    let damaged = |problem: String| SimulateError::Output {
        path: trainer_path.clone(),
        problem: format!("{problem}; pass --restart to start over"),
    };
    let checkpoint =
        Checkpoint::from_bytes(&trainer_path.display().to_string(), bytes).map_err(|e| damaged(e.problem))?;
    let round = checkpoint.extra.get(ROUND_KEY);
    let step = checkpoint.state.step;
    if round != Some(&state.rounds.to_string()) || step != state.steps {
        return Err(damaged(format!(
            "holds round {} (step {step}) but {STATE_FILE} says round {} (step {}): interrupted while saving",
            round.map_or("(none)", |r| r.as_str()),
            state.rounds,
            state.steps
        )));
    }
    Ok(Some((state, labels, checkpoint)))
}
