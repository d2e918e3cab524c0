use super::*;
use crate::field::Preset;

fn sample(cfg: FieldConfig) -> Checkpoint {
    let layout = ParamLayout::new(&cfg);
    let ramp = |k: f32| (0..layout.total).map(|i| k * i as f32 - 0.5).collect::<Vec<_>>();
    Checkpoint {
        config: cfg,
        state: TrainerState {
            step: 17,
            params: ramp(1e-3),
            first_moment: ramp(-2e-4),
            second_moment: ramp(3e-6),
        },
        extra: BTreeMap::from([("round".to_string(), "4".to_string())]),
    }
}

fn tiny() -> FieldConfig {
    Preset::Tiny.config()
}

fn message(r: Result<impl Sized, CheckpointError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn a_checkpoint_round_trips_with_its_metadata() {
    let ck = sample(tiny());
    let back = Checkpoint::from_bytes("t.safetensors", ck.to_bytes()).unwrap();
    assert_eq!(back, ck);
    let mut freq = tiny();
    freq.encoding = crate::field::config::Encoding::freq_only_baseline();
    let ck = sample(freq);
    assert_eq!(Checkpoint::from_bytes("t.safetensors", ck.to_bytes()).unwrap(), ck);
}

#[test]
fn a_checkpoint_from_before_the_opaque_last_sample_renders_without_it() {
    let mut cfg = tiny();
    cfg.last_sample = LastSample::Opaque;
    let ck = sample(cfg);
    assert_eq!(Checkpoint::from_bytes("t.safetensors", ck.to_bytes()).unwrap(), ck);
    // The field blanked out of the config in the header (spaces keep its length and are
    // whitespace to JSON), as a checkpoint written before the field existed has it.
    let mut bytes = ck.to_bytes();
    let field = br#"\"last_sample\":\"opaque\","#;
    let at = bytes.windows(field.len()).position(|w| w == field).unwrap();
    bytes[at..at + field.len()].fill(b' ');
    let back = Checkpoint::from_bytes("old.safetensors", bytes).unwrap();
    assert_eq!(back.config.last_sample, LastSample::Clear);
    assert_eq!(back.state, ck.state);
}

#[test]
fn it_is_a_plain_safetensors_file_with_one_tensor_per_layout_range() {
    // `small`: level 0 (16 cells, 17³ vertices) is dense, the 7 others hashed (2^14).
    let ck = sample(Preset::Small.config());
    let st = SafeTensors::from_bytes("t.safetensors", ck.to_bytes()).unwrap();
    let cfg = &ck.config;
    let layout = ParamLayout::new(cfg);
    assert_eq!(
        st.f32("hash_table.0", &[17 * 17 * 17, 2]).unwrap(),
        ck.state.params[layout.hash_levels[0].clone()]
    );
    assert_eq!(
        st.f32("adam.first_moment.hash_table.7", &[1 << 14, 2]).unwrap(),
        ck.state.first_moment[layout.hash_levels[7].clone()]
    );
    assert!(st.f32("hash_table", &[8, 1 << 14, 2]).is_err());
    let d = &layout.density.dims;
    assert_eq!(
        st.f32("adam.second_moment.density.1", &[d[2], d[1]]).unwrap(),
        ck.state.second_moment[layout.density.layers[1].clone()]
    );
    assert_eq!(st.metadata()["format"], FORMAT);
    assert_eq!(st.metadata()["step"], "17");
    assert_eq!(st.metadata()["round"], "4");
    // The one `hash_table` range is a tensor per level.
    assert_eq!(st.names().count(), 3 * (layout.named_ranges().len() - 1 + 8));
}

#[test]
fn a_version_1_checkpoint_with_full_tables_per_level_is_refused() {
    // What version 1 wrote: one `hash_table` tensor [levels, 2^log2, features].
    let cfg = Preset::Small.config();
    let layout = ParamLayout::new(&cfg);
    let full = vec![0.5f32; 8 * (1 << 14) * 2];
    let mut metadata = BTreeMap::new();
    for (k, v) in [("format", FORMAT), ("version", "1"), ("step", "3")] {
        metadata.insert(k.to_string(), v.to_string());
    }
    metadata.insert("config".into(), serde_json::to_string(&cfg).unwrap());
    let params = vec![0.25f32; layout.total];
    let mut entries: Vec<(&str, &[usize], &[f32])> = vec![("hash_table", &[8, 1 << 14, 2], &full)];
    let list = tensors(&cfg, &layout);
    entries.extend(
        list.iter()
            .filter(|(n, ..)| !n.starts_with("hash_table"))
            .map(|(n, s, r)| (n.as_str(), &s[..], &params[r.clone()])),
    );
    let m = message(Checkpoint::from_bytes(
        "old.safetensors",
        to_bytes_with_metadata(&entries, &metadata),
    ));
    assert!(
        m.starts_with("old.safetensors: ") && m.contains("version \"1\"") && m.contains("train again"),
        "{m}"
    );
}

#[test]
fn bad_files_are_refused_naming_the_file_and_the_problem() {
    let bytes = sample(tiny()).to_bytes();
    let m = message(Checkpoint::from_bytes(
        "t.safetensors",
        bytes[..bytes.len() - 8].to_vec(),
    ));
    assert!(m.starts_with("t.safetensors: ") && m.contains("truncated"), "{m}");
    assert_eq!(m.matches("t.safetensors").count(), 1, "{m}");
    let m = message(Checkpoint::from_bytes("t.safetensors", bytes[..100].to_vec()));
    assert!(m.contains("t.safetensors") && m.contains("truncated"), "{m}");
    let m = message(Checkpoint::from_bytes(
        "x.safetensors",
        crate::safetensors::to_bytes(&[("w", &[1], &[1.0])]),
    ));
    assert!(
        m.contains("x.safetensors: no `format`") && m.contains("not a scribblefield-trainer"),
        "{m}"
    );
    let mut old = b"SFTRAIN1".to_vec();
    old.extend_from_slice(&[0; 12]);
    let m = message(Checkpoint::from_bytes("run/trainer.bin", old));
    assert!(
        m.contains("run/trainer.bin: ") && m.contains("old private format"),
        "{m}"
    );
    // A tensor of the wrong shape is named.
    let ck = sample(tiny());
    let mut other = ck.config.clone();
    other.density_width += 1;
    let layout = ParamLayout::new(&ck.config);
    let mut metadata = BTreeMap::new();
    for (k, v) in [("format", FORMAT), ("version", VERSION), ("step", "1")] {
        metadata.insert(k.to_string(), v.to_string());
    }
    metadata.insert("config".into(), serde_json::to_string(&other).unwrap());
    let list = tensors(&ck.config, &layout);
    let entries: Vec<(&str, &[usize], &[f32])> = list
        .iter()
        .map(|(n, s, r)| (n.as_str(), &s[..], &ck.state.params[r.clone()]))
        .collect();
    let m = message(Checkpoint::from_bytes(
        "t.safetensors",
        to_bytes_with_metadata(&entries, &metadata),
    ));
    assert!(
        m.contains("t.safetensors: tensor `density.0`") && m.contains("shape"),
        "{m}"
    );
}

fn demo(seed: u64, frames: u32) -> Scene {
    crate::scene::demo::demo_scene(&crate::scene::demo::DemoOptions {
        seed,
        width: 20,
        height: 16,
        frames,
    })
    .unwrap()
}

fn two_classes() -> LabelSet {
    let text = r#"{"format":"scribblefield-labels","version":1,
        "classes":[{"name":"a","color":[1,2,3]},{"name":"b","color":[4,5,6]}],"frames":[]}"#;
    LabelSet::from_json(text.as_bytes(), "l.json", 4).unwrap()
}

