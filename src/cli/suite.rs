use std::path::PathBuf;

use clap::Args;
use scribblefield::eval::suite::{self, SuiteOptions, SuiteReport};

use super::CliResult;

#[derive(Args)]
pub struct SuiteArgs {
    /// The shared data folder (captures whose folder is absent are left out, and named).
    #[arg(long, default_value = "../shared/data")]
    data: PathBuf,
    /// Captures to run, by name (default: all; see docs/quality.md).
    #[arg(long, value_delimiter = ',')]
    captures: Vec<String>,
    /// Runs per capture and mode: run i draws scribble set i (`scribble-from-gt --seed i`) and
    /// trains with trainer seed i.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=16))]
    runs: u32,
    /// The short variant CI runs: one run per capture and mode.
    #[arg(long, conflicts_with = "runs")]
    short: bool,
    /// Leave out the runs on the strokes alone (propagation off).
    #[arg(long)]
    no_strokes_only: bool,
    /// Only spread the strokes (no training): per capture and scribble set, the labels written
    /// beyond the strokes and the share of them that is right. Seconds, not minutes.
    #[arg(long, conflicts_with = "ceilings")]
    spread_only: bool,
    /// Also measure each capture's ceiling (trained on the true masks of every frame, seed 0);
    /// give the report to --ceilings-from afterwards.
    #[arg(long)]
    ceilings: bool,
    /// Ceilings measured before (a report written with --ceilings), when this run has none.
    #[arg(long, value_name = "FILE", default_value = "docs/results/suite/full.json")]
    ceilings_from: PathBuf,
    /// Field config changes (JSON, inline or a file) on top of the budget preset with feature
    /// supervision, for every run but the ceilings: a candidate default.
    #[arg(long)]
    config: Option<String>,
    /// Runs at a time, each on its own device.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..=16))]
    jobs: u64,
    /// Keep the loaded captures here as scene archives and reuse them while their recipe holds
    /// (loading bakes feature codes: minutes).
    #[arg(long, value_name = "DIR", default_value = "target/suite-scenes")]
    cache: PathBuf,
    /// Load every capture afresh, without the cache.
    #[arg(long)]
    no_cache: bool,
    /// Write every run's figures here (JSON).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// A report written before: print the change per capture against it.
    #[arg(long, value_name = "FILE")]
    compare: Option<PathBuf>,
}

fn read_report(path: &std::path::Path) -> Result<SuiteReport, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: not a suite report: {e}", path.display()))
}

