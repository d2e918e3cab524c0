//! One writer per scene across the browser's tabs, with the Web Locks API: the tab that holds
//! the lock `scribblefield/<content id>` saves; a later tab finds it taken, follows the
//! writer's saves read-only, and queues for the lock, so it becomes the writer when the first
//! tab closes. (web-sys has Web Locks only behind an unstable flag, so the calls go through
//! `Reflect`.) Without Web Locks (an old browser) every tab writes, as before.
use std::cell::{Cell, RefCell};
use std::rc::Rc;

use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// This tab holds the lock and saves.
    Writer,
    /// Another tab holds it: this one follows, read-only, and waits for the lock.
    Follower,
    /// The browser has no Web Locks: this tab saves without knowing of others.
    Unlocked,
}

/// The lock, held until this is dropped (or the page goes).
pub struct TabLock {
    pub role: Rc<Cell<Role>>,
    /// Set when a follower has just been granted the lock.
    pub granted: Rc<Cell<bool>>,
    release: Rc<RefCell<Option<js_sys::Function>>>,
    /// Dropped: a lock granted later is let go at once.
    dropped: Rc<Cell<bool>>,
}

impl Drop for TabLock {
    fn drop(&mut self) {
        self.dropped.set(true);
        if let Some(release) = self.release.borrow_mut().take() {
            let _ = release.call0(&JsValue::NULL);
        }
    }
}

fn locks() -> Option<JsValue> {
    let navigator = web_sys::window()?.navigator();
    let locks = js_sys::Reflect::get(&navigator, &"locks".into()).ok()?;
    (!locks.is_undefined() && !locks.is_null()).then_some(locks)
}

/// Calls `navigator.locks.request(name, options, callback)`.
fn request(locks: &JsValue, name: &str, if_available: bool, callback: &JsValue) -> Result<js_sys::Promise, JsValue> {
    let options = js_sys::Object::new();
    js_sys::Reflect::set(&options, &"ifAvailable".into(), &if_available.into())?;
    let request: js_sys::Function = js_sys::Reflect::get(locks, &"request".into())?.dyn_into()?;
    request
        .call3(locks, &name.into(), &options, callback)?
        .dyn_into::<js_sys::Promise>()
}

/// A promise that resolves only when `release` is called: returned from the lock's callback,
/// it keeps the lock held.
fn hold(release: &Rc<RefCell<Option<js_sys::Function>>>) -> js_sys::Promise {
    let release = release.clone();
    js_sys::Promise::new(&mut |resolve, _| {
        *release.borrow_mut() = Some(resolve);
    })
}

/// Claims the lock for `content_id`; resolves once it is known whether this tab writes.
pub async fn claim(content_id: &str) -> TabLock {
    let lock = TabLock {
        role: Rc::new(Cell::new(Role::Unlocked)),
        granted: Rc::new(Cell::new(false)),
        release: Rc::default(),
        dropped: Rc::default(),
    };
    let Some(locks) = locks() else { return lock };
    let name = format!("scribblefield/{content_id}");
    let (known_tx, known) = futures_channel::oneshot::channel::<()>();
    let first = {
        let (role, granted, release) = (lock.role.clone(), lock.granted.clone(), lock.release.clone());
        let dropped = lock.dropped.clone();
        let locks = locks.clone();
        let name = name.clone();
        Closure::once_into_js(move |held: JsValue| -> JsValue {
            if !held.is_null() {
                role.set(Role::Writer);
                let _ = known_tx.send(());
                return hold(&release).into();
            }
            role.set(Role::Follower);
            let _ = known_tx.send(());
            // Queue for the lock: granted when the writer's tab closes or opens another scene.
            let later = Closure::once_into_js(move |_held: JsValue| -> JsValue {
                if dropped.get() {
                    return JsValue::UNDEFINED;
                }
                granted.set(true);
                hold(&release).into()
            });
            let _ = request(&locks, &name, false, &later);
            JsValue::UNDEFINED
        })
    };
    match request(&locks, &name, true, &first) {
        Ok(promise) => {
            // The request's own promise settles only when the lock is released; errors go to
            // the console (the role stays what the callback set).
            wasm_bindgen_futures::spawn_local(async move {
                if let Err(e) = JsFuture::from(promise).await {
                    web_sys::console::warn_1(&e);
                }
            });
            let _ = known.await;
        }
        Err(e) => web_sys::console::warn_1(&e),
    }
    lock
}
