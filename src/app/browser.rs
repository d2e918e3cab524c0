//! The few browser services the app uses, each wrapped once: clock and timers, local storage,
//! file download and file picking, and the page's address.
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

/// A failed browser call, with what was being done.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{what}: {detail}")]
pub struct BrowserError {
    pub what: String,
    pub detail: String,
}

impl BrowserError {
    fn new(what: &str, detail: impl Into<String>) -> BrowserError {
        BrowserError {
            what: what.into(),
            detail: detail.into(),
        }
    }

    fn js(what: &str, value: &JsValue) -> BrowserError {
        BrowserError::new(what, js_error_text(value))
    }
}

/// The readable text of a JS exception or rejection value.
pub fn js_error_text(value: &JsValue) -> String {
    if let Some(error) = value.dyn_ref::<js_sys::Error>() {
        return String::from(error.message());
    }
    value.as_string().unwrap_or_else(|| format!("{value:?}"))
}

/// Milliseconds on the page's monotonic clock.
pub fn now_ms() -> f64 {
    web_sys::window()
        .and_then(|w| w.performance())
        .map(|p| p.now())
        .unwrap_or_else(js_sys::Date::now)
}

/// Milliseconds since the Unix epoch.
pub fn wall_clock_ms() -> f64 {
    js_sys::Date::now()
}

/// Yields to the browser for `ms` milliseconds (0: just let it run its event loop once).
pub async fn sleep_ms(ms: i32) {
    crate::pause::sleep_ms(ms.max(0) as u32).await;
}

/// Resolves at the browser's next animation frame (at once where there is no window).
pub async fn next_animation_frame() {
    let Some(window) = web_sys::window() else {
        return;
    };
    let (done, fired) = futures_channel::oneshot::channel::<()>();
    let callback = wasm_bindgen::closure::Closure::once_into_js(move |_time: f64| {
        let _ = done.send(());
    });
    if window
        .request_animation_frame(wasm_bindgen::JsCast::unchecked_ref(&callback))
        .is_ok()
    {
        let _ = fired.await;
    }
}

fn local_storage() -> Result<web_sys::Storage, BrowserError> {
    let what = "browser storage";
    web_sys::window()
        .ok_or_else(|| BrowserError::new(what, "no window"))?
        .local_storage()
        .map_err(|e| BrowserError::js(what, &e))?
        .ok_or_else(|| BrowserError::new(what, "this browser offers no local storage (private mode?)"))
}

/// The stored text under `key`, if any.
pub fn storage_get(key: &str) -> Result<Option<String>, BrowserError> {
    local_storage()?
        .get_item(key)
        .map_err(|e| BrowserError::js("reading browser storage", &e))
}

/// Stores `value` under `key`; fails when the storage is full (about 5 MB per site).
pub fn storage_set(key: &str, value: &str) -> Result<(), BrowserError> {
    local_storage()?
        .set_item(key, value)
        .map_err(|e| BrowserError::js("writing browser storage", &e))
}

pub fn storage_remove(key: &str) -> Result<(), BrowserError> {
    local_storage()?
        .remove_item(key)
        .map_err(|e| BrowserError::js("clearing browser storage", &e))
}

/// Offers `bytes` as a download named `file_name`.
pub fn download(bytes: &[u8], file_name: &str, mime: &str) -> Result<(), BrowserError> {
    let what = "preparing the download";
    let js = |e: JsValue| BrowserError::js(what, &e);
    let array = js_sys::Uint8Array::from(bytes);
    let parts = js_sys::Array::of1(&array);
    let options = web_sys::BlobPropertyBag::new();
    options.set_type(mime);
    let blob = web_sys::Blob::new_with_u8_array_sequence_and_options(&parts, &options).map_err(js)?;
    let url = web_sys::Url::create_object_url_with_blob(&blob).map_err(js)?;
    let document = web_sys::window()
        .and_then(|w| w.document())
        .ok_or_else(|| BrowserError::new(what, "no document"))?;
    let anchor: web_sys::HtmlAnchorElement = document.create_element("a").map_err(js)?.unchecked_into();
    anchor.set_href(&url);
    anchor.set_download(file_name);
    anchor.click();
    // The click has started the download; the browser keeps what it needs. Revoke later so a
    // slow browser still finds the URL.
    gloo::timers::callback::Timeout::new(60_000, move || {
        let _ = web_sys::Url::revoke_object_url(&url);
    })
    .forget();
    Ok(())
}

