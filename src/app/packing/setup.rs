//! The pack settings, shown when a capture folder (or a zip of one) is picked or dropped and
//! before anything is packed: the `pack-` page options as initial values, each setting checked
//! as it is typed, and an estimate of what the pack will cost (its frames, the archive's size,
//! the page's memory, the time), from the capture's file list and its first image's size
//! (`features::pack::{survey_capture, estimate_pack}`). *Start* packs; *Cancel* (or Escape)
//! leaves whatever was open as it was.
//!
//! For scripts, `<body data-pack-setup="...">` holds the form's state while it is shown (see
//! docs/web-app.md, "For scripts").
use std::cell::RefCell;
use std::rc::Rc;

use egui::RichText;
use serde_json::json;
use wasm_bindgen_futures::JsFuture;

use super::CaptureInput;
use crate::app::page_options::PageOptions;
use crate::features::pack::{
    CaptureSurvey, FormError, PackEstimate, PackForm, PackOptions, estimate_pack, survey_capture,
};
use crate::scene::import::MAX_CAPTURE_BYTES;

/// Bytes of the first image read for its size (a JPEG's size comes after its EXIF block, which
/// is at most 64 KiB); the whole file when that is not enough.
const HEADER_BYTES: i32 = 256 << 10;

/// The first image's size, read in the background.
enum SourceSize {
    Reading,
    Known((u32, u32)),
    Unknown(String),
}

/// The form's options, or what is wrong with them.
type Checked = Result<PackOptions, Vec<FormError>>;

/// What the user decided.
pub enum SetupOutcome {
    /// Still deciding.
    Open,
    Start(Box<PackStart>),
    Cancel,
}

/// What to pack, and how.
pub struct PackStart {
    pub name: String,
    pub input: CaptureInput,
    pub opts: PackOptions,
    pub estimate: Option<PackEstimate>,
}

pub struct PackSetup {
    name: String,
    input: Option<CaptureInput>,
    survey: CaptureSurvey,
    /// The capture has no depth images and the page options name no size: the form starts at
    /// the photo captures' size, and says so.
    photo_defaults: bool,
    size: Rc<RefCell<SourceSize>>,
    /// The options the page started with (`pack-` options); the form changes some of them.
    base: PackOptions,
    form: PackForm,
    /// The `data-pack-setup` written last, so the DOM is touched only on a change.
    published: String,
}

impl PackSetup {
    /// The settings of `input` as the page options give them, with the page's defaults for its
    /// kind of capture (`super::pack_options`).
    pub fn new(name: String, input: CaptureInput, options: &PageOptions, ctx: &egui::Context) -> PackSetup {
        let size = Rc::new(RefCell::new(SourceSize::Reading));
        let survey = match &input {
            CaptureInput::Files(files) => {
                let survey = survey_capture(files.iter().map(|(p, f)| (p.as_str(), f.size() as u64)));
                match (survey.video, survey.first_image) {
                    (Some(i), _) => read_size_of_video(files[i].1.clone(), size.clone(), ctx.clone()),
                    (None, Some(i)) => read_size_of_file(files[i].1.clone(), size.clone(), ctx.clone()),
                    (None, None) => *size.borrow_mut() = SourceSize::Unknown("no images found".into()),
                }
                survey
            }
            CaptureInput::Zip { bytes, .. } => {
                let (survey, first) = survey_zip(bytes);
                *size.borrow_mut() = first;
                survey
            }
        };
        let base = super::pack_options(options, survey.dense_depth);
        let photo_defaults = !survey.dense_depth && survey.images > 0 && options.pack_size.is_none();
        PackSetup {
            name,
            input: Some(input),
            photo_defaults,
            survey,
            size,
            form: PackForm::from_options(&base),
            base,
            published: String::new(),
        }
    }

