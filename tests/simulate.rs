//! The simulated user and the ablation runner, as a smoke test small enough for CI: a 40 x 30
//! demo scene of 9 frames, a tiny field (128 rays of 4 + 8 samples) and a few short rounds. It
//! checks behaviour, not quality: clicks land on wrongly predicted pixels with their ground-truth
//! class, the curve grows in clicks, a rerun with a larger budget continues the saved run (no
//! second warm-up, same early rows, steps counting on), other settings are refused, and
//! `ablate` writes a CSV, a table and plots that parse, with and without feature codes.
use std::path::Path;
use std::process::{Command, Output};

use half::f16;
use scribblefield::eval::curves::{parse_ablation_csv, parse_curve_csv};
use scribblefield::eval::simulate::{
    self, Click, FrameSplit, RunOptions, SceneId, SimEvent, SimulateError, SimulateSettings,
};
use scribblefield::field::{FieldConfig, Preset};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::labels::LabelSet;
use scribblefield::scene::archive::{write_archive_bytes, write_archive_path};
use scribblefield::scene::demo::{DemoOptions, demo_scene};
use scribblefield::scene::{FeatureCodes, GT_VOID};
use scribblefield::scene::{Pca, Scene};

fn small_demo() -> Scene {
    demo_scene(&DemoOptions {
        width: 40,
        height: 30,
        frames: 9,
        ..Default::default()
    })
    .unwrap()
}

fn tiny_config(classes: usize) -> FieldConfig {
    FieldConfig {
        batch_rays: 128,
        samples_coarse: 4,
        samples_fine: 8,
        num_classes: classes as u32,
        // The demo scenes here have no codes to supervise with.
        feature_supervision: false,
        ..Preset::Budget.config()
    }
}

/// `--config` for the CLI runs: the same tiny field over `--preset budget`.
const TINY_CONFIG_JSON: &str = r#"{"batch_rays": 128, "samples_coarse": 4, "samples_fine": 8}"#;

fn settings(scene: &Scene) -> SimulateSettings {
    SimulateSettings {
        scene: SceneId::new(&write_archive_bytes(scene).unwrap(), scene),
        config: tiny_config(scene.classes.len()),
        seed: 1,
        warmup: 30,
        steps_per_round: 20,
        clicks_per_round: 5,
        click_radius: 0.5,
        eval_every: 1,
        frames: FrameSplit::every(scene.frames.len() as u32, 3).unwrap(),
    }
}

#[derive(Default)]
struct Log {
    resumed: Option<(u32, u32)>,
    /// (round, frame, clicks)
    clicked: Vec<(u32, u32, Vec<Click>)>,
    training_totals: Vec<u32>,
}

/// Records a run's events, checking every click against the class map it was chosen from.
fn recorder<'a>(scene: &'a Scene, log: &'a mut Log) -> impl FnMut(SimEvent<'_>) + 'a {
    move |event| match event {
        SimEvent::Resumed { rounds, clicks } => log.resumed = Some((rounds, clicks)),
        SimEvent::Training { done, total, .. } => {
            if done == total {
                log.training_totals.push(total);
            }
        }
        SimEvent::Clicked {
            round,
            frame,
            clicks,
            prediction,
        } => {
            let gt = scene.frames[frame as usize].gt.as_ref().unwrap();
            for c in clicks {
                let i = (c.y * scene.width + c.x) as usize;
                let truth = gt.as_raw()[i];
                assert_ne!(truth, GT_VOID, "round {round}: a click on a void pixel");
                assert_eq!(c.class, truth, "round {round}: a click labelled with another class");
                assert_ne!(
                    prediction[i], truth,
                    "round {round}: a click on a rightly predicted pixel"
                );
            }
            log.clicked.push((round, frame, clicks.to_vec()));
        }
        SimEvent::Evaluated(_) | SimEvent::Note(_) => {}
    }
}

fn read_curve(dir: &Path) -> Vec<scribblefield::eval::curves::CurvePoint> {
    parse_curve_csv(&std::fs::read_to_string(dir.join(simulate::CURVE_FILE)).unwrap()).unwrap()
}