fn trained(scene: &Scene) -> Checkpoint {
    let mut ck = sample(FieldConfig {
        num_classes: 2,
        ..tiny()
    });
    ck.extra = TrainedOn::of_scene("d.scene.zip", scene, 7, &two_classes()).to_extra();
    Checkpoint::from_bytes("t.safetensors", ck.to_bytes()).unwrap()
}

#[test]
fn what_segment_trained_on_round_trips_and_fits_its_archive() {
    let scene = demo(0, 4);
    let ck = trained(&scene);
    let on = TrainedOn::from_checkpoint("t.safetensors", &ck).unwrap();
    assert_eq!(on, TrainedOn::of_scene("d.scene.zip", &scene, 7, &two_classes()));
    assert_eq!((on.frames, on.width, on.height, on.seed), (4, 20, 16, 7));
    on.check_scene("t.safetensors", &ck.config, "elsewhere/d.scene.zip", &scene)
        .unwrap();
    on.check_labels("t.safetensors", &two_classes(), "l.json").unwrap();
}

#[test]
fn another_archive_or_other_labels_are_named() {
    let scene = demo(0, 4);
    let ck = trained(&scene);
    let on = TrainedOn::from_checkpoint("t.safetensors", &ck).unwrap();
    let check = |other: &Scene| message(on.check_scene("t.safetensors", &ck.config, "o.scene.zip", other));
    let m = check(&demo(0, 5));
    assert!(
        m.starts_with(
            "t.safetensors: the field was trained on d.scene.zip (4 frames of 20 x 16), but o.scene.zip has 5 frames"
        ),
        "{m}"
    );
    let m = check(&demo(1, 4));
    assert!(m.contains("o.scene.zip has other cameras"), "{m}");
    let mut repainted = scene.clone();
    repainted.frames[2].rgb.put_pixel(0, 0, image::Rgb([1, 2, 3]));
    let m = check(&repainted);
    assert!(m.contains("o.scene.zip has other images with the same cameras"), "{m}");
    let mut coded = scene.clone();
    coded.features = Some(crate::scene::FeatureCodes {
        height: 1,
        width: 1,
        dim: ck.config.feature_dim + 1,
        extractor: "x".into(),
        data: vec![half::f16::ZERO; 4 * (ck.config.feature_dim as usize + 1)],
        pca: crate::scene::Pca {
            mean: Vec::new(),
            components: [Vec::new(), Vec::new(), Vec::new()],
            lo: [0.0; 3],
            hi: [1.0; 3],
        },
    });
    let m = check(&coded);
    assert!(
        m.contains(&format!(
            "its config has feature_dim {}, but o.scene.zip's feature codes have {} dims",
            ck.config.feature_dim,
            ck.config.feature_dim + 1
        )),
        "{m}"
    );
    let mut three = two_classes();
    three.classes.push(crate::labels::ClassInfo {
        name: "c".into(),
        color: [7, 8, 9],
    });
    let m = message(on.check_labels("t.safetensors", &three, "l3.json"));
    assert!(
        m.contains("trained on 2 classes [\"a\", \"b\"], but l3.json defines 3 classes"),
        "{m}"
    );
}

