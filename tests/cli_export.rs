//! `segment --save-checkpoint` and `export`: the masks again from a saved field, without
//! training. The demo scene, written out as an autolabel capture at 64 x 48, is packed at
//! `--max-size 32` (32 x 24); `segment` trains briefly on the GPU (lavapipe in CI) and saves its
//! field, and `export` from that file must write the very files `segment` wrote, at the archive's
//! resolution and with `--source` at the capture's. The bad inputs (a checkpoint missing,
//! truncated, foreign or from `simulate`; another archive; other labels; another capture) are
//! refused before any GPU work, with checkpoints built here, so they are checked on any machine.
mod cli_support;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use cli_support::{fails, ok, run, write_autolabel};
use scribblefield::field::gpu::trainer::TrainerState;
use scribblefield::field::params::ParamLayout;
use scribblefield::field::{FieldConfig, Preset};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::labels::LabelSet;
use scribblefield::saved_field::{Checkpoint, TrainedOn};
use scribblefield::scene::demo::{DemoOptions, demo_scene};
use scribblefield::scene::read_archive_path;

const FRAMES: u32 = 6;

/// A demo-scene capture of `seed` at 64 x 48 in `dir`.
fn capture(dir: &Path, seed: u64) -> PathBuf {
    let scene = demo_scene(&DemoOptions {
        seed,
        width: 64,
        height: 48,
        frames: FRAMES,
    })
    .unwrap();
    write_autolabel(&scene, dir);
    dir.to_path_buf()
}

