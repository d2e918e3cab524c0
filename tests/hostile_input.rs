//! Hostile annotations on every path they come in by (labels.json, a share link, an autosave):
//! each is refused with an error that names the frame, the stroke and the limit. Hostile
//! archives are in tests/archive/hostile.rs, hostile captures in the import tests.
use std::time::Instant;

use scribblefield::labels::autosave::Autosave;
use scribblefield::labels::limits::{MAX_POINTS_PER_STROKE, MAX_RADIUS, MAX_TOTAL_POINTS};
use scribblefield::labels::share::{ShareError, decode_labels, encode_labels};
use scribblefield::labels::{ClassInfo, FrameLabels, LabelSet, Stroke};

const FRAMES: u32 = 4;

fn classes() -> Vec<ClassInfo> {
    vec![
        ClassInfo {
            name: "floor".into(),
            color: [1, 2, 3],
        },
        ClassInfo {
            name: "mug".into(),
            color: [4, 5, 6],
        },
    ]
}

fn stroke(radius: f32, points: usize) -> Stroke {
    Stroke {
        class: Some(1),
        radius,
        points: (0..points).map(|i| [(i % 64) as f32, 3.0]).collect(),
    }
}

fn with_strokes(frames: Vec<(u32, Vec<Stroke>)>) -> LabelSet {
    let mut set = LabelSet::new(classes());
    set.frames = frames
        .into_iter()
        .map(|(frame, strokes)| FrameLabels { frame, strokes })
        .collect();
    set
}

fn json_error(set: &LabelSet) -> String {
    LabelSet::from_json(set.to_json().as_bytes(), "labels.json", FRAMES)
        .unwrap_err()
        .to_string()
}

fn assert_mentions(err: &str, parts: &[&str]) {
    for p in parts {
        assert!(err.contains(p), "error {err:?} should mention {p:?}");
    }
}

#[test]
fn brush_radius_is_capped_at_the_brushs_maximum() {
    assert_eq!(MAX_RADIUS, scribblefield::labels::brush::MAX_RADIUS);
    let ok = with_strokes(vec![(1, vec![stroke(MAX_RADIUS, 2)])]);
    LabelSet::from_json(ok.to_json().as_bytes(), "labels.json", FRAMES).unwrap();
    let err = json_error(&with_strokes(vec![(1, vec![stroke(1.0, 1), stroke(4096.0, 2)])]));
    assert_mentions(
        &err,
        &["labels.json", "frame 1 stroke 1: brush radius 4096 is not in (0, 200]"],
    );
}

#[test]
fn points_per_stroke_are_capped() {
    let set = with_strokes(vec![(2, vec![stroke(2.0, MAX_POINTS_PER_STROKE + 1)])]);
    let err = json_error(&set);
    assert_mentions(
        &err,
        &[
            "labels.json",
            "frame 2 stroke 0: 65537 points, more than the limit of 65536 per stroke",
        ],
    );
}

#[test]
fn points_over_all_strokes_are_capped() {
    // Full strokes on every frame until the total passes the limit.
    let per_frame = MAX_TOTAL_POINTS / MAX_POINTS_PER_STROKE / FRAMES as usize + 1;
    let frames = (0..FRAMES)
        .map(|f| (f, (0..per_frame).map(|_| stroke(1.0, MAX_POINTS_PER_STROKE)).collect()))
        .collect();
    let err = with_strokes(frames)
        .check("labels.json", FRAMES)
        .unwrap_err()
        .to_string();
    assert_mentions(&err, &["labels.json", "stroke", "past the limit of 1048576"]);
}

#[test]
fn a_frame_listed_twice_is_refused_naming_it() {
    let set = with_strokes(vec![
        (1, vec![stroke(1.0, 1)]),
        (3, vec![stroke(1.0, 1)]),
        (1, vec![stroke(2.0, 1)]),
    ]);
    assert_mentions(&json_error(&set), &["labels.json", "frame 1 has more than one entry"]);
}

#[test]
fn a_small_link_holding_millions_of_points_is_refused_quickly() {
    // Like the hostile link first reported: 32 strokes of 65536 repeated points (2 M points)
    // deflate to a code of a few thousand characters. It must be refused before the points are built.
    let strokes = (0..32)
        .map(|_| Stroke {
            class: Some(0),
            radius: 2.0,
            points: vec![[5.0, 5.0]; MAX_POINTS_PER_STROKE],
        })
        .collect();
    let code = encode_labels(&with_strokes(vec![(0, strokes)]));
    assert!(code.len() < 20_000, "{} characters", code.len());
    let start = Instant::now();
    let err = decode_labels(&code).unwrap_err();
    assert!(start.elapsed().as_secs_f64() < 5.0, "{:?}", start.elapsed());
    assert!(matches!(err, ShareError::Limit(_)), "{err:?}");
    assert_mentions(
        &err.to_string(),
        &[
            "over a limit",
            "frame 0 stroke 16: brings the points of all strokes past the limit of 1048576",
        ],
    );

    let one = with_strokes(vec![(3, vec![stroke(1.0, 2), stroke(1.0, MAX_POINTS_PER_STROKE + 1)])]);
    let err = decode_labels(&encode_labels(&one)).unwrap_err().to_string();
    assert_mentions(
        &err,
        &["frame 3 stroke 1: 65537 points, more than the limit of 65536 per stroke"],
    );

    let wide = with_strokes(vec![(2, vec![stroke(4096.0, 3)])]);
    let err = decode_labels(&encode_labels(&wide)).unwrap_err().to_string();
    assert_mentions(&err, &["frame 2 stroke 0: brush radius 4096 is not in (0, 200]"]);
}

#[test]
fn links_within_the_limits_still_read_and_a_frame_listed_twice_is_merged_in_order() {
    let set = with_strokes(vec![
        (1, vec![stroke(1.5, 3)]),
        (2, vec![stroke(2.0, 1)]),
        (1, vec![stroke(200.0, 2)]),
    ]);
    let back = decode_labels(&encode_labels(&set)).unwrap();
    back.check("link", FRAMES).unwrap();
    assert_eq!(back.frames.len(), 2);
    assert_eq!(back.frames[0].frame, 1);
    assert_eq!(back.frames[0].strokes, vec![stroke(1.5, 3), stroke(200.0, 2)]);
    assert_eq!(back.frames[1].strokes, vec![stroke(2.0, 1)]);
}

#[test]
fn an_autosave_over_the_limits_is_refused_naming_frame_and_stroke() {
    let set = with_strokes(vec![(0, vec![stroke(1.0, 1), stroke(1.0, 1), stroke(250.0, 1)])]);
    let text = Autosave::new(&set, FRAMES, 64, 48, 0.0).to_json();
    let err = Autosave::from_json(&text, "the saved annotations", FRAMES, 64, 48)
        .unwrap_err()
        .to_string();
    assert_mentions(
        &err,
        &[
            "the saved annotations",
            "frame 0 stroke 2: brush radius 250 is not in (0, 200]",
        ],
    );
    let set = with_strokes(vec![(0, vec![stroke(1.0, 1)]), (0, vec![stroke(1.0, 1)])]);
    let text = Autosave::new(&set, FRAMES, 64, 48, 0.0).to_json();
    let err = Autosave::from_json(&text, "the saved annotations", FRAMES, 64, 48)
        .unwrap_err()
        .to_string();
    assert_mentions(&err, &["frame 0 has more than one entry"]);
}
