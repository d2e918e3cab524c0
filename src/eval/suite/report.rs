//! The suite's results: every run as JSON, one table per report, and the change per capture
//! against an earlier report with the seeds' spread beside it.
use std::fmt::Write;

use serde::{Deserialize, Serialize};

use super::score::SpreadFigures;
use super::{CAPTURES, Mode, SuiteOptions};

/// One run's figures (refined masks, as `segment` writes them, unless said).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    pub capture: String,
    pub mode: Mode,
    pub set: u64,
    pub seed: u32,
    pub mean_iou: f64,
    /// The field's own class maps, before refinement.
    pub field_mean_iou: f64,
    /// Per class, by id (None: in neither ground truth nor prediction).
    pub class_iou: Vec<Option<f64>>,
    /// Mean IoU over the pixels within `score::BOUNDARY_BAND` of a ground-truth edge.
    pub boundary_iou: f64,
    pub pixel_accuracy: f64,
    /// Where the strokes were spread (`Mode::Spread` only).
    pub spread: Option<SpreadFigures>,
    /// What the spread's self-check found, and whether it withheld spreading.
    #[serde(default)]
    pub check: Option<crate::spread::check::SpreadCheck>,
    #[serde(default)]
    pub withheld: bool,
    /// The class the opacity term pulls through the scene box (`Trainer::opacity_far_class`).
    #[serde(default)]
    pub opacity_far_class: Option<u32>,
    pub seconds: f64,
    /// Of `seconds`, spreading the strokes and training (the rest renders, refines and scores).
    #[serde(default)]
    pub train_seconds: f64,
    /// Refinement rounds of `mean_iou` (`RefineOptions::for_scene`).
    #[serde(default)]
    pub refine_rounds: u32,
    /// Mean IoU of the same renders refined otherwise (`REFINE_VARIANTS`, named "votes 3",
    /// "probabilities 10", ...), on every `VARIANT_EVERY`th scored frame.
    #[serde(default)]
    pub refine_variants: Vec<(String, f64)>,
    pub device: String,
}

/// A whole suite run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SuiteReport {
    pub device: String,
    /// Runs per capture and mode (`SuiteOptions::runs`).
    pub runs_per_capture: u32,
    /// The `--config` the runs trained with on top of the defaults.
    pub config: Option<serde_json::Value>,
    /// Captures whose data was absent.
    pub skipped: Vec<String>,
    pub runs: Vec<RunResult>,
}

/// One capture's figures over its runs of one mode.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    pub runs: usize,
    pub mean: f64,
    pub min: f64,
    pub max: f64,
    pub boundary: f64,
    pub pixel_accuracy: f64,
    /// Mean labels spread beyond the strokes, and the mean share of them that is right.
    pub written: f64,
    pub right: f64,
}

impl Summary {
    /// Half the range of the runs' mean IoU: how far a trainer seed or scribble set moves it.
    pub fn half_range(&self) -> f64 {
        (self.max - self.min) / 2.0
    }
}

impl SuiteReport {
    pub fn new(mut runs: Vec<RunResult>, skipped: Vec<String>, options: &SuiteOptions, device: String) -> SuiteReport {
        runs.sort_by(|a, b| {
            let order = |name: &str| CAPTURES.iter().position(|c| c.name == name).unwrap_or(usize::MAX);
            (order(&a.capture), a.mode as u8, a.set, a.seed).cmp(&(order(&b.capture), b.mode as u8, b.set, b.seed))
        });
        SuiteReport {
            device,
            runs_per_capture: options.runs,
            config: options.config.clone(),
            skipped,
            runs,
        }
    }

    /// Captures with runs, in the suite's order.
    pub fn captures(&self) -> Vec<&str> {
        let mut names: Vec<&str> = Vec::new();
        for r in &self.runs {
            if !names.contains(&r.capture.as_str()) {
                names.push(&r.capture);
            }
        }
        names
    }

    /// `capture`'s figures over its runs of `mode`.
    pub fn summary(&self, capture: &str, mode: Mode) -> Option<Summary> {
        let runs: Vec<&RunResult> = self
            .runs
            .iter()
            .filter(|r| r.capture == capture && r.mode == mode)
            .collect();
        if runs.is_empty() {
            return None;
        }
        let n = runs.len() as f64;
        let mean_of = |f: &dyn Fn(&RunResult) -> f64| runs.iter().map(|r| f(r)).sum::<f64>() / n;
        Some(Summary {
            runs: runs.len(),
            mean: mean_of(&|r| r.mean_iou),
            min: runs.iter().map(|r| r.mean_iou).fold(f64::INFINITY, f64::min),
            max: runs.iter().map(|r| r.mean_iou).fold(f64::NEG_INFINITY, f64::max),
            boundary: mean_of(&|r| r.boundary_iou),
            pixel_accuracy: mean_of(&|r| r.pixel_accuracy),
            written: mean_of(&|r| r.spread.map_or(0.0, |s| s.written as f64)),
            right: mean_of(&|r| r.spread.map_or(0.0, |s| s.right)),
        })
    }

