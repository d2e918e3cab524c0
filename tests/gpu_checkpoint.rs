//! The trainer's checkpoint (`saved_field`, a safetensors file) on lavapipe: a checkpoint
//! written by one trainer, read from disk by a fresh trainer, gives the same state and renders the
//! same frame bit for bit; another model refuses it, naming the file.
use std::collections::BTreeMap;

use scribblefield::field::FieldConfig;
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frames};
use scribblefield::saved_field::Checkpoint;
use scribblefield::scene::demo::{DemoOptions, demo_scene};

#[test]
fn a_checkpoint_written_by_one_trainer_loads_in_another_and_renders_the_same() {
    let Some(ctx) = gpu_for_tests("a_checkpoint_written_by_one_trainer_loads_in_another_and_renders_the_same") else {
        return;
    };
    let mut scene = demo_scene(&DemoOptions {
        width: 32,
        height: 24,
        frames: 4,
        ..Default::default()
    })
    .unwrap();
    scene.labels = Some(scribble_frames(&scene, &[0], &ScribbleOptions::default()));
    let cfg = FieldConfig {
        num_classes: scene.classes.len() as u32,
        batch_rays: 64,
        ..FieldConfig::small()
    };
    let mut first = pollster::block_on(Trainer::new(&ctx, &scene, &cfg, 1)).unwrap();
    first.train(5);
    let extra = BTreeMap::from([("note".to_string(), "test".to_string())]);
    let checkpoint = pollster::block_on(first.checkpoint(extra.clone())).unwrap();
    assert_eq!(checkpoint.state.step, 5);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("trainer.safetensors");
    std::fs::write(&path, checkpoint.to_bytes()).unwrap();

    let name = path.display().to_string();
    let read = Checkpoint::from_bytes(&name, std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(read, checkpoint);
    assert_eq!(read.extra, extra);
    // The same seed: it also jitters the renderer's samples, and is the trainer's, not the
    // checkpoint's. The fresh trainer starts from the initial parameters.
    let mut second = pollster::block_on(Trainer::new(&ctx, &scene, &cfg, 1)).unwrap();
    let before = pollster::block_on(second.read_state()).unwrap();
    assert!(
        before.params != checkpoint.state.params,
        "training moved the parameters"
    );
    second.restore_checkpoint(&name, &read).unwrap();
    assert_eq!(pollster::block_on(second.read_state()).unwrap(), checkpoint.state);
    assert_eq!(second.steps_done(), 5);

    let a = pollster::block_on(first.render_frame(1, scene.width, scene.height)).unwrap();
    let b = pollster::block_on(second.render_frame(1, scene.width, scene.height)).unwrap();
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert!(a.classes == b.classes, "classes differ");
    assert!(bits(&a.depth) == bits(&b.depth), "depth differs");
    assert!(bits(&a.confidence) == bits(&b.confidence), "confidence differs");

    // A model of another width cannot take it, and says which file and what differs.
    let wider = FieldConfig {
        semantic_width: cfg.semantic_width * 2,
        ..cfg.clone()
    };
    let mut other = pollster::block_on(Trainer::new(&ctx, &scene, &wider, 1)).unwrap();
    let err = other.restore_checkpoint(&name, &read).unwrap_err().to_string();
    assert!(
        err.contains("trainer.safetensors") && err.contains("another model") && err.contains("semantic_width"),
        "{err}"
    );
}
