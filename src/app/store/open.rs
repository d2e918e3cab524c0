//! Opening a scene's store before annotating starts: which tab writes, asking for persistent
//! storage, migrating the old local-storage saves, taking back a journal left by a page that
//! closed mid-write, reading the snapshots and setting aside those that cannot be read.
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

use super::idb::{self, Db};
use super::tab_lock::{self, Role};
use super::{Inner, SceneStore, legacy};
use crate::app::browser;
use crate::labels::LabelSet;
use crate::labels::autosave::{Autosave, SceneSource};
use crate::labels::snapshots::{
    KEEP_SNAPSHOTS, Migration, Reason, SNAPSHOT_FORMAT, SNAPSHOT_VERSION, SceneKey, SceneShape, SnapshotRecord,
    journal_is_newer, migration, text_mark,
};

/// A scene's store, opened, and what the user should hear about it.
pub struct Opened {
    pub store: SceneStore,
    /// The newest readable snapshot's labels.
    pub newest: Option<LabelSet>,
    /// Problems (an unreadable save set aside, a failed migration, no IndexedDB).
    pub warnings: Vec<String>,
    /// Plain news (migrated saves, another tab writing).
    pub infos: Vec<String>,
}

/// A fresh id per page load: a session's edits update its own newest snapshot.
fn session_id() -> String {
    format!(
        "{:x}-{:x}",
        browser::wall_clock_ms() as u64,
        (js_sys::Math::random() * 4_294_967_296.0) as u64
    )
}

/// Asks the browser not to evict this site's storage under pressure; `None` if it cannot say.
async fn ask_persistence() -> Option<bool> {
    let storage = web_sys::window()?.navigator().storage();
    let answer = JsFuture::from(storage.persist().ok()?).await.ok()?;
    answer.as_bool()
}

pub async fn open_scene(content_id: &str, source: &SceneSource, shape: SceneShape) -> Opened {
    let key = SceneKey::new(content_id);
    let mut warnings = Vec::new();
    let mut infos = Vec::new();
    let lock = tab_lock::claim(content_id).await;
    let persisted = ask_persistence().await;
    let (db, unavailable) = match idb::open().await {
        Ok(db) => (Some(db), None),
        Err(e) => {
            warnings.push(format!(
                "Annotations cannot be saved in this browser ({e}): export them to keep them."
            ));
            (None, Some(e.to_string()))
        }
    };
    let writer = lock.role.get() != Role::Follower;
    if lock.role.get() == Role::Follower {
        infos.push(
            "This scene is open in another tab, which saves it: this tab follows it read-only \
             (it takes over when that tab closes)."
                .into(),
        );
    }
    let mut aside = Vec::new();
    let mut records = Vec::new();
    // Over every key seen, readable or not: a new snapshot must never land on an unreadable
    // record that could not be set aside.
    let mut max_seq = None;
    let mut others = Vec::new();
    if let Some(db) = &db {
        if writer {
            migrate(db, &key, source, shape, &mut warnings, &mut infos, &mut aside).await;
            take_journal(db, &key, shape, &mut warnings, &mut aside).await;
        }
        (records, max_seq) = read_snapshots(db, &key, shape, writer, &mut warnings, &mut aside).await;
        aside = aside_keys(db, &key).await.unwrap_or(aside);
        if records.is_empty() {
            others = other_versions(db, &key, source, shape).await;
            if let Some(newest) = others.last() {
                infos.push(format!(
                    "Nothing is saved for this archive, but {} snapshot(s) are saved for another version of it at                      the same address (newest: {} strokes): the snapshots window can restore them.",
                    others.len(),
                    newest.meta().strokes
                ));
            }
        }
    }
    let newest = records.last().map(|r| r.autosave.labels.clone());
    let next_seq = max_seq.map_or(0, |s: u64| s + 1);
    let channel = web_sys::BroadcastChannel::new(&format!("scribblefield/{content_id}")).ok();
    let inner = Inner {
        db,
        unavailable,
        key,
        url: source.describe().to_string(),
        shape,
        session: session_id(),
        snapshots: records,
        others,
        next_seq,
        aside,
        wanted: None,
        written: None,
        in_flight: false,
        error: None,
        followed: None,
        takeover_warnings: Vec::new(),
        persisted,
        channel,
    };
    Opened {
        store: SceneStore::new(inner, lock),
        newest,
        warnings,
        infos,
    }
}