/// Every file under `dir` (relative path, bytes), sorted by path.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                todo.push(path);
            } else {
                let name = path.strip_prefix(dir).unwrap().to_str().unwrap().to_string();
                out.insert(name, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

/// The masks folders at `a` and `b` hold the same `count` files, byte for byte.
#[track_caller]
fn same_files(a: &Path, b: &Path, count: usize) {
    let (fa, fb) = (files(a), files(b));
    assert_eq!(
        fa.keys().collect::<Vec<_>>(),
        fb.keys().collect::<Vec<_>>(),
        "{} and {} hold other files",
        a.display(),
        b.display()
    );
    for (name, bytes) in &fa {
        assert!(
            bytes == &fb[name],
            "{name} differs between {} and {}",
            a.display(),
            b.display()
        );
    }
    assert!(fa.len() == count, "{:?}", fa.keys());
}

/// The folder a test works in: the capture, its archive and scribbles on frames 0 and 3.
struct Setup {
    _tmp: tempfile::TempDir,
    dir: PathBuf,
}

impl Setup {
    fn new() -> Setup {
        let tmp = tempfile::tempdir().unwrap();
        let s = Setup {
            dir: tmp.path().to_path_buf(),
            _tmp: tmp,
        };
        capture(&s.dir.join("capture"), 0);
        ok(&run(&[
            "pack",
            &s.path("capture"),
            "-o",
            &s.path("s.scene.zip"),
            "--max-size",
            "32",
            "--no-features",
        ]));
        ok(&run(&[
            "scribble-from-gt",
            &s.path("s.scene.zip"),
            "--frames",
            "0,3",
            "-o",
            &s.path("l.json"),
        ]));
        s
    }

    fn path(&self, name: &str) -> String {
        self.dir.join(name).to_str().unwrap().to_string()
    }

    /// `export CHECKPOINT s.scene.zip -o OUT` plus `extra`.
    fn export(&self, checkpoint: &str, out: &str, extra: &[&str]) -> std::process::Output {
        let (ck, archive, out) = (self.path(checkpoint), self.path("s.scene.zip"), self.path(out));
        let mut args = vec!["export", &ck, &archive, "-o", &out];
        args.extend_from_slice(extra);
        run(&args)
    }
}

#[test]
fn export_writes_the_masks_segment_wrote() {
    let Some(ctx) = gpu_for_tests("export_writes_the_masks_segment_wrote") else {
        return;
    };
    drop(ctx);
    let s = Setup::new();
    // Small enough for lavapipe: the point is the path and the identity, not the quality.
    let config = r#"{"hash_levels": 4, "log2_hash_table_size": 12, "density_width": 16, "color_width": 16,
        "feature_width": 16, "semantic_width": 16, "samples_coarse": 4, "samples_fine": 12, "batch_rays": 64}"#;
    std::fs::write(s.dir.join("c.json"), config).unwrap();
    let segment = |out: &str, checkpoint: &str, extra: &[&str]| {
        let (archive, labels, out, cfg, ck) = (
            s.path("s.scene.zip"),
            s.path("l.json"),
            s.path(out),
            s.path("c.json"),
            s.path(checkpoint),
        );
        let mut args = vec![
            "segment",
            &archive,
            "--labels",
            &labels,
            "-o",
            &out,
            "--preset",
            "tiny",
            "--config",
            &cfg,
            "--warmup",
            "5",
            "--steps",
            "10",
            "--seed",
            "3",
            "--save-checkpoint",
            &ck,
        ];
        args.extend_from_slice(extra);
        ok(&run(&args))
    };

    let t = segment("seg", "a.safetensors", &[]);
    assert!(
        t.contains(&format!("saved the trained field to {}", s.path("a.safetensors"))),
        "{t}"
    );
    // The file says what it was trained on.
    let file = s.path("a.safetensors");
    let ck = Checkpoint::from_bytes(&file, std::fs::read(&file).unwrap()).unwrap();
    let on = TrainedOn::from_checkpoint(&file, &ck).unwrap();
    assert_eq!((on.frames, on.width, on.height, on.seed), (FRAMES, 32, 24, 3));
    assert_eq!(on.archive, s.path("s.scene.zip"));
    assert_eq!(ck.state.step, 15);

    let t = ok(&s.export("a.safetensors", "exp", &[]));
    assert!(t.contains("wrote 6 masks of 32 x 24 (the archive's resolution"), "{t}");
    assert!(
        t.contains("trained 15 steps on") && t.contains("(seed 3), 6 classes"),
        "{t}"
    );
    // Per frame: the mask by index, by name, its preview; classes.json, labels.json.
    let plain = 3 * FRAMES as usize + 2;
    same_files(&s.dir.join("seg"), &s.dir.join("exp"), plain);
    assert!(s.dir.join("seg/by-name/00003.png").is_file());
    // The labels given again: the same files.
    ok(&s.export("a.safetensors", "exp-l", &["--labels", &s.path("l.json")]));
    same_files(&s.dir.join("seg"), &s.dir.join("exp-l"), plain);

    // The same at the capture's resolution with every format and the object cleanup:
    // segment --source, then export --source.
    let cap = s.path("capture");
    let formats = ["--format", "voc,coco", "--format", "ply", "--objects", "2"];
    let t = segment(
        "seg-src",
        "b.safetensors",
        &[&["--source", cap.as_str()][..], &formats].concat(),
    );
    assert!(t.contains("wrote 6 masks of 64 x 48 (the capture's resolution"), "{t}");
    assert!(
        t.contains("also by-name/") && t.contains("COCO JSON") && t.contains("(--objects)"),
        "{t}"
    );
    let t = ok(&s.export(
        "b.safetensors",
        "exp-src",
        &[&["--source", cap.as_str()][..], &formats].concat(),
    ));
    assert!(t.contains("wrote 6 masks of 64 x 48 (the capture's resolution"), "{t}");
    // Plus a VOC mask per frame, labelmap.txt, the frame list, coco.json and points.ply.
    same_files(
        &s.dir.join("seg-src"),
        &s.dir.join("exp-src"),
        4 * FRAMES as usize + 2 + 4,
    );
    let coco: serde_json::Value =
        serde_json::from_slice(&std::fs::read(s.dir.join("seg-src/coco.json")).unwrap()).unwrap();
    assert_eq!(coco["images"][5]["width"], 64);
    let voc = image::open(s.dir.join("seg-src/voc/SegmentationClass/00005.png")).unwrap();
    assert_eq!((voc.width(), voc.height()), (64, 48));

    // The first field at the capture's size without refinement: another resolution, no training.
    let t = ok(&s.export(
        "a.safetensors",
        "exp-raw",
        &["--source", &cap, "--refine-iterations", "0"],
    ));
    assert!(
        t.contains("wrote 6 masks of 64 x 48") && t.contains("the field's own class maps"),
        "{t}"
    );
    let mask = image::open(s.dir.join("exp-raw/00005.png")).unwrap().into_luma8();
    assert_eq!(mask.dimensions(), (64, 48));
}

/// A checkpoint of the `tiny` preset (zero parameters, `feature_dim` 8) for `classes`, saying
/// it was trained on `archive` with `labels` when `trained_on`, as `segment --save-checkpoint`
/// writes it; without, as `simulate` writes it.
fn checkpoint(archive: &str, labels: &LabelSet, trained_on: bool) -> Vec<u8> {
    let config = FieldConfig {
        num_classes: labels.classes.len() as u32,
        feature_dim: 8,
        ..Preset::Tiny.config()
    };
    let total = ParamLayout::new(&config).total;
    let scene = read_archive_path(Path::new(archive)).unwrap();
    let extra = if trained_on {
        TrainedOn::of_scene(archive, &scene, 0, labels).to_extra()
    } else {
        BTreeMap::from([("round".to_string(), "2".to_string())])
    };
    Checkpoint {
        config,
        state: TrainerState {
            step: 20,
            params: vec![0.0; total],
            first_moment: vec![0.0; total],
            second_moment: vec![0.0; total],
        },
        extra,
    }
    .to_bytes()
}

#[test]
fn bad_checkpoints_archives_labels_and_captures_are_refused_by_name() {
    let s = Setup::new();
    let labels_text = std::fs::read(s.path("l.json")).unwrap();
    let labels = LabelSet::from_json(&labels_text, "l.json", FRAMES).unwrap();
    std::fs::write(
        s.dir.join("good.safetensors"),
        checkpoint(&s.path("s.scene.zip"), &labels, true),
    )
    .unwrap();

    // The checkpoint: missing, truncated, not a safetensors file, another safetensors file, a
    // trainer checkpoint that does not say what it was trained on (`simulate`'s).
    let o = s.export("nowhere.safetensors", "x", &[]);
    fails(
        &o,
        &[
            "nowhere.safetensors: cannot read the checkpoint",
            "segment --save-checkpoint",
        ],
    );
    let good = std::fs::read(s.dir.join("good.safetensors")).unwrap();
    std::fs::write(s.dir.join("cut.safetensors"), &good[..good.len() - 100]).unwrap();
    fails(
        &s.export("cut.safetensors", "x", &[]),
        &["cut.safetensors: ", "truncated"],
    );
    // The arguments swapped: the archive given as the checkpoint.
    let o = run(&[
        "export",
        &s.path("s.scene.zip"),
        &s.path("good.safetensors"),
        "-o",
        &s.path("x"),
    ]);
    fails(&o, &["s.scene.zip: ", "not a safetensors file"]);
    std::fs::write(
        s.dir.join("weights.safetensors"),
        scribblefield::safetensors::to_bytes(&[("w", &[2], &[1.0, 2.0])]),
    )
    .unwrap();
    fails(
        &s.export("weights.safetensors", "x", &[]),
        &[
            "weights.safetensors: no `format`",
            "not a scribblefield-trainer checkpoint",
        ],
    );
    std::fs::write(
        s.dir.join("sim.safetensors"),
        checkpoint(&s.path("s.scene.zip"), &labels, false),
    )
    .unwrap();
    fails(
        &s.export("sim.safetensors", "x", &[]),
        &[
            "sim.safetensors: no `written_by`",
            "not one written by `segment --save-checkpoint`",
        ],
    );

    // Another archive: more frames, other cameras, the same one with feature codes of another
    // width than the field renders.
    let demo = |name: &str, extra: &[&str]| {
        let out = s.path(name);
        let mut args = vec!["demo-scene", "-o", &out, "--size", "32x24"];
        args.extend_from_slice(extra);
        ok(&run(&args));
        out
    };
    let export_onto = |archive: &str| run(&["export", &s.path("good.safetensors"), archive, "-o", &s.path("x")]);
    let more = demo("more.scene.zip", &["--frames", "7"]);
    fails(
        &export_onto(&more),
        &[
            "good.safetensors: the field was trained on",
            "(6 frames of 32 x 24), but",
            "more.scene.zip has 7 frames",
        ],
    );
    let other = demo("other.scene.zip", &["--frames", "6", "--seed", "1"]);
    fails(
        &export_onto(&other),
        &["other.scene.zip has other cameras", "fingerprint"],
    );
    let coded = s.path("coded.scene.zip");
    ok(&run(&[
        "pack",
        &s.path("capture"),
        "-o",
        &coded,
        "--max-size",
        "32",
        "--features",
        "baseline",
    ]));
    fails(
        &export_onto(&coded),
        &[
            "its config has feature_dim 8, but",
            "coded.scene.zip's feature codes have",
            "dims",
        ],
    );

    // Formats that cannot be written, and no objects at all: refused before the GPU opens.
    fails(
        &s.export("good.safetensors", "x", &["--objects", "0"]),
        &["--objects", "0 keeps no region"],
    );
    let mut shared = labels.clone();
    shared.classes[3].color = shared.classes[1].color;
    std::fs::write(s.dir.join("shared.json"), shared.to_json()).unwrap();
    fails(
        &s.export(
            "good.safetensors",
            "x",
            &["--labels", &s.path("shared.json"), "--format", "coco,voc"],
        ),
        &[
            "CVAT / PASCAL VOC",
            &format!("{:?} and {:?}", labels.classes[1].name, labels.classes[3].name),
            "share the colour",
        ],
    );
    fails(
        &s.export("good.safetensors", "x", &["--format", "voc,pdf"]),
        &["--format", "pdf", "voc, coco, ply"],
    );

    // Labels with a class the field was not trained with.
    let mut three = labels.clone();
    three.classes.push(scribblefield::labels::ClassInfo {
        name: "extra".into(),
        color: [9, 9, 9],
    });
    std::fs::write(s.dir.join("l3.json"), three.to_json()).unwrap();
    fails(
        &s.export("good.safetensors", "x", &["--labels", &s.path("l3.json")]),
        &[
            "good.safetensors: the field was trained on 6 classes",
            "l3.json defines 7 classes",
        ],
    );
    // Refinement out of range.
    fails(
        &s.export("good.safetensors", "x", &["--refine-iterations", "100"]),
        &["refine", "iterations", "100"],
    );

    // Another capture (other poses), and a folder that is no capture.
    let elsewhere = capture(&s.dir.join("elsewhere"), 1);
    fails(
        &s.export("good.safetensors", "x", &["--source", elsewhere.to_str().unwrap()]),
        &["--source", "frame 0 of", "another pose"],
    );
    std::fs::create_dir_all(s.dir.join("empty")).unwrap();
    fails(
        &s.export("good.safetensors", "x", &["--source", &s.path("empty")]),
        &["--source", "empty", "not a capture layout"],
    );
    assert!(
        !s.dir.join("x").exists(),
        "a refused export must not create its output folder"
    );

    // segment refuses a checkpoint it could not write before it trains.
    let segment_to = |file: &str| {
        run(&[
            "segment",
            &s.path("s.scene.zip"),
            "--labels",
            &s.path("l.json"),
            "-o",
            &s.path("y"),
            "--save-checkpoint",
            file,
        ])
    };
    fails(
        &segment_to(&s.path("field.bin")),
        &["--save-checkpoint", "field.bin", ".safetensors"],
    );
    fails(
        &segment_to(&s.path("no/such/field.safetensors")),
        &["--save-checkpoint", "no/such", "does not exist"],
    );
    assert!(!s.dir.join("y").exists());
}