    /// The table the suite prints: per capture, the spread strokes' mean IoU (range over runs),
    /// the strokes alone, the ceiling (from `ceilings` or this report) and the share of it.
    pub fn table(&self, ceilings: Option<&SuiteReport>) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| capture | mean IoU (min-max) | strokes only | ceiling | of ceiling | boundary IoU | pixel acc. | spread px | right |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
        let (mut sum, mut counted) = (0.0, 0);
        for capture in self.captures() {
            let spread = self.summary(capture, Mode::Spread);
            let alone = self.summary(capture, Mode::StrokesOnly);
            let ceiling = self
                .summary(capture, Mode::Ceiling)
                .or_else(|| ceilings.and_then(|c| c.summary(capture, Mode::Ceiling)));
            let main = spread.or(alone).or(ceiling);
            let Some(main) = main else { continue };
            if spread.is_some() {
                sum += main.mean;
                counted += 1;
            }
            let range = if main.runs > 1 {
                format!("{:.3} ({:.3}-{:.3})", main.mean, main.min, main.max)
            } else {
                format!("{:.3}", main.mean)
            };
            let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
            let share = match (spread, ceiling) {
                (Some(s), Some(c)) if c.mean > 0.0 => format!("{:.0} %", 100.0 * s.mean / c.mean),
                _ => "-".into(),
            };
            let _ = writeln!(
                s,
                "| {capture} | {range} | {} | {} | {share} | {:.3} | {:.3} | {} | {} |",
                opt(alone.map(|a| a.mean)),
                opt(ceiling.map(|c| c.mean)),
                main.boundary,
                main.pixel_accuracy,
                spread.map_or("-".into(), |s| format!("{:.0}", s.written)),
                spread.map_or("-".into(), |s| format!("{:.3}", s.right)),
            );
        }
        if counted > 0 {
            let _ = writeln!(s, "| **mean** | **{:.3}** | | | | | | | |", sum / counted as f64);
        }
        s
    }

    /// Per capture, the change of the spread strokes' mean IoU (and of the strokes alone) from
    /// `before`, with the larger of the two reports' half-ranges: a change within it is what a
    /// seed or a scribble set moves.
    pub fn compare(&self, before: &SuiteReport) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "| capture | mode | before | now | change | seeds' spread (±) | verdict |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        let (mut now_sum, mut before_sum, mut n) = (0.0, 0.0, 0);
        for capture in self.captures() {
            for mode in [Mode::Spread, Mode::StrokesOnly, Mode::Ceiling] {
                let (Some(now), Some(old)) = (self.summary(capture, mode), before.summary(capture, mode)) else {
                    continue;
                };
                if mode == Mode::Spread {
                    now_sum += now.mean;
                    before_sum += old.mean;
                    n += 1;
                }
                let change = now.mean - old.mean;
                let spread = now.half_range().max(old.half_range());
                let verdict = if change > spread {
                    "better"
                } else if change < -spread {
                    "WORSE"
                } else {
                    "within spread"
                };
                let _ = writeln!(
                    s,
                    "| {capture} | {} | {:.3} | {:.3} | {change:+.3} | {spread:.3} | {verdict} |",
                    mode.name(),
                    old.mean,
                    now.mean
                );
            }
        }
        if n > 0 {
            let _ = writeln!(
                s,
                "| **mean** | spread | {:.3} | {:.3} | {:+.3} | | |",
                before_sum / n as f64,
                now_sum / n as f64,
                (now_sum - before_sum) / n as f64
            );
        }
        s
    }

    /// Captures where the spread strokes score below the strokes alone by more than the
    /// seeds' spread.
    pub fn spread_losses(&self) -> Vec<String> {
        self.captures()
            .into_iter()
            .filter_map(|c| {
                let spread = self.summary(c, Mode::Spread)?;
                let alone = self.summary(c, Mode::StrokesOnly)?;
                (spread.mean < alone.mean - spread.half_range().max(alone.half_range()))
                    .then(|| format!("{c}: spread {:.3} < strokes only {:.3}", spread.mean, alone.mean))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(capture: &str, mode: Mode, seed: u32, iou: f64) -> RunResult {
        RunResult {
            capture: capture.into(),
            mode,
            set: 0,
            seed,
            mean_iou: iou,
            field_mean_iou: iou,
            class_iou: vec![Some(iou)],
            boundary_iou: iou / 2.0,
            pixel_accuracy: 0.9,
            spread: None,
            check: None,
            withheld: false,
            opacity_far_class: None,
            seconds: 1.0,
            train_seconds: 0.5,
            refine_rounds: 3,
            refine_variants: vec![],
            device: "test".into(),
        }
    }

    fn report(runs: Vec<RunResult>) -> SuiteReport {
        let options = SuiteOptions {
            captures: vec![],
            runs: 2,
            strokes_only: true,
            ceilings: false,
            config: None,
            jobs: 1,
            cache: None,
        };
        SuiteReport::new(runs, vec![], &options, "test".into())
    }

    #[test]
    fn summary_table_and_comparison_use_the_runs_spread() {
        let before = report(vec![
            run("demo", Mode::Spread, 0, 0.90),
            run("demo", Mode::Spread, 1, 0.92),
            run("demo", Mode::StrokesOnly, 0, 0.95),
            run("demo", Mode::StrokesOnly, 1, 0.95),
        ]);
        let s = before.summary("demo", Mode::Spread).unwrap();
        assert!((s.mean - 0.91).abs() < 1e-12 && (s.half_range() - 0.01).abs() < 1e-12);
        assert_eq!(
            before.spread_losses().len(),
            1,
            "0.91 against 0.95 with a spread of 0.01"
        );
        let ceilings = report(vec![run("demo", Mode::Ceiling, 0, 0.98)]);
        let table = before.table(Some(&ceilings));
        assert!(
            table.contains("| demo | 0.910 (0.900-0.920) | 0.950 | 0.980 | 93 % |"),
            "{table}"
        );

        let now = report(vec![
            run("demo", Mode::Spread, 0, 0.96),
            run("demo", Mode::Spread, 1, 0.96),
        ]);
        let change = now.compare(&before);
        assert!(
            change.contains("| demo | spread | 0.910 | 0.960 | +0.050 | 0.010 | better |"),
            "{change}"
        );
        let json = serde_json::to_string(&now).unwrap();
        assert_eq!(serde_json::from_str::<SuiteReport>(&json).unwrap(), now);
    }
}