/// Refuses a file larger than `max_bytes` before any of it is copied into the page's memory.
pub fn check_file_size(file: &web_sys::File, max_bytes: u64) -> Result<(), BrowserError> {
    let size = file.size();
    if size > max_bytes as f64 {
        return Err(BrowserError::new(
            &format!("{} is {} bytes", file.name(), size as u64),
            format!("more than this page opens ({max_bytes} bytes at most; docs/limits.md)"),
        ));
    }
    Ok(())
}

/// Asks the user for a file (`accept`: e.g. ".zip,application/zip") and reads it, unless it is
/// larger than `max_bytes`. `None` when the user cancels.
pub async fn pick_file(accept: &str, max_bytes: u64) -> Result<Option<(String, Vec<u8>)>, BrowserError> {
    let what = "opening a file";
    let js = |e: JsValue| BrowserError::js(what, &e);
    let document = web_sys::window()
        .and_then(|w| w.document())
        .ok_or_else(|| BrowserError::new(what, "no document"))?;
    let input: web_sys::HtmlInputElement = document.create_element("input").map_err(js)?.unchecked_into();
    input.set_type("file");
    input.set_accept(accept);
    // Resolves with the file list on "change", or null on "cancel" (the dialog was closed).
    let chosen = js_sys::Promise::new(&mut |resolve, _reject| {
        let on_change = {
            let resolve = resolve.clone();
            let input = input.clone();
            Closure::once_into_js(move || {
                let _ = resolve.call1(
                    &JsValue::NULL,
                    &input.files().map(JsValue::from).unwrap_or(JsValue::NULL),
                );
            })
        };
        let on_cancel = Closure::once_into_js(move || {
            let _ = resolve.call1(&JsValue::NULL, &JsValue::NULL);
        });
        let _ = input.add_event_listener_with_callback("change", on_change.unchecked_ref());
        let _ = input.add_event_listener_with_callback("cancel", on_cancel.unchecked_ref());
    });
    input.click();
    let files = JsFuture::from(chosen).await.map_err(js)?;
    let Some(file) = files.dyn_into::<web_sys::FileList>().ok().and_then(|list| list.get(0)) else {
        return Ok(None);
    };
    check_file_size(&file, max_bytes)?;
    let buffer = JsFuture::from(file.array_buffer()).await.map_err(js)?;
    Ok(Some((file.name(), js_sys::Uint8Array::new(&buffer).to_vec())))
}

/// The page's fragment (with its `#`), or "".
pub fn page_fragment() -> String {
    web_sys::window()
        .and_then(|w| w.location().hash().ok())
        .unwrap_or_default()
}

/// The page's address without the fragment.
pub fn page_address() -> String {
    let href = web_sys::window()
        .and_then(|w| w.location().href().ok())
        .unwrap_or_default();
    href.split('#').next().unwrap_or_default().to_string()
}

/// `url` resolved against the page's address (a share link must work from anywhere).
pub fn absolute_url(url: &str) -> String {
    web_sys::Url::new_with_base(url, &page_address())
        .map(|u| u.href())
        .unwrap_or_else(|_| url.to_string())
}

/// Replaces the page's fragment without reloading or adding a history entry (a plain
/// `location.hash = ...` would fire `hashchange`, which reloads the page).
pub fn replace_fragment(fragment: &str) {
    let Some(window) = web_sys::window() else { return };
    let Ok(history) = window.history() else { return };
    let url = format!("{}#{fragment}", page_address());
    let _ = history.replace_state_with_url(&JsValue::NULL, "", Some(&url));
}

