//! The page's durable store of annotations, as plain logic (the browser plumbing is in
//! `app::store`): each scene, keyed by its archive's content id, keeps its last
//! [`KEEP_SNAPSHOTS`] snapshots; a record that cannot be read is set aside under a key of its
//! own; saves of the old build (local storage, keyed by URL) are migrated once.
//!
//! A snapshot is not one per edit: the edits of one page session update the newest snapshot in
//! place for [`SNAPSHOT_EVERY_MS`], then a new one starts; opening a share link, restoring,
//! importing and migrating always start a new one, so the version they replace stays listed.
use serde::{Deserialize, Serialize};

use super::LabelSet;
use super::autosave::Autosave;

/// Snapshots kept per scene; older ones are deleted as new ones are made.
pub const KEEP_SNAPSHOTS: usize = 20;
/// A session's edits keep updating one snapshot for this long before a new one starts.
pub const SNAPSHOT_EVERY_MS: f64 = 5.0 * 60_000.0;
pub const SNAPSHOT_FORMAT: &str = "scribblefield-snapshot";
pub const SNAPSHOT_VERSION: u32 = 1;

/// Why a snapshot was started.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Reason {
    /// Drawing, undoing, renaming...
    Edits,
    /// The labels a share link brought.
    Link,
    /// An older snapshot brought back.
    Restored,
    /// A labels file imported.
    Imported,
    /// Moved over from the old build's local storage.
    Migrated,
    /// The old build's single "before the link" slot.
    MigratedBeforeLink,
    /// Another tab's labels, taken over when this tab became the writer.
    TakenOver,
}

impl Reason {
    /// For the snapshots window.
    pub fn describe(self) -> &'static str {
        match self {
            Reason::Edits => "edits",
            Reason::Link => "opened from a link",
            Reason::Restored => "restored",
            Reason::Imported => "imported file",
            Reason::Migrated => "from the old local storage",
            Reason::MigratedBeforeLink => "from before a link (old storage)",
            Reason::TakenOver => "taken over from another tab",
        }
    }
}

/// Keys of one scene's records: `<content id>/<seq, 12 digits>`, so that string order is
/// time order and one key range holds the scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneKey {
    pub content_id: String,
}

impl SceneKey {
    pub fn new(content_id: &str) -> SceneKey {
        SceneKey {
            content_id: content_id.to_string(),
        }
    }

    pub fn snapshot(&self, seq: u64) -> String {
        format!("{}/{seq:012}", self.content_id)
    }

    /// `[lower, upper)` of this scene's keys ('0' follows '/').
    pub fn range(&self) -> (String, String) {
        (format!("{}/", self.content_id), format!("{}0", self.content_id))
    }

    /// The sequence number in one of this scene's keys.
    pub fn seq_of(&self, key: &str) -> Option<u64> {
        key.strip_prefix(&self.content_id)?.strip_prefix('/')?.parse().ok()
    }

    /// Where an unreadable record (or legacy entry) is set aside: unique per moment and
    /// origin, and written with "add", which fails rather than overwrite.
    pub fn aside(&self, origin: &str, now_ms: f64) -> String {
        format!("{}/{origin}/aside-{}", self.content_id, now_ms as u64)
    }

    /// The local-storage key of the emergency copy written as the page is hidden or closed.
    pub fn journal(&self) -> String {
        format!("scribblefield/journal/{}", self.content_id)
    }
}

/// One stored snapshot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SnapshotRecord {
    pub format: String,
    pub version: u32,
    pub content_id: String,
    /// Where the scene was opened from: a hint for people, not part of the key.
    pub url: String,
    pub seq: u64,
    /// The page session that wrote it (one per page load).
    pub session: String,
    pub reason: Reason,
    /// When the snapshot was started (Unix ms); `autosave.saved_at_ms` is its latest write.
    pub created_ms: f64,
    pub autosave: Autosave,
}

