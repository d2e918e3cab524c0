//! Where the page keeps annotations: IndexedDB (`idb`), keyed by the scene archive's content
//! id, the last `KEEP_SNAPSHOTS` snapshots per scene, unreadable records set aside, one
//! writing tab per scene (`tab_lock`), the old local-storage saves migrated and an emergency
//! journal written as the page is hidden (`legacy`). `open` reads a scene's store before the
//! annotator starts; [`SceneStore`] then saves each edit and tells the page where saving
//! stands. The decisions themselves (keys, ring, save plan, migration) are plain logic in
//! `crate::labels::snapshots`, tested natively.
mod idb;
mod legacy;
mod open;
mod tab_lock;

use std::cell::RefCell;
use std::rc::{Rc, Weak};

use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;

pub use self::open::{Opened, open_scene};
use self::tab_lock::{Role, TabLock};
use super::browser;
use crate::labels::LabelSet;
use crate::labels::autosave::Autosave;
use crate::labels::snapshots::{
    KEEP_SNAPSHOTS, Reason, SNAPSHOT_FORMAT, SNAPSHOT_VERSION, SceneKey, SceneShape, Slot, SnapshotMeta,
    SnapshotRecord, plan_save, to_drop,
};

/// A failed store operation, with what was being done.
#[derive(Debug, Clone, thiserror::Error)]
pub enum StoreError {
    #[error("IndexedDB is not available ({0})")]
    Unavailable(String),
    #[error("{what}: {detail}")]
    Failed { what: String, detail: String },
}

/// Where saving stands, for the panel, the page status and the device-lost notice. Only
/// `Saved` may be worded as "saved".
#[derive(Clone, Debug, PartialEq)]
pub enum SaveState {
    /// The latest edit is on disk.
    Saved,
    /// A write is under way.
    Saving,
    /// The latest write failed (quota...): the latest edits are NOT saved.
    Failed(String),
    /// Another tab saves this scene; this one follows it and does not save.
    ReadOnly,
    /// There is no IndexedDB here: nothing is saved.
    Unavailable(String),
}

impl SaveState {
    /// For the page status (`save.state`).
    pub fn name(&self) -> &'static str {
        match self {
            SaveState::Saved => "saved",
            SaveState::Saving => "saving",
            SaveState::Failed(_) => "failed",
            SaveState::ReadOnly => "read_only",
            SaveState::Unavailable(_) => "unavailable",
        }
    }

    pub fn error(&self) -> Option<&str> {
        match self {
            SaveState::Failed(e) | SaveState::Unavailable(e) => Some(e),
            _ => None,
        }
    }
}

/// The labels the page wants on disk.
struct Wanted {
    version: u64,
    labels: LabelSet,
    reason: Reason,
}

struct Inner {
    db: Option<idb::Db>,
    /// Why `db` is `None`.
    unavailable: Option<String>,
    key: SceneKey,
    url: String,
    shape: SceneShape,
    session: String,
    /// The scene's readable snapshots, oldest first.
    snapshots: Vec<SnapshotRecord>,
    /// When the scene has none: snapshots of another archive once at the same URL that fit
    /// this scene, oldest first (offered in the snapshots window, never applied unasked).
    others: Vec<SnapshotRecord>,
    next_seq: u64,
    /// Keys in the `aside` store that belong to this scene.
    aside: Vec<String>,
    wanted: Option<Wanted>,
    /// The document version on disk.
    written: Option<u64>,
    in_flight: bool,
    /// The latest write's failure, until a write succeeds.
    error: Option<String>,
    /// The writer's newest labels, for a follower to show (taken by the annotator).
    followed: Option<LabelSet>,
    /// Problems met while taking over from a closed writer, for the annotator to show.
    takeover_warnings: Vec<String>,
    /// Whether the browser granted persistent storage (`None`: not answered).
    persisted: Option<bool>,
    channel: Option<web_sys::BroadcastChannel>,
}

