//! PyTorch checkpoints (`.pth`, `.pt`) as `torch.save` writes them since PyTorch 1.6: a zip
//! archive with one folder (`archive/`, or the file's stem) holding `data.pkl` (the pickled
//! object, see [`super::pickle`]), `data/<key>` (one raw little-endian entry per storage),
//! `version` and, from newer writers, `byteorder`.
//!
//! The pickle must hold a state dict (name -> tensor), either at the top or under one of the keys
//! that training scripts use (`teacher`, `model`, `state_dict`, `student`); names lose a leading
//! `module.` (DistributedDataParallel) and `backbone.` (DINO's `MultiCropWrapper`). Tensors must
//! be contiguous; float32, float16, bfloat16 and float64 are read (as `f32`).
use std::collections::BTreeMap;
use std::io::{Read, Seek};
use std::path::Path;

use half::{bf16, f16};

use super::FeatureError;
use super::pickle::{self, Dtype, Pickle, TensorRef, Value};

/// Keys under which checkpoints nest the state dict, in the order they are tried: DINO's eval
/// scripts use the teacher by default.
const WRAPPER_KEYS: [&str; 4] = ["teacher", "model", "state_dict", "student"];
/// Name prefixes dropped from every tensor name.
const PREFIXES: [&str; 2] = ["module.", "backbone."];

/// A loaded state dict: each tensor's view and the bytes of every storage it uses.
pub struct Pth {
    file: String,
    /// Where the state dict was found, e.g. "under `teacher`", for messages.
    pub location: String,
    tensors: BTreeMap<String, TensorRef>,
    storages: BTreeMap<String, Vec<u8>>,
}

impl Pth {
    pub fn open(path: &Path) -> Result<Self, FeatureError> {
        let file = std::fs::File::open(path).map_err(|e| FeatureError::io(path, e))?;
        Self::from_reader(path.display().to_string(), std::io::BufReader::new(file))
    }

    pub fn from_bytes(file: impl Into<String>, bytes: Vec<u8>) -> Result<Self, FeatureError> {
        Self::from_reader(file.into(), std::io::Cursor::new(bytes))
    }

    fn from_reader<R: Read + Seek>(file: String, mut reader: R) -> Result<Self, FeatureError> {
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
        let mut read = |name: &str| -> Result<Option<Vec<u8>>, FeatureError> {
            let mut entry = match zip.by_name(name) {
                Ok(e) => e,
                Err(zip::result::ZipError::FileNotFound) => return Ok(None),
                Err(e) => return Err(bad(format!("entry `{name}`: {e}"))),
            };
            let mut buf = Vec::with_capacity(entry.size().min(1 << 30) as usize);
            entry
                .read_to_end(&mut buf)
                .map_err(|e| bad(format!("entry `{name}`: {e} (truncated file?)")))?;
            Ok(Some(buf))
        };
        if let Some(order) = read(&format!("{folder}byteorder"))?
            && order != b"little"
        {
            return Err(bad(format!(
                "byte order `{}`; only little-endian checkpoints are read",
                String::from_utf8_lossy(&order)
            )));
        }
        let pkl_bytes = read(&pkl)?.unwrap_or_default();
        let pickle = pickle::parse(&pkl_bytes).map_err(|e| bad(format!("{pkl} {e}")))?;
        let (location, tensors) = state_dict(&pickle).map_err(|p| bad(format!("{pkl}: {p}")))?;
        let mut storages = BTreeMap::new();
        for t in tensors.values() {
            let s = &t.storage;
            if storages.contains_key(&s.key) {
                continue;
            }
            let name = format!("{folder}data/{}", s.key);
            let bytes = read(&name)?.ok_or_else(|| bad(format!("storage entry `{name}` missing")))?;
            let want = s.numel.saturating_mul(s.dtype.size() as u64);
            if bytes.len() as u64 != want {
                return Err(bad(format!(
                    "storage `{name}` has {} bytes, but the pickle says {} {} values ({want} bytes); \
                     truncated or corrupt checkpoint",
                    bytes.len(),
                    s.numel,
                    s.dtype.name()
                )));
            }
            storages.insert(s.key.clone(), bytes);
        }
        Ok(Pth {
            file,
            location,
            tensors,
            storages,
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
        let numel: usize = t.shape.iter().product();
        let size = t.storage.dtype.size();
        let end = t.offset.saturating_add(numel as u64);
        if end > t.storage.numel {
            return Err(bad(format!(
                "runs past its storage `{}` (offset {} + {numel} values > {})",
                t.storage.key, t.offset, t.storage.numel
            )));
        }
        let bytes = &self.storages[&t.storage.key][t.offset as usize * size..end as usize * size];
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
            Dtype::Other(class, _) => {
                return Err(bad(format!(
                    "is {class}, not a floating-point tensor (float32, float16, bfloat16 or float64)"
                )));
            }
        })
    }
}

/// The tensors of the state dict in `p`, with where it was found.
fn state_dict(p: &Pickle) -> Result<(String, BTreeMap<String, TensorRef>), String> {
    let Some(Value::Dict(root)) = p.root else {
        return Err(format!("the checkpoint is not a dict but {:?}", p.root));
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
                        Value::Str(s) => s.clone(),
                        other => format!("{other:?}"),
                    })
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
        let mut short = name.as_str();
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
