//! The paper's simulated user (native only): warm up without labels, then rounds of "render a
//! training frame, click a few wrongly predicted pixels with their ground-truth class, train",
//! scoring mean IoU and pixel accuracy on held-out frames every few rounds, until a click budget.
//!
//! Everything is seeded: the trainer by `seed`, the clicks of round r by (`seed`, r), the frame of
//! round r by a seeded permutation of the training frames (cycled; a frame without a wrong pixel
//! left passes its turn to the next). A run lives in one output folder:
//!
//! | file | what |
//! |---|---|
//! | `simulate.json` | settings, rounds and clicks done, the curve (the resume state; written last) |
//! | `curve.csv` | `round,clicks,mean_iou,pixel_acc,steps`, one row per evaluation |
//! | `labels.json` | every click so far, as 1-point strokes (the `labels.json` format) |
//! | `trainer.safetensors` | the trainer's parameters, Adam moments and step count after the last round (`saved_field`) |
//!
//! **Resume**: a folder holding a run with the same settings (scene bytes, field config, seed,
//! schedule, frame split; the click budget may differ) continues after its last completed round:
//! labels, parameters, Adam moments and the step count are restored exactly, and the rounds go on
//! with the same seeds, so a run interrupted and resumed follows the same schedule as one run
//! straight through. It is not bit-identical: the GPU sums hash-grid gradients with atomics in
//! no fixed order. A round cut off mid-way is trained again from its start. A folder with other
//! settings is refused (naming them) unless `restart` is set.
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::field::gpu::trainer::Trainer;
use crate::gpu::{GpuContext, GpuError};
use crate::labels::{LabelSet, Stroke, UNLABELLED, rasterize_frame};
use crate::refine::RefineOptions;
use crate::rng::SplitMix64;
use crate::scene::GT_VOID;
use crate::scene::Scene;

use super::curves::CurvePoint;
use super::headless::render_and_score;

pub const STATE_FILE: &str = "simulate.json";
pub const CURVE_FILE: &str = "curve.csv";
pub const LABELS_FILE: &str = "labels.json";
pub const TRAINER_FILE: &str = "trainer.safetensors";
/// Where runs saved the trainer before its checkpoint was a safetensors file (refused, said so).
pub const OLD_TRAINER_FILE: &str = "trainer.bin";
/// Held while a run writes the folder: two runs in one folder would overwrite each other.
pub const LOCK_FILE: &str = "simulate.lock";
const STATE_FORMAT: &str = "scribblefield-simulate";
const STATE_VERSION: u32 = 1;
/// Steps trained between loss read-backs (and progress reports).
const CHUNK: u32 = 10;

mod files;
mod run_lock;
mod settings;

use files::{load_state, save};
use run_lock::RunLock;
pub use settings::{FrameSplit, SceneId, SimulateSettings};

#[derive(Debug, thiserror::Error)]
pub enum SimulateError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Bad settings or a scene the simulated user cannot work on.
    #[error("{0}")]
    Invalid(String),
    /// The output folder holds something unusable: another run's settings, a damaged file.
    #[error("{path}: {problem}")]
    Output { path: PathBuf, problem: String },
}