pub fn run(args: SuiteArgs) -> CliResult {
    let config = match &args.config {
        Some(arg) => {
            let (text, source) = super::field_config::config_text(arg)?;
            let value: serde_json::Value =
                serde_json::from_str(&text).map_err(|e| format!("--config {source}: {e}"))?;
            Some(value)
        }
        None => None,
    };
    let before = args.compare.as_deref().map(read_report).transpose()?;
    let runs_per_capture = if args.short { 1 } else { args.runs };
    let options = SuiteOptions {
        captures: args.captures.clone(),
        runs: runs_per_capture,
        strokes_only: !args.no_strokes_only,
        ceilings: args.ceilings,
        config,
        jobs: args.jobs as usize,
        cache: (!args.no_cache).then(|| args.cache.clone()),
    };
    let runs = suite::plan(&options)?;
    if args.spread_only {
        return spread_only(&runs, &args.data, &options);
    }
    if let Some(first) = runs.first() {
        // Refuse a bad --config before anything slow.
        let probe = scribblefield::scene::demo::demo_scene(&Default::default())?;
        suite::run_config(&probe, first.mode, options.config.as_ref())?;
    }
    if let Some(out) = &args.output
        && let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty())
        && !parent.is_dir()
    {
        return Err(format!("--output {}: folder {} does not exist", out.display(), parent.display()).into());
    }
    eprintln!(
        "suite: {} runs ({} per capture and mode{}), {} at a time; loading the captures",
        runs.len(),
        runs_per_capture,
        if options.strokes_only {
            ", spread and strokes only"
        } else {
            ""
        },
        options.jobs
    );
    let started = std::time::Instant::now();
    let mut finished: Vec<suite::RunResult> = Vec::new();
    let report = suite::run(runs, &args.data, &options, |r, done, total| {
        // Every finished run goes to --output at once, so an interrupted suite keeps its runs.
        finished.push(r.clone());
        if let Some(out) = &args.output {
            let partial = SuiteReport::new(finished.clone(), Vec::new(), &options, r.device.clone());
            if let Ok(json) = serde_json::to_string_pretty(&partial) {
                let _ = std::fs::write(out, json);
            }
        }
        eprintln!(
            "[{done}/{total}] {} {} set {} seed {}: mean IoU {:.3} (boundary {:.3}) in {:.0} s ({:.0} training), {:.0} s so far",
            r.capture,
            r.mode.name(),
            r.set,
            r.seed,
            r.mean_iou,
            r.boundary_iou,
            r.seconds,
            r.train_seconds,
            started.elapsed().as_secs_f64()
        );
    })?;
    for name in &report.skipped {
        eprintln!(
            "!!! {name}: its data is not under {}; left out of the suite",
            args.data.display()
        );
    }
    let ceilings = if args.ceilings {
        None
    } else if args.ceilings_from.is_file() {
        Some(read_report(&args.ceilings_from)?)
    } else {
        eprintln!(
            "no ceilings at {} (`scribblefield suite --ceilings -o FILE` measures them)",
            args.ceilings_from.display()
        );
        None
    };
    println!("on {} ({:.0} s)", report.device, started.elapsed().as_secs_f64());
    print!("{}", report.table(ceilings.as_ref()));
    for loss in report.spread_losses() {
        println!("propagation loses: {loss}");
    }
    if let Some(before) = &before {
        println!();
        print!("{}", report.compare(before));
    }
    if let Some(out) = &args.output {
        let json = serde_json::to_string_pretty(&report)?;
        std::fs::write(out, json).map_err(|e| format!("{}: {e}", out.display()))?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// `--spread-only`: spreads each capture's strokes for every scribble set and prints how far
/// they reached and how many of the labels are right.
fn spread_only(runs: &[suite::RunSpec], data: &std::path::Path, options: &SuiteOptions) -> CliResult {
    let mut captures: Vec<&'static suite::Capture> = Vec::new();
    for r in runs {
        if !captures.iter().any(|c| c.name == r.capture.name) {
            captures.push(r.capture);
        }
    }
    captures.reverse();
    let (scenes, skipped) = suite::load(&captures, data, options)?;
    for name in skipped {
        eprintln!("!!! {name}: its data is not under {}; left out", data.display());
    }
    let jobs: Vec<(usize, u64)> = (0..scenes.len())
        .flat_map(|i| (0..u64::from(options.runs)).map(move |set| (i, set)))
        .collect();
    let results = suite::in_parallel(jobs, options.jobs, |(i, set)| {
        let (capture, scene) = &scenes[i];
        let cfg = suite::run_config(scene, suite::Mode::Spread, options.config.as_ref())?;
        let (figures, check, seconds) = suite::spread_alone(capture, scene, set, &cfg);
        Ok::<_, String>((capture.name, set, figures, check, seconds))
    });
    println!(
        "| capture | set | drawn px | spread px | frames | right | right on drawn frames | least right class | check across views | check within frames | class left out: unclaimed | seconds |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let fold = |f: Option<scribblefield::spread::check::FoldAgreement>| {
        f.map_or("-".to_string(), |f| {
            format!("{:.3} of {}/{}", f.agreement(), f.labelled, f.held)
        })
    };
    for r in results {
        let (name, set, f, check, seconds) = r?;
        println!(
            "| {name} | {set} | {} | {} | {} | {:.3} | {:.3} | {} | {} | {} | {} | {seconds:.1} |",
            f.drawn,
            f.written,
            f.frames,
            f.right,
            f.right_on_drawn_frames,
            f.worst_class
                .map_or("-".to_string(), |c| format!("{c}: {:.3}", f.worst_class_right)),
            fold(check.across_views),
            fold(check.within_frames),
            check
                .class_left_out
                .map_or("-".to_string(), |l| format!("{:.3} of {}", l.unclaimed(), l.held))
        );
    }
    Ok(())
}
