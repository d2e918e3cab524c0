//! IndexedDB, wrapped once: the database `scribblefield` with two object stores, `snapshots`
//! (each scene's last snapshots, string keys `<content id>/<seq>`) and `aside` (unreadable
//! records and legacy entries, moved there with "add", which never overwrites). Every write
//! waits for its transaction's `complete` event: only then is the data on disk.
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{IdbDatabase, IdbKeyRange, IdbObjectStore, IdbRequest, IdbTransaction, IdbTransactionMode};

use super::StoreError;

pub const DB_NAME: &str = "scribblefield";
pub const SNAPSHOTS: &str = "snapshots";
pub const ASIDE: &str = "aside";
const DB_VERSION: u32 = 1;

/// The text of a DOM exception or JS error (`QuotaExceededError: ...`).
fn describe(value: &JsValue) -> String {
    if let Some(e) = value.dyn_ref::<web_sys::DomException>() {
        return format!("{}: {}", e.name(), e.message());
    }
    super::super::browser::js_error_text(value)
}

fn failed(what: &str) -> impl Fn(JsValue) -> StoreError + '_ {
    move |e| StoreError::Failed {
        what: what.into(),
        detail: describe(&e),
    }
}

/// Resolves with the request's result, or rejects with its error.
async fn request(req: &IdbRequest) -> Result<JsValue, JsValue> {
    let promise = js_sys::Promise::new(&mut |resolve, reject| {
        let done = req.clone();
        let on_success = Closure::once_into_js(move || {
            let _ = resolve.call1(&JsValue::NULL, &done.result().unwrap_or(JsValue::UNDEFINED));
        });
        let errored = req.clone();
        let on_error = Closure::once_into_js(move || {
            let error = errored
                .error()
                .ok()
                .flatten()
                .map(JsValue::from)
                .unwrap_or(JsValue::NULL);
            let _ = reject.call1(&JsValue::NULL, &error);
        });
        req.set_onsuccess(Some(on_success.unchecked_ref()));
        req.set_onerror(Some(on_error.unchecked_ref()));
    });
    JsFuture::from(promise).await
}

/// Resolves when the transaction has committed; rejects when it aborts (quota, a failed
/// request, the page closing).
async fn committed(tx: &IdbTransaction) -> Result<(), JsValue> {
    let promise = js_sys::Promise::new(&mut |resolve, reject| {
        let on_complete = Closure::once_into_js(move || {
            let _ = resolve.call0(&JsValue::NULL);
        });
        let failing = tx.clone();
        let on_fail = Closure::once_into_js(move || {
            let error = failing
                .error()
                .map(JsValue::from)
                .unwrap_or_else(|| JsValue::from_str("the transaction was aborted"));
            let _ = reject.call1(&JsValue::NULL, &error);
        });
        tx.set_oncomplete(Some(on_complete.unchecked_ref()));
        // Abort follows error; whichever comes first rejects (a promise settles once).
        tx.set_onerror(Some(on_fail.unchecked_ref()));
        tx.set_onabort(Some(on_fail.unchecked_ref()));
    });
    JsFuture::from(promise).await.map(|_| ())
}

#[derive(Clone)]
pub struct Db(IdbDatabase);

/// Opens (creating or upgrading) the database.
pub async fn open() -> Result<Db, StoreError> {
    let what = "opening IndexedDB";
    let factory = web_sys::window()
        .ok_or(StoreError::Unavailable("no window".into()))?
        .indexed_db()
        .map_err(|e| StoreError::Unavailable(describe(&e)))?
        .ok_or(StoreError::Unavailable("this browser offers no IndexedDB".into()))?;
    let open = factory.open_with_u32(DB_NAME, DB_VERSION).map_err(failed(what))?;
    let upgrading = open.clone();
    let on_upgrade = Closure::once_into_js(move || {
        let Ok(db) = upgrading.result().map(IdbDatabase::unchecked_from_js) else {
            return;
        };
        let names = db.object_store_names();
        for name in [SNAPSHOTS, ASIDE] {
            if !names.contains(name) {
                let _ = db.create_object_store(name);
            }
        }
    });
    open.set_onupgradeneeded(Some(on_upgrade.unchecked_ref()));
    let db = request(&open).await.map_err(failed(what))?;
    Ok(Db(db.unchecked_into()))
}