/// Where an unreadable entry now is, for the user.
fn aside_note(key: &str) -> String {
    format!(
        "kept unchanged in this browser's IndexedDB \"{}\", store \"{}\", key \"{key}\" (the snapshots \
         window downloads it)",
        idb::DB_NAME,
        idb::ASIDE
    )
}

fn new_record(
    key: &SceneKey,
    source: &SceneSource,
    shape: SceneShape,
    seq: u64,
    reason: Reason,
    labels: LabelSet,
    saved_at_ms: f64,
) -> SnapshotRecord {
    SnapshotRecord {
        format: SNAPSHOT_FORMAT.into(),
        version: SNAPSHOT_VERSION,
        content_id: key.content_id.clone(),
        url: source.describe().to_string(),
        seq,
        session: "migrated".into(),
        reason,
        created_ms: saved_at_ms,
        autosave: Autosave::new(&labels, shape.frames, shape.width, shape.height, saved_at_ms),
    }
}

/// The old build's local-storage entries become snapshots (or are copied aside); each is
/// marked as migrated and left where it was.
async fn migrate(
    db: &Db,
    key: &SceneKey,
    source: &SceneSource,
    shape: SceneShape,
    warnings: &mut Vec<String>,
    infos: &mut Vec<String>,
    aside: &mut Vec<String>,
) {
    let (lower, upper) = key.range();
    let mut next_seq = match db.entries(idb::SNAPSHOTS, &lower, &upper).await {
        Ok(entries) => entries
            .iter()
            .filter_map(|(k, _)| key.seq_of(k))
            .max()
            .map_or(0, |s| s + 1),
        Err(e) => {
            warnings.push(format!("Old saves not migrated: {e}"));
            return;
        }
    };
    for (legacy_key, before_link) in legacy::legacy_keys(source) {
        let text = legacy::get(&legacy_key);
        let mark_key = legacy::mark_key(&legacy_key);
        let done = match migration(text.as_deref(), legacy::get(&mark_key).as_deref(), &legacy_key, &shape) {
            Migration::Nothing => continue,
            Migration::Import { labels, saved_at_ms } => {
                let reason = if before_link {
                    Reason::MigratedBeforeLink
                } else {
                    Reason::Migrated
                };
                let record = new_record(key, source, shape, next_seq, reason, labels, saved_at_ms);
                let put = [(key.snapshot(next_seq), record.to_json())];
                db.write_snapshots(&put, &[]).await.map(|()| {
                    next_seq += 1;
                    infos.push(format!(
                        "Moved the annotations saved by an earlier version of this page into the snapshots \
                         (the old copy stays in local storage under \"{legacy_key}\")."
                    ));
                })
            }
            Migration::SetAside(why) => {
                let to = key.aside("local-storage", browser::wall_clock_ms());
                let value = JsValue::from_str(text.as_deref().unwrap_or_default());
                db.set_aside(&to, &value, None).await.map(|()| {
                    warnings.push(format!(
                        "Annotations saved by an earlier version of this page cannot be read ({why}); {}, and \
                         in local storage under \"{legacy_key}\".",
                        aside_note(&to)
                    ));
                    aside.push(to);
                })
            }
        };
        match done {
            // Marked only once the copy is on disk; the old entry itself stays.
            Ok(()) => {
                let _ = legacy::set(&mark_key, &text_mark(text.as_deref().unwrap_or_default()));
            }
            Err(e) => warnings.push(format!("Old saves not migrated (they stay in local storage): {e}")),
        }
    }
}

