//! The run's folder: saving and loading the resume state, labels, curve and the trainer's
//! checkpoint (`trainer.bin`).
use std::path::Path;

use super::{
    CURVE_FILE, LABELS_FILE, STATE_FILE, STATE_FORMAT, STATE_VERSION, SimulateError, SimulateSettings, SimulateState,
    TRAINER_FILE, TRAINER_MAGIC, io_error,
};
use crate::eval::curves::curve_csv;
use crate::field::gpu::trainer::{Trainer, TrainerState};
use crate::labels::LabelSet;

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
    let trainer_state = pollster::block_on(trainer.read_state())?;
    write_atomic(
        &out.join(TRAINER_FILE),
        &encode_trainer_state(state.rounds, &trainer_state),
    )?;
    write_atomic(&out.join(LABELS_FILE), labels.to_json().as_bytes())?;
    write_atomic(&out.join(CURVE_FILE), curve_csv(&state.curve).as_bytes())?;
    let json = serde_json::to_string_pretty(state).expect("state serializes");
    write_atomic(&out.join(STATE_FILE), json.as_bytes())
}

/// The saved run in `out`, if any, checked against `settings`.
pub(super) fn load_state(
    out: &Path,
    settings: &SimulateSettings,
) -> Result<Option<(SimulateState, LabelSet, TrainerState)>, SimulateError> {
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
    let trainer_path = out.join(TRAINER_FILE);
    let bytes = std::fs::read(&trainer_path).map_err(io_error(&trainer_path))?;
    let (round, trainer_state) = decode_trainer_state(&bytes).map_err(|problem| SimulateError::Output {
        path: trainer_path.clone(),
        problem,
    })?;
    if round != state.rounds || trainer_state.step != state.steps {
        return Err(SimulateError::Output {
            path: trainer_path,
            problem: format!(
                "holds round {round} (step {}) but {STATE_FILE} says round {} (step {}): interrupted while saving; pass --restart",
                trainer_state.step, state.rounds, state.steps
            ),
        });
    }
    Ok(Some((state, labels, trainer_state)))
}

/// `trainer.bin`: magic, round, step, count (u32 LE each), then params, first and second
/// moment (count f32 LE each).
pub fn encode_trainer_state(round: u32, s: &TrainerState) -> Vec<u8> {
    let n = s.params.len();
    let mut out = Vec::with_capacity(20 + 12 * n);
    out.extend_from_slice(TRAINER_MAGIC);
    for v in [round, s.step, n as u32] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for part in [&s.params, &s.first_moment, &s.second_moment] {
        for v in part.iter() {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

pub fn decode_trainer_state(bytes: &[u8]) -> Result<(u32, TrainerState), String> {
    if bytes.len() < 20 || &bytes[..8] != TRAINER_MAGIC {
        return Err("not a trainer checkpoint (bad header)".into());
    }
    let word = |i: usize| u32::from_le_bytes(bytes[8 + 4 * i..12 + 4 * i].try_into().expect("4 bytes"));
    let (round, step, n) = (word(0), word(1), word(2) as usize);
    if bytes.len() != 20 + 12 * n {
        return Err(format!(
            "{} bytes, expected {} for {n} parameters",
            bytes.len(),
            20 + 12 * n
        ));
    }
    let floats = |k: usize| -> Vec<f32> {
        bytes[20 + 4 * n * k..20 + 4 * n * (k + 1)]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect()
    };
    Ok((
        round,
        TrainerState {
            step,
            params: floats(0),
            first_moment: floats(1),
            second_moment: floats(2),
        },
    ))
}
