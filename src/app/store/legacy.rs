//! Local storage, as the store uses it: the old build's saves (one entry per scene URL, and
//! its single "before the link" slot), migrated once and never removed; and the journal, an
//! emergency copy written synchronously as the page is hidden or closed, when an IndexedDB
//! write could still be under way and might not finish.
use super::super::browser;
use crate::labels::autosave::SceneSource;

/// The old build's keys for this scene: its main entry and the "before the link" slot, oldest
/// first (so that migrated, the main entry becomes the newer snapshot).
pub fn legacy_keys(source: &SceneSource) -> [(String, bool); 2] {
    let main = source.storage_key();
    [(format!("{main}#before-link"), true), (main, false)]
}

/// The mark left once `key` has been migrated (see `snapshots::text_mark`).
pub fn mark_key(key: &str) -> String {
    format!("scribblefield/migrated/{key}")
}

pub fn get(key: &str) -> Option<String> {
    browser::storage_get(key).ok().flatten()
}

/// Writes `value`; false when local storage refuses (full, or absent).
pub fn set(key: &str, value: &str) -> bool {
    browser::storage_set(key, value).is_ok()
}

pub fn remove(key: &str) {
    let _ = browser::storage_remove(key);
}
