//! The quality suite's short variant (`scribblefield suite --short`; docs/quality.md, "The
//! quality suite"): every capture trained once, headless on the GPU (lavapipe in CI), with
//! scribble set 0 and trainer seed 0, the strokes spread as the defaults say, every scored frame
//! rendered, refined and scored. Training on lavapipe gives the same bits run after run, so each
//! floor sits about 0.03 under what this run measured (docs/quality.md, "The floors of
//! tests/quality.rs"); they guard against regressions, they are not the goals. The full suite (3
//! runs per capture, the strokes alone beside the spread, the ceilings) decides defaults.
use std::path::{Path, PathBuf};

use scribblefield::eval::suite::{Mode, RunResult, RunSpec, captures::capture, run_one};
use scribblefield::gpu::test_support::gpu_for_tests;

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// Trains and scores capture `name` as the short variant does; None (the test checks nothing)
/// without its data or a GPU.
fn short_run(name: &str) -> Option<RunResult> {
    let capture = capture(name).expect("a capture of the suite");
    let cache = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/suite-scenes");
    let Some(scene) = capture.load_cached(&data(), &cache).unwrap() else {
        eprintln!(
            "\n!!! SKIPPING: real data for {name} is absent under {}; this test checks nothing here !!!\n",
            data().display()
        );
        return None;
    };
    let ctx = gpu_for_tests(name)?;
    let spec = RunSpec {
        capture,
        mode: Mode::Spread,
        set: 0,
        seed: 0,
    };
    let result = run_one(&ctx, &scene, &spec, None).unwrap();
    eprintln!(
        "{name}: mean IoU {:.3} (field {:.3}, boundary {:.3}, pixel accuracy {:.3}), refinements {:?}, spread {:?}, check {:?}, in {:.0} s",
        result.mean_iou,
        result.field_mean_iou,
        result.boundary_iou,
        result.pixel_accuracy,
        result.refine_variants,
        result.spread,
        result.check,
        result.seconds
    );
    Some(result)
}

fn assert_floor(result: &RunResult, floor: f64) {
    assert!(
        result.mean_iou > floor,
        "{}: mean IoU {:.3}, floor {floor}",
        result.capture,
        result.mean_iou
    );
}

#[test]
fn demo() {
    if let Some(r) = short_run("demo") {
        assert_floor(&r, 0.91);
    }
}

#[test]
fn demo_without_depth() {
    if let Some(r) = short_run("demo-no-depth") {
        assert_floor(&r, 0.61);
    }
}

#[test]
fn objects_on_a_white_backdrop() {
    if let Some(r) = short_run("backdrop-white") {
        assert_floor(&r, 0.90);
    }
}

#[test]
fn objects_on_a_black_backdrop() {
    if let Some(r) = short_run("backdrop-black") {
        assert_floor(&r, 0.91);
    }
}

/// The real YCB-Video clip: strokes on frame 0, frames 1-9 scored. Dense depth: no opaque last
/// sample, no far class, no opacity term.
#[test]
fn ycb() {
    if let Some(r) = short_run("ycb") {
        assert_floor(&r, 0.87);
        assert_eq!(r.opacity_far_class, None);
    }
}

/// The COLMAP head: the room (the masks' background, class 0) lies beyond the box, and the
/// opacity term pulls its rays through it (docs/quality.md, "Photo captures").
#[test]
fn alexander() {
    if let Some(r) = short_run("alexander") {
        assert_floor(&r, 0.91);
        assert_eq!(r.opacity_far_class, Some(0));
    }
}

#[test]
fn moldgoldcape() {
    if let Some(r) = short_run("moldgoldcape") {
        assert_floor(&r, 0.89);
    }
}