/// A capture folder's files, each with its path from the folder's parent (the folder's name
/// first: `capture/images/0001.jpg`), as a browser hands them over.
pub type FolderFiles = Vec<(String, web_sys::File)>;

/// `index.html`'s hidden folder input (`<input type=file webkitdirectory>`), which the *pack
/// capture folder…* button clicks and scripts can set files on.
pub const FOLDER_INPUT_ID: &str = "capture-folder";

/// The event `index.html` sends when a folder is dropped on the page: browsers hand a dropped
/// folder over only as an entry to walk (`DataTransferItem.webkitGetAsEntry`), which the page's
/// script does before the app sees the drop; its `detail` is `[[path, File], ...]`, or
/// `{error: text}` when the walk failed.
const FOLDER_DROP_EVENT: &str = "scribblefield-folder";

/// Calls `on_folder` with the files of each folder the user picks with the folder input or drops
/// on the page, for as long as the page lives.
pub fn on_capture_folder(on_folder: impl Fn(Result<FolderFiles, String>) + 'static) -> Result<(), BrowserError> {
    let what = "the capture folder input";
    let js = |e: JsValue| BrowserError::js(what, &e);
    let window = web_sys::window().ok_or_else(|| BrowserError::new(what, "no window"))?;
    let input = folder_input()?;
    let on_folder = std::rc::Rc::new(on_folder);
    let picked = {
        let (input, on_folder) = (input.clone(), on_folder.clone());
        Closure::<dyn FnMut()>::new(move || {
            let mut files = Vec::new();
            if let Some(list) = input.files() {
                for i in 0..list.length() {
                    let Some(file) = list.get(i) else { continue };
                    let path = js_sys::Reflect::get(&file, &JsValue::from_str("webkitRelativePath"))
                        .ok()
                        .and_then(|p| p.as_string())
                        .filter(|p| !p.is_empty())
                        .unwrap_or_else(|| file.name());
                    files.push((path, file));
                }
            }
            // Picking the same folder again must fire "change" again.
            input.set_value("");
            if !files.is_empty() {
                on_folder(Ok(files));
            }
        })
    };
    input
        .add_event_listener_with_callback("change", picked.as_ref().unchecked_ref())
        .map_err(js)?;
    // Both listeners live as long as the page.
    picked.forget();
    let dropped = Closure::<dyn FnMut(web_sys::Event)>::new(move |event: web_sys::Event| {
        let detail = js_sys::Reflect::get(&event, &JsValue::from_str("detail")).unwrap_or(JsValue::UNDEFINED);
        if let Some(pairs) = detail.dyn_ref::<js_sys::Array>() {
            let files = pairs
                .iter()
                .filter_map(|pair| {
                    let pair = pair.dyn_into::<js_sys::Array>().ok()?;
                    Some((pair.get(0).as_string()?, pair.get(1).dyn_into::<web_sys::File>().ok()?))
                })
                .collect();
            on_folder(Ok(files));
        } else {
            let error = js_sys::Reflect::get(&detail, &JsValue::from_str("error")).unwrap_or(JsValue::UNDEFINED);
            on_folder(Err(js_error_text(&error)));
        }
    });
    window
        .add_event_listener_with_callback(FOLDER_DROP_EVENT, dropped.as_ref().unchecked_ref())
        .map_err(js)?;
    dropped.forget();
    Ok(())
}

/// Opens the browser's folder dialog; what is chosen arrives through [`on_capture_folder`].
pub fn pick_capture_folder() -> Result<(), BrowserError> {
    folder_input()?.click();
    Ok(())
}

fn folder_input() -> Result<web_sys::HtmlInputElement, BrowserError> {
    let what = "the capture folder input";
    web_sys::window()
        .and_then(|w| w.document())
        .and_then(|d| d.get_element_by_id(FOLDER_INPUT_ID))
        .ok_or_else(|| BrowserError::new(what, format!("no element #{FOLDER_INPUT_ID} in the page")))?
        .dyn_into::<web_sys::HtmlInputElement>()
        .map_err(|_| BrowserError::new(what, format!("#{FOLDER_INPUT_ID} is not an <input>")))
}
