//! The page status while annotating (see `app::status`), put together from the three parts.
use super::super::canvas::Tool;
use super::super::status::{Annotating, PageStatus, SaveStatus};
use super::super::training::Phase;
use super::Annotator;

/// `value` rounded to `decimals` places: the status only changes (and is only rewritten) when
/// what it shows does.
fn round(value: f64, decimals: i32) -> f64 {
    let scale = 10f64.powi(decimals);
    (value * scale).round() / scale
}

fn rect(r: egui::Rect) -> [f32; 4] {
    [r.min.x, r.min.y, r.width(), r.height()].map(f32::round)
}

impl Annotator {
    fn save_status(&self) -> SaveStatus {
        let store = &self.doc.store;
        let state = self.doc.save_state();
        SaveStatus {
            state: state.name(),
            error: state.error().map(str::to_string),
            scene: store.content_id(),
            snapshots: store.snapshots().iter().map(|s| [s.seq, s.strokes as u64]).collect(),
            aside: store.aside(),
            others: store.others().len(),
            persisted: store.persisted(),
        }
    }

    pub(super) fn status(&self) -> PageStatus {
        let (doc, view) = (&self.doc, &self.view);
        let rendered = view.rendered_here();
        let mut s = Annotating {
            frames: doc.frame_count(),
            size: [doc.scene.width, doc.scene.height],
            frame: view.frame,
            class: view.class,
            tool: match view.tool {
                Tool::Brush => "brush",
                Tool::Eraser => "eraser",
            },
            classes: doc.labels.classes.len(),
            strokes: doc.summary.strokes,
            labelled: doc.summary.labelled_pixels,
            training: "none",
            spread: None,
            exporting: None,
            steps: 0,
            sps: 0.0,
            loss: None,
            rendered: -1,
            saved: doc.saved(),
            res: self.training.factor(),
            render_ms: 0.0,
            view: rect(view.image_rect),
            mask: None,
            classes_shown: rendered.is_some_and(|r| r.labelled),
            refresh_ms: None,
            step_ms: None,
            batch: None,
            features: view.features_rect.filter(|_| rendered.is_some()).map(rect),
            failure: None,
            save: self.save_status(),
        };
        if let Some(t) = &self.training.handle {
            let reports = t.reports();
            let p = &reports.progress;
            s.training = match &reports.phase {
                Phase::Starting => "starting",
                Phase::Running if reports.spreading => "spreading",
                Phase::Running if t.paused() => "paused",
                Phase::Running => "running",
                Phase::Exporting { .. } => "exporting",
                Phase::Failed(_) => "failed",
            };
            s.spread = reports.spread.map(|s| [s.pixels, s.frames]);
            if let Phase::Exporting { done, total } = reports.phase {
                s.exporting = Some([done, total]);
            }
            if let Phase::Failed(e) = &reports.phase {
                s.failure = Some(e.to_string());
            }
            s.steps = p.steps;
            s.sps = round(p.steps_per_second, 2);
            s.loss = p
                .losses
                .map(|l| round(l.terms.total() / f64::from(t.config.batch_rays), 4));
            s.rendered = rendered.map_or(-1, |r| i64::from(r.step));
            s.render_ms = reports.render_ms.round();
            s.mask = Some(match rendered {
                None => "none",
                Some(r) if r.coarse => "coarse",
                Some(_) => "full",
            });
            s.refresh_ms = reports
                .refresh
                .map(|r| [Some(r.first_ms.round()), r.full_ms.map(f64::round)]);
            s.step_ms = Some([p.step_submit_ms.round(), p.step_wait_ms.round()]);
            s.batch = Some(p.batch);
        }
        PageStatus::Ready(Box::new(s))
    }
}
