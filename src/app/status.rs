//! What the page tells scripts and tests: one JSON object on `<body data-status="...">` (the
//! canvas itself cannot be inspected from outside), written by `page_status::set`. The field
//! names and values are documented in docs/web-app.md ("For scripts"); `tests/e2e/lib.mjs`
//! reads them with `JSON.parse`. Plain data: tested natively.
use serde::Serialize;

/// The page's state. `index.html` writes `{"state":"starting"}` and `{"state":"error",...}`
/// itself before the app runs (and watches for `crashed`).
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum PageStatus {
    Loading,
    /// `frames` is 0 until the archive's manifest has been read.
    Decoding {
        done: usize,
        frames: usize,
    },
    /// Packing a capture in the page: `stage` is `reading` (its files into memory), `frames`
    /// (decoding them), `features`, `autoencoder` (its steps) or `writing` (the archive), with
    /// `done` of `total` (both 0 where the stage has no count).
    Packing {
        stage: &'static str,
        done: usize,
        total: usize,
    },
    /// Packing was cancelled; no scene is open.
    Cancelled,
    Ready(Box<Annotating>),
    /// The scene could not be opened, or the app could not start; shown in the page too.
    Error {
        message: String,
    },
    /// The app is gone (a panic); `index.html` shows the message over the canvas.
    Crashed {
        message: String,
    },
}

/// Where annotating stands.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Annotating {
    pub frames: usize,
    /// Frame size `[width, height]`.
    pub size: [u32; 2],
    /// The frame shown.
    pub frame: usize,
    /// The class the brush paints.
    pub class: u16,
    pub tool: &'static str,
    pub classes: usize,
    pub strokes: usize,
    /// Labelled pixels over every frame.
    pub labelled: u64,
    /// `none` (no GPU), `starting`, `running`, `spreading` (the latest strokes are being spread
    /// over the frames; training waits), `paused`, `exporting`, `failed`.
    pub training: &'static str,
    /// The labels the field trains on: `[pixels, frames]` (strokes and where they spread).
    pub spread: Option<[usize; 2]>,
    /// While exporting: `[done, total]` frames.
    pub exporting: Option<[u32; 2]>,
    pub steps: u32,
    pub sps: f64,
    /// Loss per ray of the latest batch.
    pub loss: Option<f64>,
    /// The step of the mask shown for this frame, -1 for none.
    pub rendered: i64,
    /// The latest edit is on disk (`save.state` is `saved`).
    pub saved: bool,
    /// The field trains on frames this many times smaller.
    pub res: u32,
    pub render_ms: f64,
    /// The frame's rectangle on the page, CSS pixels: `[x, y, width, height]`.
    pub view: [f32; 4],
    /// `none`, `coarse` (a quick low-resolution mask) or `full`; absent without training.
    pub mask: Option<&'static str>,
    /// The mask is drawn over the frame: false until the field has trained on a stroke (before,
    /// its classes are the semantic head's random start).
    pub classes_shown: bool,
    /// The latest refresh's time to the first mask and to the full one (`null` while under way).
    pub refresh_ms: Option<[Option<f64>; 2]>,
    /// Per step of the latest batch: recording and submitting, then waiting for the GPU.
    pub step_ms: Option<[f64; 2]>,
    pub batch: Option<u32>,
    /// Where the rendered-features image is, `[x, y, width, height]`, when a render of this
    /// frame is shown.
    pub features: Option<[f32; 4]>,
    /// Why training stopped.
    pub failure: Option<String>,
    /// Where saving the annotations stands.
    pub save: SaveStatus,
}

/// Where saving stands (`save` in the status); docs/web-app.md ("Nothing lost") says what is
/// kept where.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SaveStatus {
    /// `saved` (the latest edit is on disk), `saving`, `failed` (NOT saved: see `error`),
    /// `read_only` (another tab saves this scene), `unavailable` (no IndexedDB).
    pub state: &'static str,
    pub error: Option<String>,
    /// The archive's content id, which the saves are keyed by.
    pub scene: String,
    /// The scene's snapshots, oldest first: `[seq, strokes]`.
    pub snapshots: Vec<[u64; 2]>,
    /// Keys of set-aside (unreadable) records in IndexedDB store `aside`.
    pub aside: Vec<String>,
    /// Snapshots offered from another version of the archive at the same URL (only when this
    /// one has none).
    pub others: usize,
    /// Whether the browser granted persistent storage (`null`: no answer).
    pub persisted: Option<bool>,
}

impl PageStatus {
    pub fn to_json(&self) -> String {
        // Serializing plain data with string keys cannot fail.
        serde_json::to_string(self).unwrap_or_else(|e| format!(r#"{{"state":"error","message":"{e}"}}"#))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_are_tagged() {
        assert_eq!(PageStatus::Loading.to_json(), r#"{"state":"loading"}"#);
        assert_eq!(
            PageStatus::Decoding { done: 3, frames: 36 }.to_json(),
            r#"{"state":"decoding","done":3,"frames":36}"#
        );
        assert_eq!(
            PageStatus::Packing {
                stage: "autoencoder",
                done: 100,
                total: 1000
            }
            .to_json(),
            r#"{"state":"packing","stage":"autoencoder","done":100,"total":1000}"#
        );
        assert_eq!(
            PageStatus::Error {
                message: "a \"b\" 404".into()
            }
            .to_json(),
            r#"{"state":"error","message":"a \"b\" 404"}"#
        );
    }

    #[test]
    fn ready_carries_the_annotation_fields() {
        let status = PageStatus::Ready(Box::new(Annotating {
            frames: 36,
            size: [160, 120],
            frame: 5,
            class: 1,
            tool: "brush",
            classes: 4,
            strokes: 2,
            labelled: 300,
            training: "running",
            spread: Some([5000, 3]),
            exporting: None,
            steps: 12,
            sps: 0.5,
            loss: Some(0.25),
            rendered: -1,
            saved: true,
            res: 4,
            render_ms: 1500.0,
            view: [1.0, 2.0, 3.0, 4.0],
            mask: Some("coarse"),
            classes_shown: true,
            refresh_ms: Some([Some(10.0), None]),
            step_ms: Some([1.0, 2.0]),
            batch: Some(3),
            features: None,
            failure: None,
            save: SaveStatus {
                state: "saved",
                snapshots: vec![[0, 2]],
                ..SaveStatus::default()
            },
        }));
        let json: serde_json::Value = serde_json::from_str(&status.to_json()).unwrap();
        assert_eq!(json["state"], "ready");
        assert_eq!(json["frames"], 36);
        assert_eq!(json["frame"], 5);
        assert_eq!(json["view"][2], 3.0);
        assert_eq!(json["mask"], "coarse");
        assert_eq!(json["classes_shown"], true);
        assert_eq!(json["spread"][1], 3);
        assert_eq!(json["refresh_ms"][1], serde_json::Value::Null);
        assert_eq!(json["features"], serde_json::Value::Null);
        assert_eq!(json["save"]["state"], "saved");
        assert_eq!(json["save"]["snapshots"][0][1], 2);
    }
}
