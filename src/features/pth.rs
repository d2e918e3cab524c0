//! PyTorch checkpoints (`.pth`, `.pt`) as `torch.save` writes them since PyTorch 1.6: a zip
//! archive with one folder (`archive/`, or the file's stem) holding `data.pkl` (the pickled
//! object, see [`super::pickle`]), `data/<key>` (one raw little-endian entry per storage),
//! `version` and, from newer writers, `byteorder`.
//!
//! The pickle must hold a state dict (name -> tensor), either at the top or under one of the keys
//! that training scripts use (`teacher`, `model`, `state_dict`, `student`); names lose a leading
//! `module.` (DistributedDataParallel) and `backbone.` (DINO's `MultiCropWrapper`). Tensors must
//! be contiguous; float32, float16, bfloat16 and float64 are read (as `f32`).
use std::cell::{Cell, RefCell};
use std::collections::BTreeMap;
use std::io::{Read, Seek};
use std::path::Path;

use half::{bf16, f16};

use super::FeatureError;
pub use super::pickle::Limits as PickleLimits;
use super::pickle::{self, Dtype, Pickle, TensorRef, Value};

/// Keys under which checkpoints nest the state dict, in the order they are tried: DINO's eval
/// scripts use the teacher by default.
const WRAPPER_KEYS: [&str; 4] = ["teacher", "model", "state_dict", "student"];
/// Name prefixes dropped from every tensor name.
const PREFIXES: [&str; 2] = ["module.", "backbone."];
/// Keys of a dict listed in a message.
const MAX_KEYS_SHOWN: usize = 20;

/// What reading one checkpoint may cost. Every cap is on bytes actually read (through
/// `Read::take`), never on the size an entry declares, since a crafted zip can declare anything.
#[derive(Clone, Copy, Debug)]
pub struct PthLimits {
    /// `data.pkl`: a state dict's pickle is tens of KB, a training checkpoint's a few MB.
    pub pickle_bytes: u64,
    /// Storage bytes inflated over all tensors read: bounds the time a zip bomb can take. The
    /// largest model read here (DINOv2 ViT-B/14, 86 M parameters) needs 350 MB in float32.
    pub storage_bytes: u64,
    pub pickle: PickleLimits,
}

impl Default for PthLimits {
    fn default() -> Self {
        PthLimits {
            pickle_bytes: 64 << 20,
            storage_bytes: 2 << 30,
            pickle: PickleLimits::default(),
        }
    }
}

/// The zip archive, read from as tensors are asked for.
trait Source: Read + Seek {}
impl<T: Read + Seek> Source for T {}

/// A loaded state dict: each tensor's view, and the archive its storages are read from when a
/// tensor is asked for (only the bytes of that tensor are kept, so memory follows the model the
/// caller builds, not what the file claims).
pub struct Pth {
    file: String,
    /// Where the state dict was found, e.g. "under `teacher`", for messages.
    pub location: String,
    tensors: BTreeMap<String, TensorRef>,
    /// The folder of `data.pkl` (`archive/`), with its slash.
    folder: String,
    zip: RefCell<zip::ZipArchive<Box<dyn Source>>>,
    limits: PthLimits,
    /// Storage bytes inflated so far (see [`PthLimits::storage_bytes`]).
    inflated: Cell<u64>,
}

impl Pth {
    pub fn open(path: &Path) -> Result<Self, FeatureError> {
        Self::open_with(path, PthLimits::default())
    }

    /// [`Pth::open`] within `limits`.
    pub fn open_with(path: &Path, limits: PthLimits) -> Result<Self, FeatureError> {
        let file = std::fs::File::open(path).map_err(|e| FeatureError::io(path, e))?;
        Self::from_reader(
            path.display().to_string(),
            Box::new(std::io::BufReader::new(file)),
            limits,
        )
    }

    pub fn from_bytes(file: impl Into<String>, bytes: Vec<u8>) -> Result<Self, FeatureError> {
        Self::from_bytes_with(file, bytes, PthLimits::default())
    }