fn io_error(path: &Path) -> impl FnOnce(std::io::Error) -> SimulateError + '_ {
    move |source| SimulateError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The resume state (`simulate.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SimulateState {
    pub format: String,
    pub version: u32,
    pub settings: SimulateSettings,
    /// Rounds of clicking completed (and saved).
    pub rounds: u32,
    pub clicks: u32,
    pub steps: u32,
    pub curve: Vec<CurvePoint>,
    /// Why the run stopped before its budget, if it did (no wrong pixel left to click).
    pub stopped: Option<String>,
}

/// One click of the simulated user.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Click {
    pub x: u32,
    pub y: u32,
    /// The ground-truth class it is labelled with.
    pub class: u8,
}

/// What a run reports as it goes.
pub enum SimEvent<'a> {
    /// Continuing a saved run.
    Resumed {
        rounds: u32,
        clicks: u32,
    },
    /// Training steps: `done` of `total` in this phase, with the latest loss when read.
    Training {
        done: u32,
        total: u32,
        loss: Option<f64>,
    },
    /// A round's clicks on `frame`, with the class map they were chosen from.
    Clicked {
        round: u32,
        frame: u32,
        clicks: &'a [Click],
        prediction: &'a [u8],
    },
    Evaluated(&'a CurvePoint),
    /// A line worth printing (why a frame was skipped, why the run stopped).
    Note(&'a str),
}

/// Chooses up to `count` distinct pixels, uniformly among those whose ground truth is a real
/// class (not void, below `num_classes`), whose prediction differs from it and which carry no
/// label yet. Returns their indices (row-major) in the order drawn.
pub fn choose_clicks(
    gt: &[u8],
    prediction: &[u8],
    labelled: &[u16],
    num_classes: u32,
    count: usize,
    rng: &mut SplitMix64,
) -> Vec<usize> {
    let mut wrong: Vec<usize> = (0..gt.len())
        .filter(|&i| {
            let g = gt[i];
            g != GT_VOID && u32::from(g) < num_classes && prediction[i] != g && labelled[i] == UNLABELLED
        })
        .collect();
    let take = count.min(wrong.len());
    // Partial Fisher-Yates: the first `take` entries become a uniform sample.
    for k in 0..take {
        let j = k + rng.below((wrong.len() - k) as u64) as usize;
        wrong.swap(k, j);
    }
    wrong.truncate(take);
    wrong
}

/// The seeded order in which rounds visit the training frames.
pub fn frame_order(train: &[u32], seed: u32) -> Vec<u32> {
    let mut order = train.to_vec();
    let mut rng = SplitMix64::new(u64::from(seed) ^ 0x6672_616d_6573);
    for k in (1..order.len()).rev() {
        let j = rng.below(k as u64 + 1) as usize;
        order.swap(k, j);
    }
    order
}

fn round_rng(seed: u32, round: u32) -> SplitMix64 {
    SplitMix64::new((u64::from(seed) << 32 | u64::from(round)) ^ 0x636c_6963_6b73)
}

/// How far to go this time.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    /// Stop once this many clicks are labelled (a resumed run may raise it).
    pub budget: u32,
    /// Discard a previous run in the output folder instead of resuming it.
    pub restart: bool,
}

/// Runs (or resumes) the simulated user on `scene` (its shipped labels are ignored) into `out`.
pub fn run(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &SimulateSettings,
    options: RunOptions,
    out: &Path,
    events: &mut dyn FnMut(SimEvent<'_>),
) -> Result<SimulateState, SimulateError> {
    settings.check()?;
    check_scene(scene, settings)?;
    std::fs::create_dir_all(out).map_err(io_error(out))?;
    let _lock = RunLock::acquire(out)?;
    let mut scene_only = scene.clone();
    scene_only.labels = None;
    let scene = &scene_only;
    let mut trainer = pollster::block_on(Trainer::new(ctx, scene, &settings.config, settings.seed))?;

    let previous = if options.restart {
        None
    } else {
        load_state(out, settings)?
    };
    let (mut state, mut labels) = match previous {
        Some((state, labels, checkpoint)) => {
            let path = out.join(TRAINER_FILE);
            trainer
                .restore_checkpoint(&path.display().to_string(), &checkpoint)
                .map_err(|e| SimulateError::Output {
                    path,
                    problem: e.problem,
                })?;
            trainer.set_labels(Some(&labels), scene)?;
            events(SimEvent::Resumed {
                rounds: state.rounds,
                clicks: state.clicks,
            });
            (state, labels)
        }
        None => {
            for name in [STATE_FILE, CURVE_FILE, LABELS_FILE, TRAINER_FILE, OLD_TRAINER_FILE] {
                let path = out.join(name);
                if path.exists() {
                    std::fs::remove_file(&path).map_err(io_error(&path))?;
                }
            }
            train(&mut trainer, settings.warmup, events)?;
            let mut state = SimulateState {
                format: STATE_FORMAT.into(),
                version: STATE_VERSION,
                settings: settings.clone(),
                rounds: 0,
                clicks: 0,
                steps: trainer.steps_done(),
                curve: vec![],
                stopped: None,
            };
            let point = evaluate(&mut trainer, scene, &state)?;
            events(SimEvent::Evaluated(&point));
            state.curve.push(point);
            let labels = LabelSet::new(scene.classes.clone());
            save(out, &state, &labels, &trainer)?;
            (state, labels)
        }
    };

    let order = frame_order(&settings.frames.train, settings.seed);
    let num_classes = settings.config.num_classes;
    while state.clicks < options.budget && state.stopped.is_none() {
        let round = state.rounds + 1;
        let mut rng = round_rng(settings.seed, round);
        let want = settings.clicks_per_round.min(options.budget - state.clicks) as usize;
        let mut chosen = None;
        for k in 0..order.len() {
            let frame = order[(round as usize - 1 + k) % order.len()];
            let Some(gt) = scene.frames[frame as usize].gt.as_ref() else {
                continue;
            };
            let rendered = pollster::block_on(trainer.render_frame(frame, scene.width, scene.height))?;
            let labelled = rasterize_frame(labels.frame(frame), scene.width, scene.height);
            let picked = choose_clicks(gt.as_raw(), &rendered.classes, &labelled, num_classes, want, &mut rng);
            if picked.is_empty() {
                events(SimEvent::Note(&format!(
                    "round {round}: frame {frame} has no wrongly predicted unlabelled pixel; trying the next"
                )));
                continue;
            }
            let clicks: Vec<Click> = picked
                .iter()
                .map(|&i| Click {
                    x: i as u32 % scene.width,
                    y: i as u32 / scene.width,
                    class: gt.as_raw()[i],
                })
                .collect();
            events(SimEvent::Clicked {
                round,
                frame,
                clicks: &clicks,
                prediction: &rendered.classes,
            });
            chosen = Some((frame, clicks));
            break;
        }
        let Some((frame, clicks)) = chosen else {
            let why = "no training frame has a wrongly predicted unlabelled pixel left".to_string();
            events(SimEvent::Note(&why));
            state.stopped = Some(why);
            if state.curve.last().map(|p| p.round) != Some(state.rounds) {
                let point = evaluate(&mut trainer, scene, &state)?;
                events(SimEvent::Evaluated(&point));
                state.curve.push(point);
            }
            save(out, &state, &labels, &trainer)?;
            break;
        };
        for c in &clicks {
            labels.push_stroke(
                frame,
                Stroke {
                    class: Some(u16::from(c.class)),
                    radius: settings.click_radius,
                    points: vec![[c.x as f32 + 0.5, c.y as f32 + 0.5]],
                },
            );
        }
        trainer.set_labels(Some(&labels), scene)?;
        train(&mut trainer, settings.steps_per_round, events)?;
        state.rounds = round;
        state.clicks += clicks.len() as u32;
        state.steps = trainer.steps_done();
        if round.is_multiple_of(settings.eval_every) || state.clicks >= options.budget {
            let point = evaluate(&mut trainer, scene, &state)?;
            events(SimEvent::Evaluated(&point));
            state.curve.push(point);
        }
        save(out, &state, &labels, &trainer)?;
    }
    Ok(state)
}

fn check_scene(scene: &Scene, settings: &SimulateSettings) -> Result<(), SimulateError> {
    if !scene.has_gt() || scene.classes.is_empty() {
        return Err(SimulateError::Invalid(
            "the scene has no ground truth: the simulated user labels clicks with it".into(),
        ));
    }
    let frames = scene.frames.len() as u32;
    let split = &settings.frames;
    if let Some(f) = split.train.iter().chain(&split.held_out).find(|&&f| f >= frames) {
        return Err(SimulateError::Invalid(format!(
            "frame {f} does not exist (the scene has {frames} frames)"
        )));
    }
    let has_gt = |f: &u32| scene.frames[*f as usize].gt.is_some();
    if !split.train.iter().any(has_gt) {
        return Err(SimulateError::Invalid(
            "no training frame has ground truth to click from".into(),
        ));
    }
    if !split.held_out.iter().any(has_gt) {
        return Err(SimulateError::Invalid(format!(
            "no held-out frame has ground truth to score (held out: {:?})",
            split.held_out
        )));
    }
    if settings.config.num_classes as usize != scene.classes.len() {
        return Err(SimulateError::Invalid(format!(
            "config num_classes {} but the scene has {} classes",
            settings.config.num_classes,
            scene.classes.len()
        )));
    }
    Ok(())
}

fn train(trainer: &mut Trainer, steps: u32, events: &mut dyn FnMut(SimEvent<'_>)) -> Result<(), GpuError> {
    let mut done = 0;
    while done < steps {
        let n = CHUNK.min(steps - done);
        trainer.train(n);
        done += n;
        let loss = trainer.losses_blocking()?.terms.total();
        events(SimEvent::Training {
            done,
            total: steps,
            loss: Some(loss),
        });
    }
    Ok(())
}

fn evaluate(trainer: &mut Trainer, scene: &Scene, state: &SimulateState) -> Result<CurvePoint, GpuError> {
    let names: Vec<String> = scene.classes.iter().map(|c| c.name.clone()).collect();
    let frames = state.settings.frames.held_out.iter().map(|&f| f as usize);
    // The paper's protocol scores the field's own class map, so the refinement stays off here
    // (and in the clicks above): these curves measure the field and its encodings.
    let report = render_and_score(trainer, scene, &names, frames, &RefineOptions::OFF, |_, _| {})?;
    Ok(CurvePoint {
        round: state.rounds,
        clicks: state.clicks,
        mean_iou: report.mean_iou,
        pixel_acc: report.pixel_accuracy,
        steps: trainer.steps_done(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::FieldConfig;

    #[test]
    fn clicks_are_distinct_wrong_unlabelled_and_never_void() {
        // 0: right, 1: wrong, 2: void, 3: wrong but labelled, 4: wrong, 5: class out of range.
        let gt = [1u8, 2, GT_VOID, 0, 1, 7];
        let pred = [1u8, 0, 0, 1, 0, 0];
        let mut labelled = vec![UNLABELLED; 6];
        labelled[3] = 0;
        let mut rng = SplitMix64::new(3);
        for want in 0..5 {
            let got = choose_clicks(&gt, &pred, &labelled, 3, want, &mut rng);
            assert_eq!(got.len(), want.min(2));
            assert!(got.iter().all(|i| [1, 4].contains(i)), "{got:?}");
            let mut d = got.clone();
            d.dedup();
            assert_eq!(d.len(), got.len());
        }
        // Seeded: the same generator state gives the same draw.
        let many_gt = vec![1u8; 1000];
        let many_pred = vec![0u8; 1000];
        let lab = vec![UNLABELLED; 1000];
        let a = choose_clicks(&many_gt, &many_pred, &lab, 2, 5, &mut SplitMix64::new(9));
        let b = choose_clicks(&many_gt, &many_pred, &lab, 2, 5, &mut SplitMix64::new(9));
        assert_eq!(a, b);
        assert_ne!(
            a,
            choose_clicks(&many_gt, &many_pred, &lab, 2, 5, &mut SplitMix64::new(10))
        );
    }

    #[test]
    fn splits_hold_out_every_nth_frame_and_reject_bad_values() {
        let s = FrameSplit::every(9, 3).unwrap();
        assert_eq!(s.held_out, vec![2, 5, 8]);
        assert_eq!(s.train, vec![0, 1, 3, 4, 6, 7]);
        assert!(
            FrameSplit::every(9, 1)
                .unwrap_err()
                .to_string()
                .contains("--held-out-every 1")
        );
        assert!(
            FrameSplit::every(2, 3)
                .unwrap_err()
                .to_string()
                .contains("no frame is held out")
        );
        let e = FrameSplit::explicit(4, &[1, 9]).unwrap_err().to_string();
        assert!(e.contains("frame 9") && e.contains("4 frames"), "{e}");
        assert!(FrameSplit::explicit(2, &[0, 1]).is_err());
        let order = frame_order(&s.train, 0);
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, s.train);
        assert_eq!(order, frame_order(&s.train, 0));
    }

    #[test]
    fn setting_differences_name_the_fields() {
        let a = SimulateSettings {
            scene: SceneId {
                archive_fnv1a: "0".into(),
                frames: 9,
                width: 8,
                height: 6,
            },
            config: FieldConfig::small(),
            seed: 0,
            warmup: 10,
            steps_per_round: 250,
            clicks_per_round: 5,
            click_radius: 0.5,
            eval_every: 1,
            frames: FrameSplit::every(9, 3).unwrap(),
        };
        assert!(a.differences(&a).is_empty());
        let mut b = a.clone();
        b.steps_per_round = 100;
        b.config.batch_rays = 64;
        let d = b.differences(&a);
        assert_eq!(d.len(), 2, "{d:?}");
        assert!(d.contains(&"config.batch_rays: 64 vs 1024".to_string()), "{d:?}");
        assert!(d.contains(&"steps_per_round: 100 vs 250".to_string()), "{d:?}");
    }
}
