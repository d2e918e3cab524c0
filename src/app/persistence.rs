//! Keeping annotations: autosave to the browser's storage, restore on load, share links, and
//! the annotations file (export and import).
use super::browser::{self, BrowserError};
use crate::labels::autosave::{Autosave, SceneSource};
use crate::labels::share::{ShareError, decode_labels, share_fragment};
use crate::labels::{ClassInfo, LabelSet};
use crate::scene::Scene;

/// Key under which the autosave that a shared link displaced is kept.
fn displaced_key(source: &SceneSource) -> String {
    format!("{}#before-link", source.storage_key())
}

/// Where the labels the annotator starts with came from.
#[derive(Clone, Debug, PartialEq)]
pub enum Origin {
    SharedLink,
    Autosave,
    Archive,
    Empty,
}

pub struct Restored {
    pub labels: LabelSet,
    pub origin: Origin,
    /// Problems worth telling the user (a damaged link, an unreadable autosave).
    pub warnings: Vec<String>,
    /// An autosave was set aside because a shared link brought other labels.
    pub displaced: bool,
}

/// The labels to start with: a shared link's (`link_labels`, the page's `#labels=` code), else
/// the autosave's, else the archive's, else none (with the scene's classes, or two generic ones).
pub fn initial_labels(scene: &Scene, source: &SceneSource, link_labels: Option<&str>) -> Restored {
    let frames = scene.frames.len() as u32;
    let mut warnings = Vec::new();
    let key = source.storage_key();
    let saved = match browser::storage_get(&key) {
        Ok(Some(text)) => {
            match Autosave::from_json(&text, "the saved annotations", frames, scene.width, scene.height) {
                Ok(save) => Some((text, save.labels)),
                Err(e) => {
                    warnings.push(format!("ignored saved annotations: {e}"));
                    None
                }
            }
        }
        Ok(None) => None,
        Err(e) => {
            warnings.push(format!("cannot read saved annotations: {e}"));
            None
        }
    };
    if let Some(code) = link_labels {
        match decode_labels(code).and_then(|l| {
            l.check("the link's annotations", frames)
                .map_err(|e| ShareError::Corrupt(e.to_string()))?;
            Ok(l)
        }) {
            Ok(labels) => {
                // The link's labels now live in the autosave; drop them from the address so a
                // reload keeps what is drawn from here on instead of going back to the link.
                let displaced = match &saved {
                    Some((text, old)) if *old != labels => browser::storage_set(&displaced_key(source), text).is_ok(),
                    _ => false,
                };
                if let Some(url) = source.url() {
                    browser::replace_fragment(&format!("scene={}", crate::labels::share::percent_encode(url)));
                }
                return Restored {
                    labels,
                    origin: Origin::SharedLink,
                    warnings,
                    displaced,
                };
            }
            Err(e) => warnings.push(format!("{e}; opening without them")),
        }
    }
    if let Some((_, labels)) = saved {
        return Restored {
            labels,
            origin: Origin::Autosave,
            warnings,
            displaced: false,
        };
    }
    if let Some(labels) = scene.labels.clone().filter(|l| !l.classes.is_empty()) {
        return Restored {
            labels,
            origin: Origin::Archive,
            warnings,
            displaced: false,
        };
    }
    let classes = if scene.classes.is_empty() {
        vec![
            ClassInfo {
                name: "class 1".into(),
                color: [230, 25, 75],
            },
            ClassInfo {
                name: "class 2".into(),
                color: [0, 130, 200],
            },
        ]
    } else {
        scene.classes.clone()
    };
    Restored {
        labels: LabelSet::new(classes),
        origin: Origin::Empty,
        warnings,
        displaced: false,
    }
}

/// The autosave that a shared link displaced, taken out of storage.
pub fn take_displaced(scene: &Scene, source: &SceneSource) -> Result<Option<LabelSet>, String> {
    let key = displaced_key(source);
    let text = browser::storage_get(&key).map_err(|e| e.to_string())?;
    let Some(text) = text else { return Ok(None) };
    let _ = browser::storage_remove(&key);
    Autosave::from_json(
        &text,
        "the annotations from before the link",
        scene.frames.len() as u32,
        scene.width,
        scene.height,
    )
    .map(|s| Some(s.labels))
    .map_err(|e| e.to_string())
}

/// Saves `labels` as the scene's autosave.
pub fn autosave(scene: &Scene, source: &SceneSource, labels: &LabelSet) -> Result<(), BrowserError> {
    let entry = Autosave::new(
        labels,
        scene.frames.len() as u32,
        scene.width,
        scene.height,
        browser::wall_clock_ms(),
    );
    browser::storage_set(&source.storage_key(), &entry.to_json())
}

/// A link that opens this scene with these labels.
pub fn share_link(source: &SceneSource, labels: &LabelSet) -> Result<String, ShareError> {
    let url = source.url().ok_or(ShareError::LocalScene)?;
    let fragment = share_fragment(&browser::absolute_url(url), labels)?;
    Ok(format!("{}#{fragment}", browser::page_address()))
}

/// File name for downloads of this scene: its archive name without `.scene.zip`.
pub fn download_stem(source: &SceneSource) -> String {
    let name = source.describe().rsplit('/').next().unwrap_or("scene");
    let name = name.split(['?', '#']).next().unwrap_or(name);
    let stem = name
        .strip_suffix(".scene.zip")
        .or_else(|| name.strip_suffix(".zip"))
        .unwrap_or(name);
    if stem.is_empty() { "scene".into() } else { stem.into() }
}