    /// [`Pth::from_bytes`] within `limits`.
    pub fn from_bytes_with(file: impl Into<String>, bytes: Vec<u8>, limits: PthLimits) -> Result<Self, FeatureError> {
        Self::from_reader(file.into(), Box::new(std::io::Cursor::new(bytes)), limits)
    }

    fn from_reader(file: String, mut reader: Box<dyn Source>, limits: PthLimits) -> Result<Self, FeatureError> {
        let bad = |problem: String| FeatureError::invalid(file.clone(), problem);
        let mut magic = [0u8; 2];
        let n = reader.read(&mut magic).map_err(|e| FeatureError::io(&file, e))?;
        if n == 2 && magic == [0x80, 0x02] {
            // The legacy format is a sequence of pickles with a magic number first.
            return Err(bad(
                "a PyTorch checkpoint in the legacy format (before PyTorch 1.6), which is not \
                 read here; re-save it with a newer torch.save, or convert it to safetensors"
                    .into(),
            ));
        }
        reader.rewind().map_err(|e| FeatureError::io(&file, e))?;
        let mut zip = zip::ZipArchive::new(reader).map_err(|e| {
            bad(format!(
                "not a PyTorch checkpoint (torch.save writes a zip archive): {e}"
            ))
        })?;
        let pkl = zip
            .file_names()
            .filter_map(|n| n.ok())
            .find(|n| n == "data.pkl" || n.ends_with("/data.pkl") && n.matches('/').count() == 1)
            .map(|n| n.into_owned())
            .ok_or_else(|| bad("a zip archive without `<folder>/data.pkl`: not a PyTorch checkpoint".into()))?;
        let folder = pkl.trim_end_matches("data.pkl").to_string();
        if let Some(order) = read_entry(&mut zip, &format!("{folder}byteorder"), 64, &bad)?
            && order != b"little"
        {
            return Err(bad(format!(
                "byte order `{}`; only little-endian checkpoints are read",
                String::from_utf8_lossy(&order)
            )));
        }
        let pkl_bytes = read_entry(&mut zip, &pkl, limits.pickle_bytes, &bad)?.unwrap_or_default();
        let pickle = pickle::parse_with(&pkl_bytes, limits.pickle).map_err(|e| bad(format!("{pkl} {e}")))?;
        drop(pkl_bytes);
        let (location, tensors) = state_dict(&pickle).map_err(|p| bad(format!("{pkl}: {p}")))?;
        drop(pickle);
        // Each storage is checked against its entry's declared size here, without reading it;
        // the bytes read later are checked again, since the declaration may lie.
        let mut seen: BTreeMap<&str, (&Dtype, u64)> = BTreeMap::new();
        for (name, t) in &tensors {
            let s = &t.storage;
            match seen.get(s.key.as_str()) {
                Some(&(dtype, numel)) if (dtype, numel) == (&s.dtype, s.numel) => continue,
                Some(&(dtype, numel)) => {
                    return Err(bad(format!(
                        "{pkl}: tensor `{name}` names storage `{}` as {} {} values, another tensor as {numel} {} \
                         values; one storage has one size and type",
                        s.key,
                        s.numel,
                        s.dtype.name(),
                        dtype.name()
                    )));
                }
                None => {}
            }
            seen.insert(&s.key, (&s.dtype, s.numel));
            let name = format!("{folder}data/{}", s.key);
            let declared = match zip.by_name(&name) {
                Ok(e) => e.size(),
                Err(zip::result::ZipError::FileNotFound) => {
                    return Err(bad(format!("storage entry `{name}` missing")));
                }
                Err(e) => return Err(bad(format!("entry `{name}`: {e}"))),
            };
            let want = storage_bytes(s);
            if declared != want {
                return Err(bad(format!(
                    "storage `{name}` has {declared} bytes, but the pickle says {} {} values ({want} bytes); \
                     truncated or corrupt checkpoint",
                    s.numel,
                    s.dtype.name()
                )));
            }
        }
        Ok(Pth {
            file,
            location,
            tensors,
            folder,
            zip: RefCell::new(zip),
            limits,
            inflated: Cell::new(0),
        })
    }

