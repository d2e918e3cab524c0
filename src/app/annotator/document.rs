//! The document being annotated: the scene, its labels and their undo history, the version that
//! every edit bumps, its store (where each version is saved), and the summary of what has been
//! labelled.
use std::rc::Rc;

use super::super::persistence;
use super::super::store::{SaveState, SceneStore};
use crate::labels::LabelSet;
use crate::labels::autosave::SceneSource;
use crate::labels::history::{Edit, EditError, History};
use crate::labels::snapshots::Reason;
use crate::labels::summary::SummaryCache;
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
    /// Bumped by every edit: textures, summary, saving and trainer follow it.
    pub version: u64,
    pub history: History,
    pub summary: Summary,
    /// Per-frame counts behind the summary: an edit re-rasterizes only its frame.
    counts: SummaryCache,
    pub store: SceneStore,
}

impl Document {
    pub fn new(scene: Rc<Scene>, source: SceneSource, labels: LabelSet, store: SceneStore) -> Document {
        Document {
            scene,
            source,
            labels,
            version: 1,
            history: History::new(),
            summary: Summary::default(),
            counts: SummaryCache::default(),
            store,
        }
    }

    /// Shows labels another tab saved (this tab follows it): they replace the document, and
    /// the undo history, which was about the labels replaced, starts again.
    pub fn follow(&mut self, labels: LabelSet) {
        self.labels = labels;
        self.history = History::new();
        self.version += 1;
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

    /// Saves the labels as they are now; `reason` starts a new snapshot when it is not plain
    /// edits. The write is asynchronous: [`Document::save_state`] says how it went.
    pub fn save(&mut self, reason: Reason) {
        self.store.save(self.version, &self.labels, reason);
    }

    pub fn save_state(&self) -> SaveState {
        self.store.state(self.version)
    }

    /// The latest edit is on disk.
    pub fn saved(&self) -> bool {
        self.save_state() == SaveState::Saved
    }

    /// Makes [`Document::summary`] describe the current labels.
    pub fn refresh_summary(&mut self) {
        if self.summary.version == self.version {
            return;
        }
        let (w, h) = (self.scene.width, self.scene.height);
        self.counts.update(&self.labels, w, h);
        let per_frame = self.counts.labelled_pixels_per_frame();
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
            classes_used: self.counts.classes_used(self.labels.classes.len()),
        };
    }

    /// The annotations file, for download.
    pub fn labels_file(&self) -> (String, Vec<u8>) {
        let name = format!("{}-labels.json", persistence::download_stem(&self.source));
        (name, self.labels.to_json().into_bytes())
    }
}