#[test]
fn simulated_user_clicks_wrong_pixels_and_resumes_where_it_stopped() {
    let Some(ctx) = gpu_for_tests("simulated_user_clicks_wrong_pixels_and_resumes_where_it_stopped") else {
        return;
    };
    let scene = small_demo();
    let s = settings(&scene);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let options = RunOptions {
        budget: 10,
        restart: false,
    };

    let mut log = Log::default();
    let state = simulate::run(&ctx, &scene, &s, options, &out, &mut recorder(&scene, &mut log)).unwrap();
    assert_eq!(log.resumed, None);
    assert_eq!((state.rounds, state.clicks), (2, 10));
    assert_eq!(
        log.training_totals,
        vec![30, 20, 20],
        "warm-up, then a round of 20 steps each"
    );
    // Clicks only on training frames, and the labels file holds exactly them as 1-pixel strokes.
    assert!(log.clicked.iter().all(|(_, f, _)| s.frames.train.contains(f)));
    let labels_path = out.join(simulate::LABELS_FILE);
    let labels = LabelSet::from_json(&std::fs::read(&labels_path).unwrap(), "labels", 9).unwrap();
    let strokes: Vec<(u32, [f32; 2], u16)> = labels
        .frames
        .iter()
        .flat_map(|f| f.strokes.iter().map(move |s| (f.frame, s.points[0], s.class.unwrap())))
        .collect();
    assert_eq!(strokes.len(), 10);
    for (_, frame, clicks) in &log.clicked {
        for c in clicks {
            let at = [c.x as f32 + 0.5, c.y as f32 + 0.5];
            assert!(
                strokes.contains(&(*frame, at, u16::from(c.class))),
                "{c:?} missing from labels"
            );
        }
    }
    let first = read_curve(&out);
    assert_eq!(first, state.curve);
    assert_eq!(first.iter().map(|p| p.clicks).collect::<Vec<_>>(), vec![0, 5, 10]);
    assert_eq!(first.iter().map(|p| p.steps).collect::<Vec<_>>(), vec![30, 50, 70]);
    assert!(
        first
            .iter()
            .all(|p| (0.0..=1.0).contains(&p.mean_iou) && (0.0..=1.0).contains(&p.pixel_acc))
    );

    // A larger budget continues: no warm-up, the saved rows kept, rounds and steps counting on.
    let mut log2 = Log::default();
    let options = RunOptions {
        budget: 20,
        restart: false,
    };
    let state = simulate::run(&ctx, &scene, &s, options, &out, &mut recorder(&scene, &mut log2)).unwrap();
    assert_eq!(log2.resumed, Some((2, 10)));
    assert_eq!(log2.training_totals, vec![20, 20], "resuming must not warm up again");
    assert_eq!((state.rounds, state.clicks, state.steps), (4, 20, 110));
    let second = read_curve(&out);
    assert_eq!(second[..3], first[..]);
    assert_eq!(
        second.iter().map(|p| p.clicks).collect::<Vec<_>>(),
        vec![0, 5, 10, 15, 20]
    );
    assert!(
        second
            .windows(2)
            .all(|w| w[0].clicks < w[1].clicks && w[0].steps < w[1].steps)
    );
    assert_eq!(log2.clicked.iter().map(|c| c.0).collect::<Vec<_>>(), vec![3, 4]);
    // Earlier clicks are kept and new ones never repeat a labelled pixel.
    let labels = LabelSet::from_json(&std::fs::read(&labels_path).unwrap(), "labels", 9).unwrap();
    let mut all: Vec<(u32, [u32; 2])> = labels
        .frames
        .iter()
        .flat_map(|f| f.strokes.iter().map(move |s| (f.frame, s.points[0].map(|v| v as u32))))
        .collect();
    assert_eq!(all.len(), 20);
    all.sort_unstable();
    all.dedup();
    assert_eq!(all.len(), 20, "a pixel was clicked twice");

    // The budget already reached: nothing to do, nothing changes.
    let state = simulate::run(&ctx, &scene, &s, options, &out, &mut |_| {}).unwrap();
    assert_eq!(state.curve, second);

    // A second run while one writes the folder is refused; a lock left by a dead process is not.
    assert!(!out.join(simulate::LOCK_FILE).exists(), "the lock outlived its run");
    // Another run: the lock file locked by a live holder (this test, in the name of pid 1).
    std::fs::write(out.join(simulate::LOCK_FILE), "1").unwrap();
    let holder = std::fs::File::open(out.join(simulate::LOCK_FILE)).unwrap();
    holder.try_lock().unwrap();
    let err = simulate::run(&ctx, &scene, &s, options, &out, &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("another run (process 1)"), "{err}");
    drop(holder);
    // A dead run's lock: the file is there, nobody holds it.
    std::fs::write(out.join(simulate::LOCK_FILE), "4000000000").unwrap(); // no such process
    simulate::run(&ctx, &scene, &s, options, &out, &mut |_| {}).unwrap();

    // A folder saved before checkpoints were safetensors files: refused, saying so.
    let checkpoint = out.join(simulate::TRAINER_FILE);
    let saved = std::fs::read(&checkpoint).unwrap();
    std::fs::remove_file(&checkpoint).unwrap();
    let mut old = b"SFTRAIN1".to_vec();
    old.extend_from_slice(&[0; 12]);
    std::fs::write(out.join(simulate::OLD_TRAINER_FILE), &old).unwrap();
    let err = simulate::run(&ctx, &scene, &s, options, &out, &mut |_| {}).unwrap_err();
    let m = err.to_string();
    assert!(
        m.contains("trainer.bin") && m.contains("old private format") && m.contains("--restart"),
        "{m}"
    );
    std::fs::write(&checkpoint, saved).unwrap();

    // Other settings are refused, naming the field; --restart starts over (and removes the old
    // checkpoint too).
    let other = SimulateSettings {
        steps_per_round: 30,
        ..s.clone()
    };
    let err = simulate::run(&ctx, &scene, &other, options, &out, &mut |_| {}).unwrap_err();
    assert!(matches!(err, SimulateError::Output { .. }), "{err}");
    assert!(err.to_string().contains("steps_per_round: 20 vs 30"), "{err}");
    let restart = RunOptions {
        budget: 5,
        restart: true,
    };
    let state = simulate::run(&ctx, &scene, &other, restart, &out, &mut |_| {}).unwrap();
    assert_eq!((state.rounds, state.clicks, state.steps), (1, 5, 60));
    assert_eq!(read_curve(&out).len(), 2);
    assert!(!out.join(simulate::OLD_TRAINER_FILE).exists());
    assert!(out.join(simulate::TRAINER_FILE).is_file());
}

