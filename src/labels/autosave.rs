//! One saved state of a scene's labels, as the annotator keeps it so nothing is lost to a reload
//! or a crash: the labels and enough about the scene (frames and size) to refuse restoring them
//! onto a different one. `labels::snapshots` keeps the last few of these per scene, keyed by the
//! archive's content. Where a scene came from (`SceneSource`) names it in messages and share
//! links; its `storage_key` is the key the old build saved under in local storage, which the
//! store reads once to migrate such saves.
use serde::{Deserialize, Serialize};

use super::LabelSet;
use crate::scene::error::SceneError;

pub const AUTOSAVE_FORMAT: &str = "scribblefield-autosave";
pub const AUTOSAVE_VERSION: u32 = 1;
const KEY_PREFIX: &str = "scribblefield/labels/";

/// Where a scene came from, as the autosave key sees it.
#[derive(Clone, Debug, PartialEq)]
pub enum SceneSource {
    /// Fetched from a URL (absolute, as the page resolved it).
    Url(String),
    /// Opened from a local file (picker or drop): its name and size are all the page knows.
    File { name: String, bytes: u64 },
}

impl SceneSource {
    /// The storage key of this scene's annotations. A URL's fragment is dropped: it is not part
    /// of the resource.
    pub fn storage_key(&self) -> String {
        match self {
            SceneSource::Url(url) => format!("{KEY_PREFIX}{}", url.split('#').next().unwrap_or(url)),
            SceneSource::File { name, bytes } => format!("{KEY_PREFIX}file:{name}:{bytes}"),
        }
    }

    /// The URL a share link can point to, if there is one.
    pub fn url(&self) -> Option<&str> {
        match self {
            SceneSource::Url(url) => Some(url),
            SceneSource::File { .. } => None,
        }
    }

    /// For messages: the URL or the file name.
    pub fn describe(&self) -> &str {
        match self {
            SceneSource::Url(url) => url,
            SceneSource::File { name, .. } => name,
        }
    }
}

/// One stored entry.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Autosave {
    pub format: String,
    pub version: u32,
    /// Frame count and size of the scene the labels were drawn on.
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    /// Milliseconds since the Unix epoch (the page's clock).
    pub saved_at_ms: f64,
    pub labels: LabelSet,
}

impl Autosave {
    pub fn new(labels: &LabelSet, frames: u32, width: u32, height: u32, saved_at_ms: f64) -> Autosave {
        Autosave {
            format: AUTOSAVE_FORMAT.into(),
            version: AUTOSAVE_VERSION,
            frames,
            width,
            height,
            saved_at_ms,
            labels: labels.clone(),
        }
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("autosaves always serialize")
    }

    /// Reads an entry back for a scene of `frames` frames of `width x height`; `key` names the
    /// entry in errors. A mismatch is an error: those labels belong to another scene.
    pub fn from_json(text: &str, key: &str, frames: u32, width: u32, height: u32) -> Result<Autosave, SceneError> {
        let save: Autosave = serde_json::from_str(text).map_err(|source| SceneError::Json {
            file: key.into(),
            source,
        })?;
        if save.format != AUTOSAVE_FORMAT || save.version != AUTOSAVE_VERSION {
            return Err(SceneError::invalid(
                key,
                format!(
                    "{} version {} is not an autosave this build reads",
                    save.format, save.version
                ),
            ));
        }
        if (save.frames, save.width, save.height) != (frames, width, height) {
            return Err(SceneError::invalid(
                key,
                format!(
                    "saved for a scene of {} frames of {} x {}, this one has {frames} of {width} x {height}",
                    save.frames, save.width, save.height
                ),
            ));
        }
        save.labels.check(key, frames)?;
        Ok(save)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, Stroke};

    #[test]
    fn keys_follow_the_scene_not_the_fragment() {
        let a = SceneSource::Url("https://h/a.scene.zip#labels=xyz".into());
        let b = SceneSource::Url("https://h/a.scene.zip".into());
        assert_eq!(a.storage_key(), b.storage_key());
        let f = SceneSource::File {
            name: "a.scene.zip".into(),
            bytes: 10,
        };
        assert_ne!(f.storage_key(), b.storage_key());
        assert_eq!(f.url(), None);
    }

    #[test]
    fn entries_round_trip_and_refuse_other_scenes() {
        let mut labels = LabelSet::new(vec![ClassInfo {
            name: "a".into(),
            color: [1, 2, 3],
        }]);
        labels.push_stroke(
            3,
            Stroke {
                class: Some(0),
                radius: 2.0,
                points: vec![[1.0, 1.0]],
            },
        );
        let text = Autosave::new(&labels, 10, 160, 120, 1.5e12).to_json();
        let back = Autosave::from_json(&text, "k", 10, 160, 120).unwrap();
        assert_eq!(back.labels, labels);
        let err = Autosave::from_json(&text, "k", 10, 320, 240).unwrap_err().to_string();
        assert!(err.contains("160 x 120"), "{err}");
        assert!(Autosave::from_json("{", "k", 10, 160, 120).is_err());
        // Labels on a frame the scene does not have are refused even when the sizes agree.
        let mut far = labels.clone();
        far.frames[0].frame = 50;
        let text = Autosave::new(&far, 10, 160, 120, 0.0).to_json();
        assert!(Autosave::from_json(&text, "k", 10, 160, 120).is_err());
    }
}