impl Inner {
    /// The record `w` would be written as now, and the snapshots that writing it drops.
    fn record_for(&self, w: &Wanted, now_ms: f64) -> (SnapshotRecord, Vec<u64>) {
        let newest = self.snapshots.last().map(SnapshotRecord::meta);
        let (seq, created_ms) = match plan_save(newest.as_ref(), &self.session, w.reason, now_ms, self.next_seq) {
            Slot::Update(seq) => (seq, newest.map_or(now_ms, |n| n.created_ms)),
            Slot::New(seq) => (seq, now_ms),
        };
        let mut seqs: Vec<u64> = self.snapshots.iter().map(|r| r.seq).filter(|&s| s != seq).collect();
        seqs.push(seq);
        let record = SnapshotRecord {
            format: SNAPSHOT_FORMAT.into(),
            version: SNAPSHOT_VERSION,
            content_id: self.key.content_id.clone(),
            url: self.url.clone(),
            seq,
            session: self.session.clone(),
            reason: w.reason,
            created_ms,
            autosave: Autosave::new(
                &w.labels,
                self.shape.frames,
                self.shape.width,
                self.shape.height,
                now_ms,
            ),
        };
        (record, to_drop(&seqs, KEEP_SNAPSHOTS))
    }

    /// Takes a written (or read) record into the list.
    fn keep(&mut self, record: SnapshotRecord, dropped: &[u64]) {
        self.next_seq = self.next_seq.max(record.seq + 1);
        self.snapshots
            .retain(|r| r.seq != record.seq && !dropped.contains(&r.seq));
        self.snapshots.push(record);
        self.snapshots.sort_by_key(|r| r.seq);
    }

    fn dirty(&self) -> bool {
        self.wanted.as_ref().is_some_and(|w| Some(w.version) != self.written)
    }
}

/// Removes the page listeners when the store goes.
struct Listeners {
    hide: Closure<dyn FnMut()>,
}

impl Drop for Listeners {
    fn drop(&mut self) {
        let f = self.hide.as_ref().unchecked_ref();
        if let Some(w) = web_sys::window() {
            let _ = w.remove_event_listener_with_callback("pagehide", f);
            if let Some(d) = w.document() {
                let _ = d.remove_event_listener_with_callback("visibilitychange", f);
            }
        }
    }
}

/// One scene's store, for as long as the scene is open.
pub struct SceneStore {
    inner: Rc<RefCell<Inner>>,
    lock: TabLock,
    _listeners: Option<Listeners>,
}

impl SceneStore {
    fn new(inner: Inner, lock: TabLock) -> SceneStore {
        let inner = Rc::new(RefCell::new(inner));
        let listeners = listen_for_hiding(Rc::downgrade(&inner));
        let store = SceneStore {
            inner,
            lock,
            _listeners: listeners,
        };
        store.listen_to_writer();
        store
    }

    pub fn content_id(&self) -> String {
        self.inner.borrow().key.content_id.clone()
    }

    /// Whether this tab may edit (it is the writer, or nobody coordinates tabs).
    pub fn writable(&self) -> bool {
        self.lock.role.get() != Role::Follower
    }

    /// Saves `labels` (the document at `version`) as soon as it can; `reason` says why a new
    /// snapshot should start (see `snapshots::plan_save`).
    pub fn save(&self, version: u64, labels: &LabelSet, reason: Reason) {
        if !self.writable() {
            return;
        }
        let mut i = self.inner.borrow_mut();
        // A milestone not yet on disk keeps its reason when plain edits follow it at once, so
        // a share link's labels still get their own snapshot.
        let reason = match &i.wanted {
            Some(w) if reason == Reason::Edits && Some(w.version) != i.written && w.reason != Reason::Edits => w.reason,
            _ => reason,
        };
        i.wanted = Some(Wanted {
            version,
            labels: labels.clone(),
            reason,
        });
        drop(i);
        kick(&self.inner);
    }

    /// Where saving stands for the document at `version`.
    pub fn state(&self, version: u64) -> SaveState {
        let i = self.inner.borrow();
        if !self.writable() {
            return SaveState::ReadOnly;
        }
        if let Some(e) = &i.unavailable {
            return SaveState::Unavailable(e.clone());
        }
        if let Some(e) = &i.error {
            return SaveState::Failed(e.clone());
        }
        match &i.wanted {
            Some(w) if w.version == version && i.written == Some(version) => SaveState::Saved,
            // Nothing asked for since the page opened on what is already stored.
            None => SaveState::Saved,
            _ => SaveState::Saving,
        }
    }