#[test]
fn a_checkpoint_without_what_it_was_trained_on_says_so() {
    let ck = sample(tiny());
    let m = message(TrainedOn::from_checkpoint("run/trainer.safetensors", &ck));
    assert!(
        m.starts_with("run/trainer.safetensors: no `written_by`") && m.contains("segment --save-checkpoint"),
        "{m}"
    );
    let scene = demo(0, 4);
    let mut ck = trained(&scene);
    ck.extra.insert(trained_on_keys::SIZE.into(), "20 by 16".into());
    let m = message(TrainedOn::from_checkpoint("t.safetensors", &ck));
    assert!(m.contains("archive_size \"20 by 16\" is not WIDTHxHEIGHT"), "{m}");
    let mut ck = trained(&scene);
    ck.config.num_classes = 3;
    let m = message(TrainedOn::from_checkpoint("t.safetensors", &ck));
    assert!(
        m.contains("labels define 2 classes, but its field config has num_classes 3"),
        "{m}"
    );
}

#[test]
fn another_model_is_named_by_its_differences() {
    let ck = sample(tiny());
    assert!(ck.layout_differences(&ck.config).is_empty());
    let mut other = ck.config.clone();
    other.loss.rgb *= 2.0;
    assert!(
        ck.layout_differences(&other).is_empty(),
        "loss weights do not change the layout"
    );
    other.semantic_width *= 2;
    let diff = ck.layout_differences(&other);
    assert!(
        diff.len() == 2 && diff.iter().any(|d| d.starts_with("semantic_width:")),
        "{diff:?}"
    );
}