    /// Draws the settings over the page; what the user chose.
    pub fn show(&mut self, ctx: &egui::Context) -> SetupOutcome {
        let (checked, _, estimate) = self.check();
        let too_large = self.survey.capture_bytes > MAX_CAPTURE_BYTES;
        let can_start = checked.is_ok() && !too_large;
        let mut rects: Vec<(&'static str, egui::Rect)> = Vec::new();
        let mut start = false;
        let mut cancel = false;
        let mut changed = false;
        let modal = egui::Modal::new(egui::Id::unique("pack settings")).show(ctx, |ui| {
            ui.set_max_width(520.0);
            ui.heading(format!("Pack {}", self.name));
            ui.label(self.describe_capture());
            ui.add_space(6.0);
            let errors = checked.as_ref().err();
            let error_of = |field: &str| errors.and_then(|e| e.iter().find(|e| e.field == field));
            let error_color = ui.visuals().error_fg_color;
            let features_on = self.form.features;
            egui::Grid::new("pack settings grid")
                .num_columns(3)
                .spacing([8.0, 6.0])
                .show(ui, |ui| {
                    let form = &mut self.form;
                    let rows = [
                        ("max_size", "longest side", "pixels (frames are only ever made smaller)"),
                        ("every", "every", "th frame (1: every frame)"),
                        ("max_frames", "at most", "frames (empty: all)"),
                        (
                            "features",
                            "features",
                            "weight-free baseline features, for feature supervision",
                        ),
                        ("stride", "feature cell", "x that many pixels"),
                        (
                            "steps",
                            "autoencoder steps",
                            "fitting the codes (the command line's default: 3000)",
                        ),
                    ];
                    for (key, label, hint) in rows {
                        ui.label(label);
                        let r = if key == "features" {
                            ui.checkbox(&mut form.features, "feature codes")
                        } else {
                            let text = match key {
                                "max_size" => &mut form.max_size,
                                "every" => &mut form.every,
                                "max_frames" => &mut form.max_frames,
                                "stride" => &mut form.stride,
                                _ => &mut form.steps,
                            };
                            let edit = egui::TextEdit::singleline(text).desired_width(70.0);
                            ui.add_enabled(form_enabled(key, features_on), edit)
                        };
                        let r = match error_of(key) {
                            Some(e) => r.on_hover_text(RichText::new(&e.message).color(error_color)),
                            None => r,
                        };
                        rects.push((key, r.rect));
                        changed |= r.changed();
                        ui.label(RichText::new(hint).small());
                        ui.end_row();
                    }
                });
            if let Some(errors) = errors {
                for e in errors {
                    let label = match e.field {
                        "max_size" => "longest side",
                        "every" => "every",
                        "max_frames" => "at most",
                        "stride" => "feature cell",
                        _ => "autoencoder steps",
                    };
                    ui.label(RichText::new(format!("{label}: {}", e.message)).color(error_color));
                }
            }
            if too_large {
                ui.label(
                    RichText::new(format!(
                        "its images and model files are {:.0} MB, more than this page packs ({:.0} MB at most); \
                         pack it with the command line (`scribblefield pack`)",
                        self.survey.capture_bytes as f64 / 1e6,
                        MAX_CAPTURE_BYTES as f64 / 1e6
                    ))
                    .color(error_color),
                );
            }
            ui.separator();
            ui.horizontal(|ui| {
                ui.strong("Estimate");
                ui.label(
                    RichText::new("from per-frame and per-step costs measured on one machine; yours may differ")
                        .small(),
                );
            });
            match (&estimate, &*self.size.borrow()) {
                (Some(e), _) => estimate_lines(ui, e, &self.survey),
                (None, SourceSize::Reading) => {
                    ui.label("reading the size of the first image…");
                }
                (None, SourceSize::Unknown(why)) => {
                    ui.label(format!("none: the frames' size is unknown ({why})"));
                }
                (None, SourceSize::Known(_)) => {
                    ui.label("none until the settings are right");
                }
            }
            ui.add_space(8.0);
            ui.horizontal(|ui| {
                let r = ui
                    .add_enabled(can_start, egui::Button::new("Start"))
                    .on_hover_text("pack with these settings (Enter)");
                rects.push(("start", r.rect));
                start = r.clicked();
                let r = ui.button("Cancel").on_hover_text("Escape; whatever was open stays");
                rects.push(("cancel", r.rect));
                cancel = r.clicked();
            });
        });
        // The estimate above was of the values before this frame's edits: show the new one.
        if changed {
            ctx.request_repaint();
        }
        let enter = ctx.input(|i| i.key_pressed(egui::Key::Enter));
        // Scripts see the values as they are now, with their own errors and estimate.
        let (checked, source, estimate) = self.check();
        let can_start = checked.is_ok() && !too_large;
        self.publish(&checked, source, estimate.as_ref(), &rects);
        if (start || enter) && can_start {
            let opts = checked.expect("checked above");
            return match self.input.take() {
                Some(input) => SetupOutcome::Start(Box::new(PackStart {
                    name: self.name.clone(),
                    input,
                    opts,
                    estimate,
                })),
                None => SetupOutcome::Cancel,
            };
        }
        if cancel || modal.should_close() {
            return SetupOutcome::Cancel;
        }
        SetupOutcome::Open
    }

    /// The form's options (or what is wrong with them), the first image's size when known, and
    /// the estimate when both are.
    fn check(&self) -> (Checked, Option<(u32, u32)>, Option<PackEstimate>) {
        let checked = self.form.options(&self.base);
        let source = match &*self.size.borrow() {
            SourceSize::Known(s) => Some(*s),
            _ => None,
        };
        let estimate = match (&checked, source) {
            (Ok(opts), Some(s)) => Some(estimate_pack(&self.survey, s, opts)),
            _ => None,
        };
        (checked, source, estimate)
    }

    fn describe_capture(&self) -> String {
        let s = &self.survey;
        let size = match &*self.size.borrow() {
            SourceSize::Known((w, h)) => format!(" of {w} x {h}"),
            _ => String::new(),
        };
        if s.images == 0 {
            return format!(
                "No images found ({:.1} MB of model files); packing says what it expected.",
                s.capture_bytes as f64 / 1e6
            );
        }
        let mut text = format!(
            "{} {}{size} in {} ({:.1} MB of images and model files to read).",
            s.images,
            if s.video.is_some() { "frames" } else { "images" },
            s.found_in,
            s.capture_bytes as f64 / 1e6
        );
        if self.photo_defaults {
            text.push_str(&format!(
                " No depth images: photos pack at a longest side of {} with feature cells of {} px by \
                 default, where such captures gave the best masks.",
                super::PHOTO_CAPTURE_MAX_SIZE,
                super::PHOTO_CAPTURE_FEATURE_STRIDE
            ));
        }
        text
    }

    /// Puts the form's state on `<body data-pack-setup>` for scripts.
    fn publish(
        &mut self,
        checked: &Checked,
        source: Option<(u32, u32)>,
        estimate: Option<&PackEstimate>,
        rects: &[(&'static str, egui::Rect)],
    ) {
        let errors: serde_json::Map<String, serde_json::Value> = match checked {
            Ok(_) => Default::default(),
            Err(errors) => errors.iter().map(|e| (e.field.to_string(), json!(e.message))).collect(),
        };
        let rects: serde_json::Map<String, serde_json::Value> = rects
            .iter()
            .map(|(k, r)| (k.to_string(), json!([r.min.x, r.min.y, r.width(), r.height()])))
            .collect();
        let f = &self.form;
        let value = json!({
            "name": self.name,
            "images": self.survey.images,
            "caption": self.describe_capture(),
            "source": source.map(|(w, h)| [w, h]),
            "values": {
                "max_size": f.max_size, "every": f.every, "max_frames": f.max_frames,
                "features": f.features, "stride": f.stride, "steps": f.steps,
            },
            "errors": errors,
            "estimate": estimate.map(estimate_json),
            "rects": rects,
        })
        .to_string();
        if value != self.published {
            set_body_attribute("data-pack-setup", Some(&value));
            self.published = value;
        }
    }
}

/// The estimate as scripts read it (`data-pack-setup`, `data-pack-result`).
pub fn estimate_json(e: &PackEstimate) -> serde_json::Value {
    let s = &e.seconds;
    json!({
        "frames": e.frames,
        "size": [e.size.0, e.size.1],
        "grid": e.grid.map(|(w, h)| [w, h]),
        "archive_bytes": e.archive_bytes,
        "memory_bytes": e.memory_bytes,
        "seconds": s.total(),
        "stages": {
            "reading": s.reading, "frames": s.frames, "features": s.features,
            "autoencoder": s.autoencoder, "writing": s.writing,
        },
    })
}

fn estimate_lines(ui: &mut egui::Ui, e: &PackEstimate, survey: &CaptureSurvey) {
    let mut what = format!(
        "{} of the {} images, at {} x {}",
        e.frames, survey.images, e.size.0, e.size.1
    );
    if let Some((w, h)) = e.grid {
        what.push_str(&format!("; features on a {w} x {h} grid"));
    }
    ui.label(what);
    let s = &e.seconds;
    ui.label(format!(
        "archive ≈ {}   memory ≈ {}   time ≈ {}",
        megabytes(e.archive_bytes),
        megabytes(e.memory_bytes),
        duration(s.total())
    ))
    .on_hover_text(format!(
        "reading the files {}, frames {}, features {}, autoencoder {}, writing {}\n\
         memory: the page's at the peak of packing (the files read, the frames, the features, the archive \
         and the scene opened from it)",
        duration(s.reading),
        duration(s.frames),
        duration(s.features),
        duration(s.autoencoder),
        duration(s.writing)
    ));
}

pub fn megabytes(bytes: u64) -> String {
    let mb = bytes as f64 / 1e6;
    if mb < 10.0 {
        format!("{mb:.1} MB")
    } else {
        format!("{mb:.0} MB")
    }
}

pub fn duration(seconds: f64) -> String {
    if seconds < 1.0 {
        "< 1 s".into()
    } else if seconds < 90.0 {
        format!("{seconds:.0} s")
    } else if seconds < 5400.0 {
        format!("{:.0} min", seconds / 60.0)
    } else {
        format!("{:.1} h", seconds / 3600.0)
    }
}

/// Sets (or with `None` removes) an attribute of `<body>`.
pub fn set_body_attribute(name: &str, value: Option<&str>) {
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        let _ = match value {
            Some(v) => body.set_attribute(name, v),
            None => body.remove_attribute(name),
        };
    }
}

/// A zip's survey, and the size of its first image.
fn survey_zip(bytes: &[u8]) -> (CaptureSurvey, SourceSize) {
    let none = || SourceSize::Unknown("no images found".into());
    let Ok(mut zip) = zip::ZipArchive::new(std::io::Cursor::new(bytes)) else {
        // Packing says what is wrong with it.
        return (survey_capture([]), none());
    };
    let entries: Vec<(String, u64)> = (0..zip.len())
        .filter_map(|i| {
            let e = zip.by_index_raw(i).ok()?;
            Some((e.name().ok()?.into_owned(), e.size()))
        })
        .filter(|(name, _)| !name.ends_with('/'))
        .collect();
    let survey = survey_capture(entries.iter().map(|(n, s)| (n.as_str(), *s)));
    let first = match survey.video.or(survey.first_image) {
        None => none(),
        Some(i) => {
            let (name, size) = &entries[i];
            let mut data = Vec::new();
            let read = *size <= MAX_CAPTURE_BYTES
                && zip
                    .by_name(name)
                    .is_ok_and(|mut f| std::io::Read::read_to_end(&mut f, &mut data).is_ok());
            let sized = if survey.video.is_some() {
                video_size(&data)
            } else {
                image_size(&data)
            };
            match sized.filter(|_| read) {
                Some(s) => SourceSize::Known(s),
                None => SourceSize::Unknown(format!("cannot read the size of {name}")),
            }
        }
    };
    (survey, first)
}

/// Reads the size of an image file from its header, in the background.
fn read_size_of_file(file: web_sys::File, slot: Rc<RefCell<SourceSize>>, ctx: egui::Context) {
    wasm_bindgen_futures::spawn_local(async move {
        let read = |blob: web_sys::Blob| async move {
            JsFuture::from(blob.array_buffer())
                .await
                .ok()
                .map(|b| js_sys::Uint8Array::new(&b).to_vec())
        };
        let head = match file.slice_with_i32_and_i32(0, HEADER_BYTES) {
            Ok(b) => read(b).await,
            Err(_) => None,
        };
        let mut size = head.as_deref().and_then(image_size);
        if size.is_none() && file.size() > HEADER_BYTES as f64 && file.size() <= MAX_CAPTURE_BYTES as f64 {
            size = read(file.clone().into()).await.as_deref().and_then(image_size);
        }
        *slot.borrow_mut() = match size {
            Some(s) => SourceSize::Known(s),
            None => SourceSize::Unknown(format!("cannot read the size of {}", file.name())),
        };
        ctx.request_repaint();
    });
}

/// Reads the size of a video's frames from its MP4 index, in the background: the whole file,
/// since the index may lie at its end (packing reads it anyway).
fn read_size_of_video(file: web_sys::File, slot: Rc<RefCell<SourceSize>>, ctx: egui::Context) {
    wasm_bindgen_futures::spawn_local(async move {
        let bytes = if file.size() <= MAX_CAPTURE_BYTES as f64 {
            JsFuture::from(file.array_buffer())
                .await
                .ok()
                .map(|b| js_sys::Uint8Array::new(&b).to_vec())
        } else {
            None
        };
        *slot.borrow_mut() = match bytes.as_deref().and_then(video_size) {
            Some(s) => SourceSize::Known(s),
            None => SourceSize::Unknown(format!("cannot read the size of {}", file.name())),
        };
        ctx.request_repaint();
    });
}

/// A video's frame size from its MP4 index.
fn video_size(bytes: &[u8]) -> Option<(u32, u32)> {
    crate::scene::import::text_checks::mp4_video(bytes)
        .ok()
        .map(|(size, _)| size)
}

/// An image's size from its first bytes (PNG, JPEG).
fn image_size(bytes: &[u8]) -> Option<(u32, u32)> {
    image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .ok()?
        .into_dimensions()
        .ok()
}

/// Whether a field of the form can be typed in: the feature cell and the autoencoder's steps
/// only with features.
fn form_enabled(key: &str, features: bool) -> bool {
    features || !matches!(key, "stride" | "steps")
}