#[test]
fn scenes_the_simulated_user_cannot_use_are_refused() {
    let Some(ctx) = gpu_for_tests("scenes_the_simulated_user_cannot_use_are_refused") else {
        return;
    };
    let mut scene = small_demo();
    let s = settings(&scene);
    let dir = tempfile::tempdir().unwrap();
    for f in &mut scene.frames {
        f.gt = None;
    }
    let options = RunOptions {
        budget: 5,
        restart: false,
    };
    let err = simulate::run(&ctx, &scene, &s, options, dir.path(), &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("no ground truth"), "{err}");
    let bad = SimulateSettings {
        clicks_per_round: 0,
        ..settings(&small_demo())
    };
    let err = simulate::run(&ctx, &small_demo(), &bad, options, dir.path(), &mut |_| {}).unwrap_err();
    assert!(err.to_string().contains("--clicks-per-round 0"), "{err}");
}

fn run_cli(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_scribblefield"))
        .args(args)
        .env(
            "XDG_RUNTIME_DIR",
            std::env::var("XDG_RUNTIME_DIR").unwrap_or("/tmp".into()),
        )
        .output()
        .expect("binary runs")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// The demo scene with feature codes that follow the ground truth (a one-hot of the class at
/// the cell's centre, at a coarser resolution), as an extractor would give.
fn with_features(mut scene: Scene) -> Scene {
    let (fw, fh, dim) = (10u32, 8u32, 8u32);
    let mut data = Vec::new();
    for frame in &scene.frames {
        let gt = frame.gt.as_ref().unwrap();
        for y in 0..fh {
            for x in 0..fw {
                let (px, py) = (
                    (x * 2 + 1) * scene.width / (2 * fw),
                    (y * 2 + 1) * scene.height / (2 * fh),
                );
                let class = gt.get_pixel(px, py).0[0] as u32;
                data.extend((0..dim).map(|d| f16::from_f32(if d == class % dim { 1.0 } else { 0.0 })));
            }
        }
    }
    let values: Vec<f32> = data.iter().map(|v| v.to_f32()).collect();
    scene.features = Some(FeatureCodes {
        height: fh,
        width: fw,
        dim,
        extractor: "gt-one-hot codes of the class at the cell centre".into(),
        pca: Pca::fit(&values, dim as usize).unwrap(),
        data,
    });
    scene
}

#[test]
fn ablate_writes_a_csv_a_table_and_plots_with_and_without_features() {
    if gpu_for_tests("ablate_writes_a_csv_a_table_and_plots_with_and_without_features").is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("demo.scene.zip");
    write_archive_path(&small_demo(), &plain).unwrap();
    let featured = dir.path().join("feat.scene.zip");
    write_archive_path(&with_features(small_demo()), &featured).unwrap();
    let config = dir.path().join("tiny.json");
    std::fs::write(&config, TINY_CONFIG_JSON).unwrap();
    let out = dir.path().join("ablation");
    let schedule = [
        "--preset",
        "budget",
        "--config",
        config.to_str().unwrap(),
        "--budget",
        "5",
        "--warmup",
        "20",
        "--steps-per-round",
        "10",
    ];
    let mut args = vec!["ablate", plain.to_str().unwrap(), "-o", out.to_str().unwrap()];
    args.extend(schedule);
    let o = run_cli(&args);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("has no feature codes: skipping"), "{}", text(&o));
    // A scene with codes: the feature-supervised variants run too (only hash+freq, to save time).
    let mut args = vec!["ablate", featured.to_str().unwrap(), "-o"];
    let out_feat = dir.path().join("ablation-feat");
    args.push(out_feat.to_str().unwrap());
    args.extend(schedule);
    args.extend(["--only", "hash+freq"]);
    let o = run_cli(&args);
    assert!(o.status.success(), "{}", text(&o));

    let curves = parse_ablation_csv(&std::fs::read_to_string(out.join("ablation.csv")).unwrap()).unwrap();
    let methods: Vec<&str> = curves.iter().map(|c| c.method.as_str()).collect();
    assert_eq!(methods, ["freq-only", "hash-only", "hash+freq"]);
    for c in &curves {
        assert_eq!(c.scene, "demo");
        assert_eq!(c.points.iter().map(|p| p.clicks).collect::<Vec<_>>(), vec![0, 5]);
        // Each method's own run folder holds the same curve.
        assert_eq!(read_curve(&out.join("demo").join(&c.method)), c.points);
    }
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("| scene | freq-only | hash-only | hash+freq |"),
        "{table}"
    );
    assert!(
        table.contains("| scene | method | clicks to 80 % | clicks to 90 % | IoU @ 50 |"),
        "{table}"
    );
    assert!(table.contains("| demo | hash+freq |"), "{table}");
    let svg = std::fs::read_to_string(out.join("plot-demo.svg")).unwrap();
    assert_eq!(svg.matches("<polyline").count(), 3);
    assert!(svg.starts_with(r#"<svg xmlns="http://www.w3.org/2000/svg" width="800" height="480""#));

    let curves = parse_ablation_csv(&std::fs::read_to_string(out_feat.join("ablation.csv")).unwrap()).unwrap();
    let methods: Vec<&str> = curves.iter().map(|c| c.method.as_str()).collect();
    assert_eq!(methods, ["hash+freq", "hash+freq+features(gt-one-hot)"]);
    assert!(out_feat.join("plot-feat.svg").is_file());
}

#[test]
fn bad_simulate_input_fails_cleanly_naming_the_file_or_flag() {
    let dir = tempfile::tempdir().unwrap();
    let mut no_gt = small_demo();
    for f in &mut no_gt.frames {
        f.gt = None;
    }
    let no_gt_path = dir.path().join("nogt.scene.zip");
    write_archive_path(&no_gt, &no_gt_path).unwrap();
    let demo = dir.path().join("demo.scene.zip");
    write_archive_path(&small_demo(), &demo).unwrap();
    let bad_config = dir.path().join("bad.json");
    std::fs::write(&bad_config, r#"{"batch_ray": 3}"#).unwrap();
    let out = dir.path().join("out");
    let (o_s, d_s, c_s) = (
        out.to_str().unwrap(),
        demo.to_str().unwrap(),
        bad_config.to_str().unwrap(),
    );
    let cases: Vec<(Vec<&str>, Vec<&str>)> = vec![
        (
            vec!["simulate", no_gt_path.to_str().unwrap(), "-o", o_s],
            vec!["nogt.scene.zip", "no ground truth"],
        ),
        (
            vec!["simulate", "missing.scene.zip", "-o", o_s],
            vec!["missing.scene.zip"],
        ),
        (
            vec!["simulate", d_s, "-o", o_s, "--held-out-every", "1"],
            vec!["--held-out-every 1"],
        ),
        (
            vec!["simulate", d_s, "-o", o_s, "--held-out", "2,40"],
            vec!["--held-out", "frame 40"],
        ),
        (
            vec!["simulate", d_s, "-o", o_s, "--clicks-per-round", "0"],
            vec!["--clicks-per-round 0"],
        ),
        (
            vec!["simulate", d_s, "-o", o_s, "--click-radius", "0.1"],
            vec!["--click-radius 0.1"],
        ),
        (
            vec!["simulate", d_s, "-o", o_s, "--config", c_s],
            vec!["bad.json", "batch_ray"],
        ),
        (
            vec!["ablate", d_s, no_gt_path.to_str().unwrap(), "-o", o_s],
            vec!["nogt.scene.zip", "no ground truth"],
        ),
        (
            vec!["ablate", d_s, "-o", o_s, "--only", "nothing"],
            vec!["--only nothing", "matches no method"],
        ),
    ];
    for (args, mentions) in cases {
        let o = run_cli(&args);
        let t = text(&o);
        assert!(!o.status.success(), "{args:?} should fail:\n{t}");
        assert!(!t.contains("panicked"), "{args:?} panicked:\n{t}");
        for m in mentions {
            assert!(t.contains(m), "{args:?}: output should mention {m:?}:\n{t}");
        }
    }
    assert!(!out.exists(), "a failed check must not leave an output folder");
}
