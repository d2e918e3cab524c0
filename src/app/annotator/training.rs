//! The annotator's hold on training: the handle to the running task, what it needs to start
//! again (device, model, page options, the downscaled scene), and the masks export in progress.
use std::rc::Rc;

use super::super::browser;
use super::super::page_options::PageOptions;
use super::super::training::scene::{auto_factor, downscale};
use super::super::training::{Phase, Refresh, Training, TrainingOptions, TrainingSetup};
use super::document::Document;
use crate::export::ExportOptions;
use crate::field::{Preset, Runner, finish};
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::refine::RefineOptions;
use crate::scene::Scene;

pub struct TrainingControl {
    /// The page's device; `None` without WebGPU.
    gpu: Option<GpuContext>,
    pub model: Preset,
    options: PageOptions,
    /// The running task; `None` before the first start, without a GPU, or while a restart waits.
    pub handle: Option<Training>,
    /// A new class outgrew the field: start again at the next frame.
    restart_pending: bool,
    /// The scene at training resolution, for (downscale factor, whether it keeps the codes);
    /// kept for restarts.
    train_scene: Option<((u32, bool), Rc<Scene>)>,
    export_started_ms: Option<f64>,
    /// How long the latest masks export took.
    pub last_export_ms: Option<f64>,
}

impl TrainingControl {
    pub fn new(gpu: Option<GpuContext>, model: Preset, options: PageOptions) -> TrainingControl {
        TrainingControl {
            gpu,
            model,
            options,
            handle: None,
            restart_pending: false,
            train_scene: None,
            export_started_ms: None,
            last_export_ms: None,
        }
    }

    /// A CPU rasterizer: every repaint costs the training about a second there.
    pub fn software(&self) -> bool {
        self.gpu.as_ref().is_some_and(|g| g.profile().software)
    }

    /// (Re)starts training from scratch on `doc`'s labels, showing `frame` first; on load, after
    /// a failure, or when the classes outgrow the field's semantic head. Says why it cannot.
    pub fn start(&mut self, ctx: &egui::Context, doc: &Document, frame: u32) -> Result<(), String> {
        self.handle = None;
        self.restart_pending = false;
        let Some(gpu) = self.gpu.clone() else {
            return Err("No GPU device: the field cannot be trained in this page.".into());
        };
        let scene = &doc.scene;
        let factor = self
            .options
            .res
            .unwrap_or_else(|| auto_factor(scene.width, scene.height, self.model == Preset::Tiny));
        let key = (factor, Runner::Page.trains_on_codes(self.model));
        let train_scene = match &self.train_scene {
            Some((k, s)) if *k == key => s.clone(),
            _ => {
                let s = Rc::new(downscale(scene, factor, key.1));
                self.train_scene = Some((key, s.clone()));
                s
            }
        };
        let mut config = finish(self.model.config(), &train_scene, doc.labels.classes.len()).config;
        if let Some(rays) = self.options.rays {
            config.batch_rays = rays;
        }
        config.validate().map_err(|e| format!("cannot train: {e}"))?;
        let mut options = TrainingOptions {
            profile: self.options.profile,
            // Training numbers: on a CPU rasterizer every repaint delays training by about a
            // second, so there the panel is updated every few seconds.
            repaint_ms: gpu.profile().training_repaint_ms,
            split_steps: self.options.split,
            refine: RefineOptions::for_scene(&train_scene),
            ..TrainingOptions::default()
        };
        if let Some(n) = self.options.refine {
            options.refine.iterations = n;
        }
        if let Some(n) = self.options.coarse {
            options.refresh = Refresh {
                coarse_divisor: n,
                coarse_always: true,
            };
        }
        let gpu = match self.options.kernels {
            Some(kernels) => gpu.with_kernels(kernels),
            None => gpu,
        };
        let setup = TrainingSetup {
            scene: train_scene,
            factor,
            full_size: (scene.width, scene.height),
            config,
            options,
        };
        let training = Training::start(gpu, setup, &doc.labels, frame, ctx.clone());
        training.set_labels(doc.version, &doc.labels);
        self.handle = Some(training);
        Ok(())
    }

    /// The labels changed: hands them to the task, or, when their classes outgrew the field,
    /// stops it to start again at the next frame (`true`).
    pub fn labels_changed(&mut self, doc: &Document) -> bool {
        let outgrown = self
            .handle
            .as_ref()
            .is_some_and(|t| (t.config.num_classes as usize) < doc.labels.classes.len());
        if outgrown {
            self.handle = None;
            self.restart_pending = true;
        } else if let Some(t) = &self.handle {
            t.set_labels(doc.version, &doc.labels);
        }
        outgrown
    }

    /// A restart that [`TrainingControl::labels_changed`] left for now.
    pub fn restart_pending(&self) -> bool {
        self.handle.is_none() && self.gpu.is_some() && self.restart_pending
    }

    /// Asks for the masks of every frame.
    pub fn export(&mut self, labels: &LabelSet, options: &ExportOptions) -> Result<(), String> {
        let Some(t) = &self.handle else {
            return Err("No trained field to render masks from.".into());
        };
        t.export(labels, options);
        self.export_started_ms = Some(browser::now_ms());
        Ok(())
    }

    /// An export's zip came: note how long it took.
    pub fn export_done(&mut self) {
        self.last_export_ms = self.export_started_ms.take().map(|s| browser::now_ms() - s);
    }

    pub fn toggle_pause(&mut self) {
        if let Some(t) = &mut self.handle {
            t.toggle_pause();
        }
    }

    pub fn phase(&self) -> Option<&Phase> {
        self.handle.as_ref().map(|t| &t.reports().phase)
    }

    /// The training resolution's downscale factor (1 without training).
    pub fn factor(&self) -> u32 {
        self.handle.as_ref().map_or(1, |t| t.factor)
    }
}
