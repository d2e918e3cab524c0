//! The device's side of training in the page: its faults (a lost device, uncaptured errors,
//! reported by browser callbacks), waiting for submitted work without blocking, and the
//! steps-per-second meter.
use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Mutex};

use futures_channel::oneshot;

use super::super::browser::now_ms;
use super::super::page_status;
use super::TrainError;

/// Device loss and uncaptured GPU errors, as the device reports them (from browser callbacks,
/// hence the mutex: wgpu asks for `Send` handlers).
#[derive(Clone)]
pub struct GpuFaults(Arc<Mutex<Option<String>>>);

impl GpuFaults {
    pub fn watch(device: &wgpu::Device, egui_ctx: &egui::Context) -> GpuFaults {
        let faults = GpuFaults(Arc::new(Mutex::new(None)));
        let lost = faults.clone();
        let repaint = egui_ctx.clone();
        device.set_device_lost_callback(move |reason, message| {
            let text = format!("the GPU device was lost ({reason:?}): {message}");
            // Dropping a trainer destroys its buffers, not the device: anything arriving here
            // means the page's (shared) device is gone.
            page_status::set_gpu_lost(&text);
            lost.record(text);
            repaint.request_repaint();
        });
        let errors = faults.clone();
        let repaint = egui_ctx.clone();
        device.on_uncaptured_error(Arc::new(move |error| {
            let text = match &error {
                wgpu::Error::OutOfMemory { .. } => {
                    "the GPU ran out of memory; a smaller scene or a GPU with more memory is needed".to_string()
                }
                other => format!("GPU error: {other}"),
            };
            errors.record(text);
            repaint.request_repaint();
        }));
        faults
    }

    fn record(&self, message: String) {
        if let Ok(mut slot) = self.0.lock() {
            slot.get_or_insert(message);
        }
    }

    fn take(&self) -> Option<String> {
        self.0.lock().ok().and_then(|mut slot| slot.take())
    }

    /// The fault the device reported since the last call, as an error.
    pub fn check(&self) -> Result<(), TrainError> {
        match self.take() {
            Some(message) => Err(TrainError::Device(message)),
            None => Ok(()),
        }
    }
}

/// Steps per second over the last few seconds of batches.
#[derive(Default)]
pub struct RateMeter {
    samples: std::collections::VecDeque<(f64, u32, f64)>,
}

impl RateMeter {
    /// `steps` steps that took `ms` and ended at `at_ms` (page clock).
    pub fn add_at(&mut self, at_ms: f64, steps: u32, ms: f64) {
        self.samples.push_back((at_ms, steps, ms));
        while self.samples.len() > 2 && self.samples.front().is_some_and(|s| at_ms - s.0 > 3000.0) {
            self.samples.pop_front();
        }
    }

    /// Steps per second of wall time, counting the gaps between batches too.
    pub fn per_second(&self) -> f64 {
        let (Some(first), Some(last)) = (self.samples.front(), self.samples.back()) else {
            return 0.0;
        };
        let steps: u32 = self.samples.iter().map(|s| s.1).sum();
        let span = last.0 - (first.0 - first.2);
        if span <= 0.0 {
            0.0
        } else {
            f64::from(steps) * 1000.0 / span
        }
    }

    pub fn reset(&mut self) {
        self.samples.clear();
    }
}

/// Resolves once the GPU has finished everything submitted so far. The browser calls back
/// from its event loop; nothing blocks.
pub fn gpu_done(queue: &wgpu::Queue) -> impl Future<Output = ()> + use<> {
    let (done, finished) = oneshot::channel();
    // Registered now, not when the future is first polled.
    queue.on_submitted_work_done(move || {
        let _ = done.send(());
    });
    async move {
        // A callback dropped without running (the device is gone) ends the wait too.
        let _ = finished.await;
    }
}

/// Resolves to when (page clock, ms) the GPU finished everything submitted before it was made;
/// `None` when the callback was dropped without running (the device is gone).
pub type GpuDone = Pin<Box<dyn Future<Output = Option<f64>>>>;

/// Like [`gpu_done`], and notes the time the browser reported the work done, so a caller that
/// awaits it later (with more work queued behind) still learns when it ended.
pub fn gpu_done_at(queue: &wgpu::Queue) -> GpuDone {
    let (done, finished) = oneshot::channel();
    queue.on_submitted_work_done(move || {
        let _ = done.send(now_ms());
    });
    Box::pin(async move { finished.await.ok() })
}