/// A journal left by a page that closed before its last write finished: stored if it is
/// newer than what the store has, then removed.
pub(super) async fn take_journal(
    db: &Db,
    key: &SceneKey,
    shape: SceneShape,
    warnings: &mut Vec<String>,
    aside: &mut Vec<String>,
) {
    let journal_key = key.journal();
    let Some(text) = legacy::get(&journal_key) else { return };
    let (lower, upper) = key.range();
    let stored: Vec<_> = match db.entries(idb::SNAPSHOTS, &lower, &upper).await {
        Ok(entries) => entries
            .iter()
            .filter_map(|(k, v)| SnapshotRecord::read(&v.as_string()?, k, &shape).ok())
            .map(|r| r.meta())
            .collect(),
        Err(e) => {
            warnings.push(format!("The last edits before the page closed are not back yet: {e}"));
            return;
        }
    };
    let done = match SnapshotRecord::read(&text, &journal_key, &shape) {
        Ok(record) if journal_is_newer(&record, &stored) => {
            db.write_snapshots(&[(key.snapshot(record.seq), text.clone())], &[])
                .await
        }
        Ok(_) => Ok(()),
        Err(why) => {
            let to = key.aside("journal", browser::wall_clock_ms());
            db.set_aside(&to, &JsValue::from_str(&text), None).await.map(|()| {
                warnings.push(format!(
                    "The copy saved as the page closed cannot be read ({why}); {}.",
                    aside_note(&to)
                ));
                aside.push(to);
            })
        }
    };
    match done {
        Ok(()) => legacy::remove(&journal_key),
        Err(e) => warnings.push(format!(
            "The last edits before the page closed are kept in local storage, not yet back: {e}"
        )),
    }
}

/// The scene's readable snapshots, oldest first. A writer moves unreadable ones aside (a
/// follower leaves that to the writer).
async fn read_snapshots(
    db: &Db,
    key: &SceneKey,
    shape: SceneShape,
    writer: bool,
    warnings: &mut Vec<String>,
    aside: &mut Vec<String>,
) -> (Vec<SnapshotRecord>, Option<u64>) {
    let (lower, upper) = key.range();
    let entries = match db.entries(idb::SNAPSHOTS, &lower, &upper).await {
        Ok(e) => e,
        Err(e) => {
            warnings.push(format!("Cannot read the saved annotations: {e}"));
            return (Vec::new(), None);
        }
    };
    let max_seq = entries.iter().filter_map(|(k, _)| key.seq_of(k)).max();
    let mut records = Vec::new();
    for (k, value) in entries {
        let read = match value.as_string() {
            Some(text) => SnapshotRecord::read(&text, &k, &shape).map_err(|e| e.0),
            None => Err(format!("{k}: not a text record")),
        };
        match read {
            Ok(r) => records.push(r),
            Err(why) if writer => {
                let to = key.aside(
                    &format!("snapshot-{}", key.seq_of(&k).unwrap_or(0)),
                    browser::wall_clock_ms(),
                );
                match db.set_aside(&to, &value, Some(&k)).await {
                    Ok(()) => {
                        warnings.push(format!(
                            "Saved annotations could not be read ({why}); {}.",
                            aside_note(&to)
                        ));
                        aside.push(to);
                    }
                    Err(e) => warnings.push(format!(
                        "Saved annotations could not be read ({why}) and could not be set aside ({e}); they stay \
                         under \"{k}\"."
                    )),
                }
            }
            Err(why) => warnings.push(format!("Saved annotations could not be read ({why}).")),
        }
    }
    (records, max_seq)
}

/// Snapshots of other content saved from the same address (the archive there has changed),
/// that still fit this scene: the URL is a hint, so they are offered, never applied.
async fn other_versions(db: &Db, key: &SceneKey, source: &SceneSource, shape: SceneShape) -> Vec<SnapshotRecord> {
    // Content ids are hex digits: every snapshot key lies in ["0", "g").
    let Ok(entries) = db.entries(idb::SNAPSHOTS, "0", "g").await else {
        return Vec::new();
    };
    let url = source.describe();
    let mut found: Vec<SnapshotRecord> = entries
        .iter()
        .filter(|(k, _)| !k.starts_with(&key.content_id))
        .filter_map(|(k, v)| SnapshotRecord::read(&v.as_string()?, k, &shape).ok())
        .filter(|r| r.url == url)
        .collect();
    found.sort_by(|a, b| a.autosave.saved_at_ms.total_cmp(&b.autosave.saved_at_ms));
    let excess = found.len().saturating_sub(KEEP_SNAPSHOTS);
    found.drain(..excess);
    found
}

async fn aside_keys(db: &Db, key: &SceneKey) -> Option<Vec<String>> {
    let (lower, upper) = key.range();
    let entries = db.entries(idb::ASIDE, &lower, &upper).await.ok()?;
    Some(entries.into_iter().map(|(k, _)| k).collect())
}