    pub fn snapshots(&self) -> Vec<SnapshotMeta> {
        self.inner.borrow().snapshots.iter().map(SnapshotRecord::meta).collect()
    }

    /// Snapshots of another version of the archive at the same URL: (content id, meta).
    pub fn others(&self) -> Vec<(String, SnapshotMeta)> {
        let i = self.inner.borrow();
        i.others.iter().map(|r| (r.content_id.clone(), r.meta())).collect()
    }

    pub fn other_labels(&self, content_id: &str, seq: u64) -> Option<LabelSet> {
        let i = self.inner.borrow();
        i.others
            .iter()
            .find(|r| r.content_id == content_id && r.seq == seq)
            .map(|r| r.autosave.labels.clone())
    }

    pub fn snapshot_labels(&self, seq: u64) -> Option<LabelSet> {
        let i = self.inner.borrow();
        i.snapshots
            .iter()
            .find(|r| r.seq == seq)
            .map(|r| r.autosave.labels.clone())
    }

    /// Keys of this scene's set-aside records (in IndexedDB `scribblefield`, store `aside`).
    pub fn aside(&self) -> Vec<String> {
        self.inner.borrow().aside.clone()
    }

    pub fn persisted(&self) -> Option<bool> {
        self.inner.borrow().persisted
    }

    /// The writer's newest labels, when a follower has new ones to show.
    pub fn take_followed(&self) -> Option<LabelSet> {
        self.inner.borrow_mut().followed.take()
    }

    /// Called every frame: a follower that has just been granted the lock takes back the
    /// journal the writer left as it closed (edits its last write did not get to disk), reads
    /// what the writer saved, then becomes the writer.
    pub fn poll(&self) {
        if self.lock.granted.replace(false) {
            let inner = self.inner.clone();
            let role = self.lock.role.clone();
            wasm_bindgen_futures::spawn_local(async move {
                take_writers_journal(&inner).await;
                refresh(&inner).await;
                role.set(Role::Writer);
            });
        }
    }

    /// Problems met while taking over from a closed writer, once.
    pub fn take_takeover_warnings(&self) -> Vec<String> {
        std::mem::take(&mut self.inner.borrow_mut().takeover_warnings)
    }

    /// A set-aside record's stored value, as text, for download.
    pub fn read_aside(&self, key: String) -> impl std::future::Future<Output = Result<String, StoreError>> + 'static {
        let db = self.inner.borrow().db.clone();
        async move {
            let db = db.ok_or_else(|| StoreError::Unavailable("no database".into()))?;
            let value = db.get(idb::ASIDE, &key).await?;
            Ok(value
                .map(|v| v.as_string().unwrap_or_else(|| format!("{v:?}")))
                .unwrap_or_default())
        }
    }

    /// A follower re-reads the store when the writer says it saved.
    fn listen_to_writer(&self) {
        let i = self.inner.borrow();
        let Some(channel) = &i.channel else { return };
        let weak = Rc::downgrade(&self.inner);
        let role = self.lock.role.clone();
        let on_message = Closure::<dyn FnMut()>::new(move || {
            if role.get() != Role::Follower {
                return;
            }
            if let Some(inner) = weak.upgrade() {
                wasm_bindgen_futures::spawn_local(async move { refresh(&inner).await });
            }
        });
        channel.set_onmessage(Some(on_message.as_ref().unchecked_ref()));
        // Lives as long as the channel, which the store closes when it goes.
        on_message.forget();
    }
}

impl Drop for SceneStore {
    fn drop(&mut self) {
        if let Some(c) = &self.inner.borrow().channel {
            c.set_onmessage(None);
            c.close();
        }
    }
}

/// Starts the write loop unless it runs (or there is nowhere to write).
fn kick(inner: &Rc<RefCell<Inner>>) {
    {
        let mut i = inner.borrow_mut();
        if i.db.is_none() || i.in_flight || !i.dirty() {
            return;
        }
        i.in_flight = true;
    }
    let inner = inner.clone();
    wasm_bindgen_futures::spawn_local(async move { write_loop(&inner).await });
}

