//! Saving, as the user sees it: the store's news each frame (labels another tab saved, a
//! failed write), the banner that stays while the latest edits are NOT saved or the tab is
//! read-only, the save line in the tools panel, and the snapshots window (restore a snapshot,
//! download a set-aside record). The wording says "saved" only for [`SaveState::Saved`].
use egui::RichText;

use super::super::browser;
use super::super::persistence;
use super::super::store::SaveState;
use super::{Annotator, InboxItem};
use crate::labels::snapshots::{KEEP_SNAPSHOTS, Reason};

/// Local date and time of a Unix-ms instant, for people.
fn local_time(ms: f64) -> String {
    let d = js_sys::Date::new(&ms.into());
    format!(
        "{:04}-{:02}-{:02} {:02}:{:02}:{:02}",
        d.get_full_year(),
        d.get_month() + 1,
        d.get_date(),
        d.get_hours(),
        d.get_minutes(),
        d.get_seconds()
    )
}

impl Annotator {
    /// What the store has to say this frame.
    pub(super) fn take_store_news(&mut self) {
        self.doc.store.poll();
        for warning in self.doc.store.take_takeover_warnings() {
            self.notify(&warning, true);
        }
        if let Some(labels) = self.doc.store.take_followed()
            && labels != self.doc.labels
        {
            self.doc.follow(labels);
            self.labels_followed();
        }
        let state = self.doc.save_state();
        let read_only = state == SaveState::ReadOnly;
        if self.save_news.read_only && !read_only {
            self.notify("The other tab has closed: this tab now saves this scene.", false);
        }
        self.save_news.read_only = read_only;
        match &state {
            SaveState::Failed(e) if self.save_news.failure.as_deref() != Some(e.as_str()) => {
                self.save_news.failure = Some(e.clone());
                self.notify(&format!("The annotations could not be saved: {e}"), true);
            }
            SaveState::Failed(_) => {}
            _ => self.save_news.failure = None,
        }
    }

    /// The line that stays on top while saving is not what it should be.
    pub(super) fn save_banner(&self) -> Option<(String, bool)> {
        // Browser messages end with a full stop of their own.
        let clean = |e: &str| e.trim_end_matches('.').to_string();
        match self.doc.save_state() {
            SaveState::Failed(e) => Some((
                format!(
                    "⚠ NOT SAVED: {}. The latest edits are only in this tab: export labels to keep them.",
                    clean(&e)
                ),
                true,
            )),
            SaveState::Unavailable(e) => Some((
                format!(
                    "⚠ NOT SAVED: this browser cannot store annotations ({}). Export labels to keep them.",
                    clean(&e)
                ),
                true,
            )),
            SaveState::ReadOnly => Some((
                "Read-only: this scene is being edited in another tab; this tab follows its saves.".into(),
                false,
            )),
            SaveState::Saved | SaveState::Saving => None,
        }
    }

    /// The save line and the snapshots button, in the tools panel.
    pub(super) fn save_section(&mut self, ui: &mut egui::Ui) {
        let state = self.doc.save_state();
        let (text, color) = match &state {
            SaveState::Saved => ("✔ saved in this browser".to_string(), ui.visuals().weak_text_color()),
            SaveState::Saving => ("saving…".to_string(), ui.visuals().weak_text_color()),
            SaveState::Failed(_) | SaveState::Unavailable(_) => {
                ("⚠ NOT SAVED (see above)".to_string(), ui.visuals().error_fg_color)
            }
            SaveState::ReadOnly => ("read-only: another tab saves".to_string(), ui.visuals().warn_fg_color),
        };
        ui.label(RichText::new(text).color(color));
        let count = self.doc.store.snapshots().len();
        if ui
            .button(format!("snapshots ({count})…"))
            .on_hover_text("earlier versions of these annotations kept in this browser; restore one")
            .clicked()
        {
            self.snapshots_open = !self.snapshots_open;
        }
    }

