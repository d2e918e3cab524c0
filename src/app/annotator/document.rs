//! The document being annotated: the scene, its labels and their undo history, the version that
//! every edit bumps, the autosave, and the summary of what has been labelled.
use std::rc::Rc;

use super::super::persistence;
use crate::labels::LabelSet;
use crate::labels::autosave::SceneSource;
use crate::labels::history::{Edit, EditError, History};
use crate::labels::summary::{classes_used, labelled_pixels_per_frame};
use crate::scene::Scene;

/// What has been annotated, recomputed when the labels change.
#[derive(Default)]
pub struct Summary {
    version: u64,
    pub strokes: usize,
    pub labelled_pixels: u64,
    pub labelled_frames: Vec<bool>,
    pub classes_used: Vec<bool>,
}

pub struct Document {
    pub scene: Rc<Scene>,
    pub source: SceneSource,
    pub labels: LabelSet,
    /// Bumped by every edit: textures, summary, autosave and trainer follow it.
    pub version: u64,
    pub history: History,
    pub summary: Summary,
    autosaved_version: Option<u64>,
    autosave_error: Option<String>,
    /// An autosave that a shared link replaced, which the user may want back.
    pub displaced: bool,
}

impl Document {
    pub fn new(scene: Rc<Scene>, source: SceneSource, labels: LabelSet, displaced: bool) -> Document {
        Document {
            scene,
            source,
            labels,
            version: 1,
            history: History::new(),
            summary: Summary::default(),
            autosaved_version: None,
            autosave_error: None,
            displaced,
        }
    }

    pub fn frame_count(&self) -> usize {
        self.scene.frames.len()
    }

    /// Applies an edit (merged into the previous one when `merge`, as for a colour being
    /// dragged) and bumps the version.
    pub fn apply(&mut self, edit: Edit, merge: bool) -> Result<(), EditError> {
        if merge {
            self.history.apply_merging(&mut self.labels, edit)?;
        } else {
            self.history.apply(&mut self.labels, edit)?;
        }
        self.version += 1;
        Ok(())
    }

    /// Undoes the latest edit; `Some(frame it touched, if one)` when there was one.
    pub fn undo(&mut self) -> Result<Option<Option<u32>>, EditError> {
        let frame = self.history.undo(&mut self.labels)?.map(|edit| edit.frame());
        if frame.is_some() {
            self.version += 1;
        }
        Ok(frame)
    }

    /// Redoes the latest undone edit, as [`Document::undo`].
    pub fn redo(&mut self) -> Result<Option<Option<u32>>, EditError> {
        let frame = self.history.redo(&mut self.labels)?.map(|edit| edit.frame());
        if frame.is_some() {
            self.version += 1;
        }
        Ok(frame)
    }

    /// Writes the autosave (each edit is one small write: strokes are whole, not per move).
    /// On failure, the message to tell the user, the first time in a row only.
    pub fn save(&mut self) -> Option<String> {
        match persistence::autosave(&self.scene, &self.source, &self.labels) {
            Ok(()) => {
                self.autosaved_version = Some(self.version);
                self.autosave_error = None;
                None
            }
            Err(e) => {
                let first = self.autosave_error.is_none();
                self.autosave_error = Some(e.to_string());
                first.then(|| format!("Cannot autosave the annotations ({e}); export them to keep them."))
            }
        }
    }

    /// The autosave holds the latest edit.
    pub fn saved(&self) -> bool {
        self.autosaved_version == Some(self.version)
    }

    /// The autosave that a shared link displaced, taken out of storage.
    pub fn take_displaced(&mut self) -> Result<Option<LabelSet>, String> {
        self.displaced = false;
        persistence::take_displaced(&self.scene, &self.source)
    }

    /// Makes [`Document::summary`] describe the current labels.
    pub fn refresh_summary(&mut self) {
        if self.summary.version == self.version {
            return;
        }
        let (w, h) = (self.scene.width, self.scene.height);
        let per_frame = labelled_pixels_per_frame(&self.labels, w, h);
        let mut labelled_frames = vec![false; self.scene.frames.len()];
        for &(f, n) in &per_frame {
            if let Some(slot) = labelled_frames.get_mut(f as usize) {
                *slot = n > 0;
            }
        }
        self.summary = Summary {
            version: self.version,
            strokes: self.labels.frames.iter().map(|f| f.strokes.len()).sum(),
            labelled_pixels: per_frame.iter().map(|p| p.1).sum(),
            labelled_frames,
            classes_used: classes_used(&self.labels, w, h),
        };
    }

    /// The annotations file, for download.
    pub fn labels_file(&self) -> (String, Vec<u8>) {
        let name = format!("{}-labels.json", persistence::download_stem(&self.source));
        (name, self.labels.to_json().into_bytes())
    }
}