    pub fn file(&self) -> &str {
        &self.file
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(|k| k.as_str())
    }

    pub fn shape(&self, name: &str) -> Option<&[usize]> {
        self.tensors.get(name).map(|t| &t.shape[..])
    }

    /// The tensor `name` as `f32`, which must have shape `shape`.
    pub fn f32(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, FeatureError> {
        let bad = |problem: String| FeatureError::invalid(self.file.clone(), format!("tensor `{name}` {problem}"));
        let t = self.tensors.get(name).ok_or_else(|| {
            bad(format!(
                "missing ({} tensors in the state dict {})",
                self.tensors.len(),
                self.location
            ))
        })?;
        if t.shape != shape {
            return Err(bad(format!("has shape {:?}, expected {shape:?}", t.shape)));
        }
        // C-contiguous strides; a dimension of size 1 may have any stride.
        let mut expected = 1usize;
        for (&d, &s) in t.shape.iter().zip(&t.stride).rev() {
            if d != 1 && s != expected {
                return Err(bad(format!(
                    "is not contiguous (size {:?}, stride {:?}); save `tensor.contiguous()` instead",
                    t.shape, t.stride
                )));
            }
            expected *= d;
        }
        if let Dtype::Other(class, _) = &t.storage.dtype {
            return Err(bad(format!(
                "is {class}, not a floating-point tensor (float32, float16, bfloat16 or float64)"
            )));
        }
        let numel: usize = t.shape.iter().product();
        let size = t.storage.dtype.size();
        let end = t.offset.saturating_add(numel as u64);
        if end > t.storage.numel {
            return Err(bad(format!(
                "runs past its storage `{}` (offset {} + {numel} values > {})",
                t.storage.key, t.offset, t.storage.numel
            )));
        }
        let skip = t
            .offset
            .checked_mul(size as u64)
            .ok_or_else(|| bad(format!("has offset {}, past any storage", t.offset)))?;
        let bytes = self.read_storage(&t.storage, skip, numel * size)?;
        let bytes = &bytes[..];
        let le2 = |b: &[u8]| u16::from_le_bytes([b[0], b[1]]);
        Ok(match &t.storage.dtype {
            Dtype::F32 => bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")))
                .collect(),
            Dtype::F16 => bytes.chunks_exact(2).map(|b| f16::from_bits(le2(b)).to_f32()).collect(),
            Dtype::Bf16 => bytes
                .chunks_exact(2)
                .map(|b| bf16::from_bits(le2(b)).to_f32())
                .collect(),
            Dtype::F64 => bytes
                .chunks_exact(8)
                .map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes")) as f32)
                .collect(),
            // Refused above, before any byte was read.
            Dtype::Other(..) => Vec::new(),
        })
    }
}

/// Bytes of storage `s` as the pickle describes it.
fn storage_bytes(s: &pickle::StorageRef) -> u64 {
    s.numel.saturating_mul(s.dtype.size() as u64)
}

/// The whole entry `name`, read through a cap of `cap` bytes; `None` when there is none.
fn read_entry<R: Read + Seek>(
    zip: &mut zip::ZipArchive<R>,
    name: &str,
    cap: u64,
    bad: &dyn Fn(String) -> FeatureError,
) -> Result<Option<Vec<u8>>, FeatureError> {
    let entry = match zip.by_name(name) {
        Ok(e) => e,
        Err(zip::result::ZipError::FileNotFound) => return Ok(None),
        Err(e) => return Err(bad(format!("entry `{name}`: {e}"))),
    };
    let mut buf = Vec::with_capacity(entry.size().min(cap) as usize);
    entry
        .take(cap + 1)
        .read_to_end(&mut buf)
        .map_err(|e| bad(format!("entry `{name}`: {e} (truncated file?)")))?;
    if buf.len() as u64 > cap {
        return Err(bad(format!(
            "entry `{name}` inflates to more than {cap} bytes, more than a checkpoint's {name} holds"
        )));
    }
    Ok(Some(buf))
}

impl Pth {
    /// `len` bytes of storage `s` from byte `skip` on, inflated from its entry through a cap.
    fn read_storage(&self, s: &pickle::StorageRef, skip: u64, len: usize) -> Result<Vec<u8>, FeatureError> {
        let name = format!("{}data/{}", self.folder, s.key);
        let bad = |problem: String| FeatureError::invalid(self.file.clone(), format!("storage `{name}` {problem}"));
        let spent = self.inflated.get().saturating_add(skip).saturating_add(len as u64);
        if spent > self.limits.storage_bytes {
            return Err(bad(format!(
                "would take the tensors read past {} bytes in all, more than any model read here needs \
                 (a zip bomb, or a model this reader does not know)",
                self.limits.storage_bytes
            )));
        }
        self.inflated.set(spent);
        let mut zip = self.zip.borrow_mut();
        let mut entry = zip.by_name(&name).map_err(|e| bad(e.to_string()))?;
        let skipped = std::io::copy(&mut (&mut entry).take(skip), &mut std::io::sink())
            .map_err(|e| bad(format!("{e} (truncated file?)")))?;
        let mut buf = Vec::with_capacity(len);
        (&mut entry)
            .take(len as u64)
            .read_to_end(&mut buf)
            .map_err(|e| bad(format!("{e} (truncated file?)")))?;
        if skipped != skip || buf.len() != len {
            return Err(bad(format!(
                "ends after {} bytes, before byte {} that the tensor needs: truncated or corrupt checkpoint",
                skipped + buf.len() as u64,
                skip + len as u64
            )));
        }
        Ok(buf)
    }
}

/// The tensors of the state dict in `p`, with where it was found.
fn state_dict(p: &Pickle) -> Result<(String, BTreeMap<String, TensorRef>), String> {
    let Some(Value::Dict(root)) = p.root else {
        let what = p.root.as_ref().map_or("nothing".to_string(), pickle::brief);
        return Err(format!("the checkpoint is not a dict but {what}"));
    };
    let has_tensors = |d: usize| p.dicts[d].iter().any(|(_, v)| matches!(v, Value::Tensor(_)));
    let (location, dict) = if has_tensors(root) {
        ("at the top".to_string(), root)
    } else {
        WRAPPER_KEYS
            .iter()
            .find_map(|&k| match p.get(root, k) {
                Some(&Value::Dict(d)) if has_tensors(d) => Some((format!("under `{k}`"), d)),
                _ => None,
            })
            .ok_or_else(|| {
                let keys: Vec<String> = p.dicts[root]
                    .iter()
                    .map(|(k, _)| match k {
                        Value::Str(s) => s.chars().take(200).collect(),
                        other => pickle::brief(other),
                    })
                    .take(MAX_KEYS_SHOWN)
                    .collect();
                format!(
                    "no state dict: no tensors at the top nor under {} (keys: {})",
                    WRAPPER_KEYS.join(", "),
                    keys.join(", ")
                )
            })?
    };
    let mut tensors = BTreeMap::new();
    for (k, v) in &p.dicts[dict] {
        let (Value::Str(name), Value::Tensor(t)) = (k, v) else {
            // Non-tensor entries (e.g. a step counter) are not weights.
            continue;
        };
        let mut short: &str = name;
        for prefix in PREFIXES {
            short = short.strip_prefix(prefix).unwrap_or(short);
        }
        if tensors.insert(short.to_string(), (**t).clone()).is_some() {
            return Err(format!(
                "two tensors are named `{short}` once the prefixes {PREFIXES:?} are dropped"
            ));
        }
    }
    Ok((location, tensors))
}

#[cfg(test)]
#[path = "pth_tests.rs"]
mod tests;