/// What the snapshots window and the save plan need of a record.
#[derive(Clone, Debug, PartialEq)]
pub struct SnapshotMeta {
    pub seq: u64,
    pub session: String,
    pub reason: Reason,
    pub created_ms: f64,
    pub saved_ms: f64,
    pub strokes: usize,
}

pub fn stroke_count(labels: &LabelSet) -> usize {
    labels.frames.iter().map(|f| f.strokes.len()).sum()
}

impl SnapshotRecord {
    pub fn meta(&self) -> SnapshotMeta {
        SnapshotMeta {
            seq: self.seq,
            session: self.session.clone(),
            reason: self.reason,
            created_ms: self.created_ms,
            saved_ms: self.autosave.saved_at_ms,
            strokes: stroke_count(&self.autosave.labels),
        }
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("snapshots always serialize")
    }

    /// Reads a stored record for this scene (`frames` of `width x height`); any problem
    /// (damaged JSON, a format this build does not read, another scene's labels) is
    /// [`Unreadable`], and the caller sets the record aside.
    pub fn read(text: &str, key: &str, scene: &SceneShape) -> Result<SnapshotRecord, Unreadable> {
        let record: SnapshotRecord = serde_json::from_str(text).map_err(|e| Unreadable(format!("{key}: {e}")))?;
        if record.format != SNAPSHOT_FORMAT || record.version != SNAPSHOT_VERSION {
            return Err(Unreadable(format!(
                "{key}: {} version {} is not a snapshot this build reads",
                record.format, record.version
            )));
        }
        // Re-checks the labels against the scene as an autosave would be.
        let autosave = Autosave::from_json(&record.autosave.to_json(), key, scene.frames, scene.width, scene.height)
            .map_err(|e| Unreadable(e.to_string()))?;
        Ok(SnapshotRecord { autosave, ..record })
    }
}

/// A stored entry this build cannot use, with why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct Unreadable(pub String);

/// The scene's frame count and size, which saved labels must fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneShape {
    pub frames: u32,
    pub width: u32,
    pub height: u32,
}

/// Where the next save goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Slot {
    /// Rewrite the newest snapshot (same session, plain edits, recent).
    Update(u64),
    /// Start snapshot `seq`.
    New(u64),
}

/// Where a save made for `reason` by `session` at `now_ms` goes, given the scene's newest
/// snapshot and the next free sequence number.
pub fn plan_save(newest: Option<&SnapshotMeta>, session: &str, reason: Reason, now_ms: f64, next_seq: u64) -> Slot {
    match newest {
        Some(n)
            if reason == Reason::Edits
                && n.reason == Reason::Edits
                && n.session == session
                && now_ms - n.created_ms < SNAPSHOT_EVERY_MS =>
        {
            Slot::Update(n.seq)
        }
        _ => Slot::New(next_seq),
    }
}

/// The snapshots to delete so that `keep` remain: the oldest (lowest sequence numbers).
pub fn to_drop(seqs: &[u64], keep: usize) -> Vec<u64> {
    let mut sorted = seqs.to_vec();
    sorted.sort_unstable();
    let excess = sorted.len().saturating_sub(keep);
    sorted.truncate(excess);
    sorted
}

/// The labels to start annotating with, by priority.
#[derive(Clone, Debug, PartialEq)]
pub enum Start {
    /// The share link's labels (saved at once as a new snapshot).
    Link,
    /// The newest readable snapshot.
    Snapshot,
    /// The archive's own labels.
    Archive,
    Empty,
}

pub fn choose_start(link: bool, snapshot: bool, archive_has_labels: bool) -> Start {
    match (link, snapshot, archive_has_labels) {
        (true, _, _) => Start::Link,
        (false, true, _) => Start::Snapshot,
        (false, false, true) => Start::Archive,
        _ => Start::Empty,
    }
}