    pub(super) fn snapshots_window(&mut self, ctx: &egui::Context) {
        if !self.snapshots_open {
            return;
        }
        let mut open = true;
        let mut restore = None;
        let mut download = None;
        let snapshots = self.doc.store.snapshots();
        let others = self.doc.store.others();
        let mut restore_other = None;
        let aside = self.doc.store.aside();
        let writable = self.doc.store.writable();
        egui::Window::new("Snapshots").open(&mut open).show(ctx, |ui| {
            ui.label(
                RichText::new(format!(
                    "The last {KEEP_SNAPSHOTS} versions of this scene's annotations, kept in this browser \
                     (IndexedDB) under the scene's content id {}.",
                    self.doc.store.content_id()
                ))
                .small(),
            );
            egui::Grid::new("snapshot list").striped(true).show(ui, |ui| {
                for s in snapshots.iter().rev() {
                    ui.label(local_time(s.saved_ms));
                    ui.label(format!("{} strokes", s.strokes));
                    ui.label(s.reason.describe());
                    if ui
                        .add_enabled(writable, egui::Button::new("restore"))
                        .on_hover_text("undoable; what is shown now stays in its own snapshot")
                        .clicked()
                    {
                        restore = Some((s.seq, s.saved_ms));
                    }
                    ui.end_row();
                }
            });
            if snapshots.is_empty() {
                ui.label("Nothing saved yet.");
            }
            if !others.is_empty() {
                ui.separator();
                ui.label("Saved for another version of this archive at the same address:");
                egui::Grid::new("other versions").striped(true).show(ui, |ui| {
                    for (id, s) in others.iter().rev() {
                        ui.label(local_time(s.saved_ms));
                        ui.label(format!("{} strokes", s.strokes));
                        ui.label(RichText::new(&id[..8.min(id.len())]).monospace())
                            .on_hover_text(format!("content id {id}"));
                        if ui.add_enabled(writable, egui::Button::new("restore")).clicked() {
                            restore_other = Some((id.clone(), s.seq, s.saved_ms));
                        }
                        ui.end_row();
                    }
                });
            }
            if !aside.is_empty() {
                ui.separator();
                ui.label(
                    RichText::new("Set aside (could not be read; never overwritten):")
                        .color(ui.visuals().warn_fg_color),
                );
                for key in &aside {
                    ui.horizontal(|ui| {
                        ui.label(RichText::new(key).monospace().small());
                        if ui.button("download").clicked() {
                            download = Some(key.clone());
                        }
                    });
                }
            }
        });
        self.snapshots_open = open;
        if let Some((seq, saved_ms)) = restore {
            self.restore_snapshot(seq, saved_ms);
        }
        if let Some((id, seq, saved_ms)) = restore_other {
            match self.doc.store.other_labels(&id, seq) {
                Some(labels) => self.replace_labels(
                    labels,
                    &format!(
                        "Restored the annotations of {} saved for another version of this archive.",
                        local_time(saved_ms)
                    ),
                    Reason::Restored,
                ),
                None => self.notify("That snapshot is gone.", true),
            }
        }
        if let Some(key) = download {
            self.download_aside(key);
        }
    }

    fn restore_snapshot(&mut self, seq: u64, saved_ms: f64) {
        match self.doc.store.snapshot_labels(seq) {
            Some(labels) => self.replace_labels(
                labels,
                &format!("Restored the snapshot of {} (undo goes back).", local_time(saved_ms)),
                Reason::Restored,
            ),
            None => self.notify("That snapshot is gone.", true),
        }
    }

    fn download_aside(&mut self, key: String) {
        let name = format!(
            "{}-unreadable-{}.json",
            persistence::download_stem(&self.doc.source),
            key.rsplit('-').next().unwrap_or("save")
        );
        let read = self.doc.store.read_aside(key);
        let inbox = self.inbox.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = read.await.map_err(|e| e.to_string()).and_then(|text| {
                browser::download(text.as_bytes(), &name, "application/json").map_err(|e| e.to_string())
            });
            if let Err(e) = result {
                inbox.borrow_mut().push(InboxItem::Error(e));
            }
        });
    }
}
