//! Writes what scripts and tests read on `<body>`: the status (`data-status`, JSON: see
//! [`PageStatus`]), the latest share link, a lost GPU device, the `#profile` result, the page
//! bench (`#bench=`).
use std::cell::RefCell;

use super::status::PageStatus;

thread_local! {
    // Writing the DOM every frame is cheap but pointless; remember what is already there.
    static LAST: RefCell<String> = const { RefCell::new(String::new()) };
}

/// Sets `document.body.dataset.status` to `status` as JSON when it differs from what was last
/// set.
pub fn set(status: &PageStatus) {
    let status = status.to_json();
    let status = status.as_str();
    let unchanged = LAST.with(|last| match last.try_borrow_mut() {
        Ok(last) if *last == status => true,
        Ok(mut last) => {
            status.clone_into(&mut last);
            false
        }
        // Only when called re-entrantly from the panic hook: write through.
        Err(_) => false,
    });
    if unchanged {
        return;
    }
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        // Only fails for an invalid attribute name, and this one is a constant.
        let _ = body.set_attribute("data-status", status);
    }
}

/// Puts the latest share link on `<body data-share-link="...">`, for scripts and tests (the
/// clipboard is not readable from a headless browser).
pub fn set_share_link(link: &str) {
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        let _ = body.set_attribute("data-share-link", link);
    }
}

/// Marks the page's GPU device as lost on `<body data-gpu-lost="...">`: the canvas cannot draw
/// any more, so `index.html` says so over it (with the reason) instead of leaving it frozen.
pub fn set_gpu_lost(message: &str) {
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        let _ = body.set_attribute("data-gpu-lost", message);
    }
}

/// Puts the wall-clock profile of a training step (`#profile` in the address) on
/// `<body data-profile="...">`.
pub fn set_profile(text: &str) {
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        let _ = body.set_attribute("data-profile", text);
    }
}

/// Puts the page bench's state and, once done, its report (`#bench=` in the address,
/// `app::bench`; a JSON object) on `<body data-bench="...">`.
pub fn set_bench(json: &str) {
    if let Some(body) = web_sys::window().and_then(|w| w.document()).and_then(|d| d.body()) {
        let _ = body.set_attribute("data-bench", json);
    }
}