/// A short, stable fingerprint of a text (FNV-1a 64, hex): marks which legacy entry was
/// migrated, so that an entry an old build rewrites later is migrated again.
pub fn text_mark(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in text.as_bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// What to do with an old local-storage entry.
#[derive(Clone, Debug, PartialEq)]
pub enum Migration {
    /// Nothing there, or already migrated as it is now.
    Nothing,
    /// Make a snapshot of these labels (saved at that time).
    Import { labels: LabelSet, saved_at_ms: f64 },
    /// Unreadable: copy it aside as it is, with why.
    SetAside(Unreadable),
}

/// The decision for a legacy entry's text (`None`: absent) given the mark left by an earlier
/// migration. The legacy entry itself is never removed.
pub fn migration(legacy: Option<&str>, mark: Option<&str>, key: &str, scene: &SceneShape) -> Migration {
    let Some(text) = legacy else { return Migration::Nothing };
    if mark == Some(text_mark(text).as_str()) {
        return Migration::Nothing;
    }
    match Autosave::from_json(text, key, scene.frames, scene.width, scene.height) {
        Ok(save) => Migration::Import {
            labels: save.labels,
            saved_at_ms: save.saved_at_ms,
        },
        Err(e) => Migration::SetAside(Unreadable(e.to_string())),
    }
}

/// Whether the emergency copy written as the page closed holds a later save than the store's
/// record of the same snapshot (absent there: it is later).
pub fn journal_is_newer(journal: &SnapshotRecord, stored: &[SnapshotMeta]) -> bool {
    stored
        .iter()
        .find(|m| m.seq == journal.seq)
        .is_none_or(|m| m.saved_ms < journal.autosave.saved_at_ms)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, Stroke};

    const SHAPE: SceneShape = SceneShape {
        frames: 10,
        width: 160,
        height: 120,
    };

    fn labels(strokes: usize) -> LabelSet {
        let mut l = LabelSet::new(vec![ClassInfo {
            name: "a".into(),
            color: [1, 2, 3],
        }]);
        for i in 0..strokes {
            l.push_stroke(
                (i % 10) as u32,
                Stroke {
                    class: Some(0),
                    radius: 2.0,
                    points: vec![[1.0, 1.0]],
                },
            );
        }
        l
    }

    fn record(seq: u64, strokes: usize, saved: f64) -> SnapshotRecord {
        SnapshotRecord {
            format: SNAPSHOT_FORMAT.into(),
            version: SNAPSHOT_VERSION,
            content_id: "c".into(),
            url: "https://h/a.scene.zip".into(),
            seq,
            session: "s1".into(),
            reason: Reason::Edits,
            created_ms: 1000.0,
            autosave: Autosave::new(&labels(strokes), 10, 160, 120, saved),
        }
    }

    fn meta(seq: u64, session: &str, reason: Reason, created_ms: f64) -> SnapshotMeta {
        SnapshotMeta {
            seq,
            session: session.into(),
            reason,
            created_ms,
            saved_ms: created_ms,
            strokes: 1,
        }
    }

    #[test]
    fn keys_sort_by_time_and_stay_in_their_scene() {
        let k = SceneKey::new("abc");
        assert!(k.snapshot(9) < k.snapshot(10));
        let (lo, hi) = k.range();
        assert!(lo.as_str() <= k.snapshot(0).as_str() && k.snapshot(u64::MAX / 1000).as_str() < hi.as_str());
        assert!(!(lo.as_str() <= "abcd/000000000001" && "abcd/000000000001" < hi.as_str()));
        assert_eq!(k.seq_of(&k.snapshot(42)), Some(42));
        assert_eq!(k.seq_of("abcd/000000000042"), None);
        assert_eq!(k.seq_of(&k.aside("snapshot-3", 5.0)), None);
        assert_ne!(k.aside("a", 1.0), k.aside("a", 2.0));
    }

    #[test]
    fn records_round_trip_and_unreadable_ones_say_why() {
        let r = record(3, 2, 5.0);
        let back = SnapshotRecord::read(&r.to_json(), "k", &SHAPE).unwrap();
        assert_eq!(back, r);
        assert_eq!(back.meta().strokes, 2);
        let e = SnapshotRecord::read("{garbage", "k", &SHAPE).unwrap_err();
        assert!(e.0.starts_with("k:"), "{e}");
        let mut future = r.clone();
        future.version = 99;
        let e = SnapshotRecord::read(&future.to_json(), "k", &SHAPE).unwrap_err();
        assert!(e.0.contains("version 99"), "{e}");
        let other = SceneShape { frames: 5, ..SHAPE };
        assert!(SnapshotRecord::read(&r.to_json(), "k", &other).is_err());
    }

    #[test]
    fn a_session_updates_its_snapshot_then_starts_another() {
        let n = meta(4, "s1", Reason::Edits, 0.0);
        assert_eq!(plan_save(Some(&n), "s1", Reason::Edits, 1000.0, 5), Slot::Update(4));
        // A new page load, an old snapshot, or a milestone starts a new one.
        assert_eq!(plan_save(Some(&n), "s2", Reason::Edits, 1000.0, 5), Slot::New(5));
        assert_eq!(
            plan_save(Some(&n), "s1", Reason::Edits, SNAPSHOT_EVERY_MS, 5),
            Slot::New(5)
        );
        assert_eq!(plan_save(Some(&n), "s1", Reason::Restored, 1000.0, 5), Slot::New(5));
        // The link's snapshot is never rewritten by the edits after it.
        let link = meta(4, "s1", Reason::Link, 0.0);
        assert_eq!(plan_save(Some(&link), "s1", Reason::Edits, 1.0, 5), Slot::New(5));
        assert_eq!(plan_save(None, "s1", Reason::Edits, 1.0, 0), Slot::New(0));
    }

    #[test]
    fn the_ring_keeps_the_newest() {
        assert_eq!(to_drop(&[5, 1, 3, 2, 4], 3), vec![1, 2]);
        assert!(to_drop(&[1, 2], 3).is_empty());
        let many: Vec<u64> = (0..25).collect();
        assert_eq!(to_drop(&many, KEEP_SNAPSHOTS), vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn a_link_comes_first_then_the_newest_snapshot() {
        assert_eq!(choose_start(true, true, true), Start::Link);
        assert_eq!(choose_start(false, true, true), Start::Snapshot);
        assert_eq!(choose_start(false, false, true), Start::Archive);
        assert_eq!(choose_start(false, false, false), Start::Empty);
    }

    #[test]
    fn legacy_entries_migrate_once_and_bad_ones_go_aside() {
        let text = Autosave::new(&labels(2), 10, 160, 120, 7.0).to_json();
        match migration(Some(&text), None, "k", &SHAPE) {
            Migration::Import { labels, saved_at_ms } => {
                assert_eq!(stroke_count(&labels), 2);
                assert_eq!(saved_at_ms, 7.0);
            }
            other => panic!("{other:?}"),
        }
        let mark = text_mark(&text);
        assert_eq!(migration(Some(&text), Some(&mark), "k", &SHAPE), Migration::Nothing);
        // Rewritten by an old build after the migration: migrated again.
        let later = Autosave::new(&labels(3), 10, 160, 120, 8.0).to_json();
        assert!(matches!(
            migration(Some(&later), Some(&mark), "k", &SHAPE),
            Migration::Import { .. }
        ));
        assert!(matches!(
            migration(Some("{nope"), None, "k", &SHAPE),
            Migration::SetAside(_)
        ));
        assert_eq!(migration(None, None, "k", &SHAPE), Migration::Nothing);
    }

    #[test]
    fn a_journal_counts_only_when_later_than_the_store() {
        let j = record(3, 2, 50.0);
        assert!(journal_is_newer(&j, &[]));
        let mut stored = j.meta();
        stored.saved_ms = 40.0;
        assert!(journal_is_newer(&j, std::slice::from_ref(&stored)));
        stored.saved_ms = 50.0;
        assert!(!journal_is_newer(&j, &[stored]));
    }
}