fn range(lower: &str, upper: &str) -> Result<IdbKeyRange, StoreError> {
    IdbKeyRange::bound(&lower.into(), &upper.into()).map_err(failed("a key range"))
}

impl Db {
    fn transaction(&self, stores: &[&str], mode: IdbTransactionMode) -> Result<IdbTransaction, StoreError> {
        let names: js_sys::Array = stores.iter().map(|s| JsValue::from_str(s)).collect();
        self.0
            .transaction_with_str_sequence_and_mode(&names, mode)
            .map_err(failed("starting a transaction"))
    }

    fn store(tx: &IdbTransaction, name: &str) -> Result<IdbObjectStore, StoreError> {
        tx.object_store(name).map_err(failed("opening an object store"))
    }

    /// The entries of `store` with keys in `[lower, upper]`, in key order.
    pub async fn entries(&self, store: &str, lower: &str, upper: &str) -> Result<Vec<(String, JsValue)>, StoreError> {
        let what = "reading IndexedDB";
        let tx = self.transaction(&[store], IdbTransactionMode::Readonly)?;
        let s = Self::store(&tx, store)?;
        let r = range(lower, upper)?;
        let keys = s.get_all_keys_with_key(&r).map_err(failed(what))?;
        let values = s.get_all_with_key(&r).map_err(failed(what))?;
        let keys: js_sys::Array = request(&keys).await.map_err(failed(what))?.unchecked_into();
        let values: js_sys::Array = request(&values).await.map_err(failed(what))?.unchecked_into();
        Ok(keys
            .iter()
            .zip(values.iter())
            .map(|(k, v)| (k.as_string().unwrap_or_default(), v))
            .collect())
    }

    /// One value, if there.
    pub async fn get(&self, store: &str, key: &str) -> Result<Option<JsValue>, StoreError> {
        let what = "reading IndexedDB";
        let tx = self.transaction(&[store], IdbTransactionMode::Readonly)?;
        let req = Self::store(&tx, store)?.get(&key.into()).map_err(failed(what))?;
        let value = request(&req).await.map_err(failed(what))?;
        Ok((!value.is_undefined()).then_some(value))
    }

    /// Puts `puts` and deletes `deletes` in `snapshots`, all or nothing.
    pub async fn write_snapshots(&self, puts: &[(String, String)], deletes: &[String]) -> Result<(), StoreError> {
        let what = "saving to IndexedDB";
        let tx = self.transaction(&[SNAPSHOTS], IdbTransactionMode::Readwrite)?;
        let s = Self::store(&tx, SNAPSHOTS)?;
        let staged = (|| {
            for (key, value) in puts {
                s.put_with_key(&value.into(), &key.into())?;
            }
            for key in deletes {
                s.delete(&key.into())?;
            }
            Ok::<(), JsValue>(())
        })();
        if let Err(e) = staged {
            // Nothing of a half-staged write may land.
            let _ = tx.abort();
            return Err(failed(what)(e));
        }
        committed(&tx).await.map_err(failed(what))
    }

    /// Copies `value` to `aside` under `aside_key` (failing, not overwriting, if the key is
    /// taken) and, in the same transaction, deletes `from` in `snapshots`.
    pub async fn set_aside(&self, aside_key: &str, value: &JsValue, from: Option<&str>) -> Result<(), StoreError> {
        let what = "setting an unreadable save aside";
        let tx = self.transaction(&[SNAPSHOTS, ASIDE], IdbTransactionMode::Readwrite)?;
        let staged = (|| {
            Self::store(&tx, ASIDE)
                .map_err(|e| JsValue::from_str(&e.to_string()))?
                .add_with_key(value, &aside_key.into())?;
            if let Some(key) = from {
                Self::store(&tx, SNAPSHOTS)
                    .map_err(|e| JsValue::from_str(&e.to_string()))?
                    .delete(&key.into())?;
            }
            Ok::<(), JsValue>(())
        })();
        if let Err(e) = staged {
            let _ = tx.abort();
            return Err(failed(what)(e));
        }
        committed(&tx).await.map_err(failed(what))
    }
}