/// Writes the wanted labels until the disk holds the latest, or a write fails.
async fn write_loop(inner: &Rc<RefCell<Inner>>) {
    loop {
        let (db, version, record, dropped) = {
            let i = inner.borrow();
            let (Some(db), Some(w)) = (i.db.clone(), i.wanted.as_ref()) else {
                break;
            };
            if i.written == Some(w.version) {
                break;
            }
            let (record, dropped) = i.record_for(w, browser::wall_clock_ms());
            (db, w.version, record, dropped)
        };
        let key = SceneKey::new(&record.content_id);
        let puts = [(key.snapshot(record.seq), record.to_json())];
        let deletes: Vec<String> = dropped.iter().map(|&s| key.snapshot(s)).collect();
        let result = db.write_snapshots(&puts, &deletes).await;
        let mut i = inner.borrow_mut();
        match result {
            Ok(()) => {
                let seq = record.seq;
                i.keep(record, &dropped);
                i.written = Some(version);
                i.error = None;
                if let Some(c) = &i.channel {
                    let _ = c.post_message(&JsValue::from_f64(seq as f64));
                }
            }
            Err(e) => {
                web_sys::console::error_1(&format!("annotations not saved: {e}").into());
                i.error = Some(e.to_string());
                break;
            }
        }
    }
    inner.borrow_mut().in_flight = false;
}

/// The journal a closed writer left, into the store, before a follower takes over: otherwise
/// the new writer's next save could take the journal's slot and the journal would look stale.
async fn take_writers_journal(inner: &Rc<RefCell<Inner>>) {
    let (db, key, shape) = {
        let i = inner.borrow();
        let Some(db) = i.db.clone() else { return };
        (db, i.key.clone(), i.shape)
    };
    let (mut warnings, mut aside) = (Vec::new(), Vec::new());
    open::take_journal(&db, &key, shape, &mut warnings, &mut aside).await;
    let mut i = inner.borrow_mut();
    i.takeover_warnings.extend(warnings);
    i.aside.extend(aside);
}

/// Re-reads the scene's snapshots (a follower, after the writer saved or went); the newest
/// labels become `followed`.
async fn refresh(inner: &Rc<RefCell<Inner>>) {
    let (db, key, shape) = {
        let i = inner.borrow();
        let Some(db) = i.db.clone() else { return };
        (db, i.key.clone(), i.shape)
    };
    let (lower, upper) = key.range();
    let Ok(entries) = db.entries(idb::SNAPSHOTS, &lower, &upper).await else {
        return;
    };
    let max_seq = entries.iter().filter_map(|(k, _)| key.seq_of(k)).max();
    let records: Vec<SnapshotRecord> = entries
        .iter()
        .filter_map(|(k, v)| SnapshotRecord::read(&v.as_string()?, k, &shape).ok())
        .collect();
    let mut i = inner.borrow_mut();
    i.followed = records.last().map(|r| r.autosave.labels.clone());
    i.next_seq = max_seq.map_or(0, |s| s + 1).max(i.next_seq);
    i.snapshots = records;
}

/// As the page is hidden or closed, an IndexedDB write may not finish: the labels not yet on
/// disk also go to local storage, synchronously (read back at the next load).
fn listen_for_hiding(inner: Weak<RefCell<Inner>>) -> Option<Listeners> {
    let window = web_sys::window()?;
    let document = window.document()?;
    let hide = Closure::<dyn FnMut()>::new(move || {
        let Some(inner) = inner.upgrade() else { return };
        let hidden = web_sys::window()
            .and_then(|w| w.document())
            .is_none_or(|d| d.visibility_state() == web_sys::VisibilityState::Hidden);
        if hidden {
            write_journal(&inner);
        }
    });
    let f = hide.as_ref().unchecked_ref();
    let _ = window.add_event_listener_with_callback("pagehide", f);
    let _ = document.add_event_listener_with_callback("visibilitychange", f);
    Some(Listeners { hide })
}

fn write_journal(inner: &Rc<RefCell<Inner>>) {
    {
        let i = inner.borrow();
        if !i.dirty() {
            return;
        }
        let Some(w) = &i.wanted else { return };
        let (record, _) = i.record_for(w, browser::wall_clock_ms());
        if !legacy::set(&i.key.journal(), &record.to_json()) {
            web_sys::console::error_1(&"annotations not saved: local storage refused the journal".into());
        }
    }
    kick(inner);
}
