//! Which labels a scene starts with, share links, and download names. (Saving is
//! `app::store`.)
use super::browser;
use crate::labels::autosave::SceneSource;
use crate::labels::share::{ShareError, decode_labels, share_fragment};
use crate::labels::snapshots::{Start, choose_start};
use crate::labels::{ClassInfo, LabelSet};
use crate::scene::Scene;

/// Where the labels the annotator starts with came from.
#[derive(Clone, Debug, PartialEq)]
pub enum Origin {
    SharedLink,
    Snapshot,
    Archive,
    Empty,
}

pub struct Restored {
    pub labels: LabelSet,
    pub origin: Origin,
    /// Problems worth telling the user (a damaged link).
    pub warnings: Vec<String>,
}

/// The labels to start with: a shared link's (`link_labels`, the page's `#labels=` code), else
/// the newest saved snapshot's (`newest`), else the archive's, else none (with the scene's
/// classes, or two generic ones). The saved ones are not replaced: a link's labels are saved
/// as a new snapshot, so what they displace stays among the snapshots.
pub fn initial_labels(
    scene: &Scene,
    source: &SceneSource,
    link_labels: Option<&str>,
    newest: Option<LabelSet>,
) -> Restored {
    let frames = scene.frames.len() as u32;
    let mut warnings = Vec::new();
    let link = link_labels.and_then(|code| {
        match decode_labels(code).and_then(|l| {
            l.check("the link's annotations", frames)
                .map_err(|e| ShareError::Corrupt(e.to_string()))?;
            Ok(l)
        }) {
            Ok(labels) => Some(labels),
            Err(e) => {
                warnings.push(format!("{e}; opening without them"));
                None
            }
        }
    });
    let archive = scene.labels.clone().filter(|l| !l.classes.is_empty());
    let start = choose_start(link.is_some(), newest.is_some(), archive.is_some());
    let (labels, origin) = match (start, link, newest, archive) {
        (Start::Link, Some(labels), _, _) => {
            // The link's labels are saved at once; drop them from the address so a reload
            // keeps what is drawn from here on instead of going back to the link.
            if let Some(url) = source.url() {
                browser::replace_fragment(&format!("scene={}", crate::labels::share::percent_encode(url)));
            }
            (labels, Origin::SharedLink)
        }
        (Start::Snapshot, _, Some(labels), _) => (labels, Origin::Snapshot),
        (Start::Archive, _, _, Some(labels)) => (labels, Origin::Archive),
        _ => (LabelSet::new(default_classes(scene)), Origin::Empty),
    };
    Restored {
        labels,
        origin,
        warnings,
    }
}

fn default_classes(scene: &Scene) -> Vec<ClassInfo> {
    if !scene.classes.is_empty() {
        return scene.classes.clone();
    }
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
