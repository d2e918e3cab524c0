//! wasm entry point. `www/index.html` checks that the browser offers WebGPU, then calls
//! [`start`] with the id of the canvas to run the app in.
use std::sync::Arc;

use eframe::egui_wgpu::{WgpuSetup, WgpuSetupCreateNew};
use eframe::wgpu;
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;

use crate::app::bench::BenchApp;
use crate::app::page_options::PageOptions;
use crate::app::status::PageStatus;
use crate::app::{App, browser, page_status};

/// Starts the app in the canvas `canvas_id`, with the options in the page's fragment (the scene
/// named by `#scene=<url>`, or `demo.scene.zip` next to the page).
///
/// Resolves once the app runs (the scene keeps loading in the background); rejects with a
/// message when the canvas is missing or WebGPU cannot be initialised.
#[wasm_bindgen]
pub async fn start(canvas_id: String) -> Result<(), JsValue> {
    page_status::set(&PageStatus::Loading);
    report_panics_in_the_page();
    let result = run(&canvas_id).await;
    if let Err(e) = &result {
        page_status::set(&PageStatus::Error {
            message: browser::js_error_text(e),
        });
    }
    result
}

async fn run(canvas_id: &str) -> Result<(), JsValue> {
    let document = web_sys::window()
        .and_then(|w| w.document())
        .ok_or("no document: not running in a page")?;
    let canvas = document
        .get_element_by_id(canvas_id)
        .ok_or_else(|| format!("no element with id {canvas_id:?} in the page"))?
        .dyn_into::<web_sys::HtmlCanvasElement>()
        .map_err(|_| format!("element {canvas_id:?} is not a <canvas>"))?;
    // Read once: the app keeps them for the page's life (`index.html` reloads the page when
    // the address's fragment changes).
    let (options, errors) = PageOptions::parse(&browser::page_fragment());

    // The runner lives on in the event handlers it installs; this handle may go.
    eframe::WebRunner::new()
        .start(
            canvas,
            web_options(),
            Box::new(move |cc| -> Result<Box<dyn eframe::App>, _> {
                // `#bench=PRESET`: the page's training bench instead of the annotator.
                Ok(match options.bench {
                    Some(preset) => Box::new(BenchApp::new(cc, preset, &options)),
                    None => Box::new(App::new(cc, options, errors)),
                })
            }),
        )
        .await
}

/// After a panic the app no longer draws; say so in the page instead of leaving a frozen canvas.
/// eframe's own hook (installed by `WebRunner::new`, after this one) logs the stack and then
/// calls this one.
fn report_panics_in_the_page() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        page_status::set(&PageStatus::Crashed {
            message: info.to_string(),
        });
        previous(info);
    }));
}

fn web_options() -> eframe::WebOptions {
    let mut setup = WgpuSetupCreateNew::without_display_handle();
    // WebGPU only: the WebGL fallback could draw the UI but never train the field, and a page
    // that looks alive but cannot do its job is worse than a clear message (index.html).
    setup.instance_descriptor.backends = wgpu::Backends::BROWSER_WEBGPU;
    // The trainer shares this device, and its kernels size themselves to what the GPU allows,
    // so ask for everything the adapter offers rather than WebGPU's small defaults.
    setup.device_descriptor = Arc::new(|adapter| wgpu::DeviceDescriptor {
        label: Some("scribblefield device"),
        required_limits: adapter.limits(),
        ..Default::default()
    });
    let mut options = eframe::WebOptions::default();
    options.wgpu_options.wgpu_setup = WgpuSetup::CreateNew(setup);
    options
}
