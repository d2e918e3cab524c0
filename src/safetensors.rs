//! A minimal reader of the safetensors format: an 8-byte little-endian header length, a JSON
//! header `{name: {"dtype", "shape", "data_offsets": [begin, end]}, "__metadata__"?: {..}}` and
//! the raw little-endian tensor bytes (offsets are relative to the end of the header).
//! Only `F32` tensors are read; other dtypes are listed (their byte sizes checked) but not decoded.
//! The `__metadata__` map (strings to strings, as the format specifies) is kept.
//!
//! Written here rather than taken from the `safetensors` crate because every error must name the
//! file and the tensor it is about. Used by the feature extractors' weights (`features`) and the
//! trainer's checkpoints (`saved_field`), hence at the bottom of the module layers.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// What went wrong reading a safetensors file; both variants name the file.
#[derive(Debug, thiserror::Error)]
pub enum SafeTensorsError {
    /// The content is not a (usable) safetensors file, or lacks what was asked for.
    #[error("{file}: {problem}")]
    Invalid { file: String, problem: String },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

impl SafeTensorsError {
    pub fn invalid(file: impl Into<String>, problem: impl Into<String>) -> Self {
        SafeTensorsError::Invalid {
            file: file.into(),
            problem: problem.into(),
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct TensorInfo {
    pub dtype: String,
    pub shape: Vec<usize>,
    /// Byte range in the data section.
    pub begin: usize,
    pub end: usize,
}

/// A whole safetensors file in memory (the weights this crate reads are tens of MB).
pub struct SafeTensors {
    /// The file's name as given, for error messages.
    file: String,
    tensors: BTreeMap<String, TensorInfo>,
    metadata: BTreeMap<String, String>,
    data: Vec<u8>,
}

/// Largest safetensors file read (a regular file only): the weights read here are tens of MB,
/// a trainer checkpoint at most `saved_field::MAX_FILE_BYTES`.
const MAX_FILE_BYTES: u64 = 2 << 30;

fn dtype_size(dtype: &str) -> Option<usize> {
    Some(match dtype {
        "BOOL" | "U8" | "I8" | "F8_E4M3" | "F8_E5M2" => 1,
        "I16" | "U16" | "F16" | "BF16" => 2,
        "I32" | "U32" | "F32" => 4,
        "I64" | "U64" | "F64" => 8,
        _ => return None,
    })
}

/// Tensors must not share bytes (the format's own rule): a file whose tensors all point at one
/// range would decode to many times its size.
fn check_no_overlap(tensors: &BTreeMap<String, TensorInfo>) -> Result<(), String> {
    let mut ranges: Vec<(&str, &TensorInfo)> = tensors
        .iter()
        .filter(|(_, t)| t.end > t.begin)
        .map(|(n, t)| (n.as_str(), t))
        .collect();
    ranges.sort_by_key(|(_, t)| t.begin);
    for pair in ranges.windows(2) {
        let ((a, ta), (b, tb)) = (pair[0], pair[1]);
        if tb.begin < ta.end {
            return Err(format!(
                "tensors `{a}` (data_offsets [{}, {}]) and `{b}` ([{}, {}]) overlap; each tensor has bytes of its own",
                ta.begin, ta.end, tb.begin, tb.end
            ));
        }
    }
    Ok(())
}

impl SafeTensors {
    pub fn open(path: &Path) -> Result<Self, SafeTensorsError> {
        let bytes =
            crate::bounded_read::read_regular_file(path, MAX_FILE_BYTES).map_err(|source| SafeTensorsError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        Self::from_bytes(path.display().to_string(), bytes)
    }

    /// Parses `bytes` (the content of a file named `file` in messages).
    pub fn from_bytes(file: impl Into<String>, mut bytes: Vec<u8>) -> Result<Self, SafeTensorsError> {
        let file = file.into();
        let bad = |problem: String| SafeTensorsError::invalid(file.clone(), problem);
        if bytes.len() < 8 {
            return Err(bad(format!(
                "not a safetensors file: {} bytes, shorter than the 8-byte header length (truncated?)",
                bytes.len()
            )));
        }
        let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap());
        let available = bytes.len() as u64 - 8;
        if header_len > available {
            return Err(bad(format!(
                "safetensors header says {header_len} header bytes but the file has only {available} after the \
                 length (truncated, or not a safetensors file)"
            )));
        }
        let header_end = 8 + header_len as usize;
        let header: serde_json::Value = serde_json::from_slice(&bytes[8..header_end])
            .map_err(|e| bad(format!("safetensors header is not valid JSON: {e}")))?;
        let serde_json::Value::Object(entries) = header else {
            return Err(bad("safetensors header is not a JSON object".into()));
        };
        let data_len = bytes.len() - header_end;
        let mut tensors = BTreeMap::new();
        let mut metadata = BTreeMap::new();
        for (name, entry) in entries {
            if name == "__metadata__" {
                let serde_json::Value::Object(map) = entry else {
                    return Err(bad(
                        "`__metadata__` in the safetensors header is not a JSON object".into()
                    ));
                };
                for (key, value) in map {
                    let serde_json::Value::String(value) = value else {
                        return Err(bad(format!(
                            "`__metadata__` entry `{key}` is not a string (the format allows strings only)"
                        )));
                    };
                    metadata.insert(key, value);
                }
                continue;
            }
            let bad_entry = |what: &str| bad(format!("tensor `{name}`: {what} in the safetensors header"));
            let dtype = entry
                .get("dtype")
                .and_then(|d| d.as_str())
                .ok_or_else(|| bad_entry("no string `dtype`"))?
                .to_string();
            let shape = entry
                .get("shape")
                .and_then(|s| s.as_array())
                .ok_or_else(|| bad_entry("no array `shape`"))?
                .iter()
                .map(|d| d.as_u64().and_then(|d| usize::try_from(d).ok()))
                .collect::<Option<Vec<_>>>()
                .ok_or_else(|| bad_entry("a `shape` that is not a list of non-negative integers that fit in memory"))?;
            let offsets = entry
                .get("data_offsets")
                .and_then(|o| o.as_array())
                .filter(|o| o.len() == 2)
                .and_then(|o| Some((o[0].as_u64()?, o[1].as_u64()?)))
                .ok_or_else(|| bad_entry("no `data_offsets` [begin, end]"))?;
            // Compared as u64 before any conversion: a 32-bit target must not truncate them.
            let (begin, end) = offsets;
            if begin > end || end > data_len as u64 {
                return Err(bad(format!(
                    "tensor `{name}`: data_offsets [{begin}, {end}] outside the {data_len} data bytes (truncated file?)"
                )));
            }
            let (begin, end) = (begin as usize, end as usize);
            let size = dtype_size(&dtype).ok_or_else(|| bad_entry(&format!("unknown dtype `{dtype}`")))?;
            // The shape is the file's: its product is checked so a huge shape cannot wrap to a
            // size that happens to match the offsets.
            let bytes_needed = shape.iter().try_fold(size, |n, &d| n.checked_mul(d)).ok_or_else(|| {
                bad(format!(
                    "tensor `{name}`: shape {shape:?} of {dtype} has more bytes than this machine can address"
                ))
            })?;
            if bytes_needed != end - begin {
                return Err(bad(format!(
                    "tensor `{name}`: shape {shape:?} of {dtype} needs {bytes_needed} bytes but data_offsets span {}",
                    end - begin
                )));
            }
            tensors.insert(
                name,
                TensorInfo {
                    dtype,
                    shape,
                    begin,
                    end,
                },
            );
        }
        check_no_overlap(&tensors).map_err(bad)?;
        bytes.drain(..header_end);
        Ok(SafeTensors {
            file,
            tensors,
            metadata,
            data: bytes,
        })
    }

    pub fn file(&self) -> &str {
        &self.file
    }

    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(|k| k.as_str())
    }

    pub fn info(&self, name: &str) -> Option<&TensorInfo> {
        self.tensors.get(name)
    }

    /// The header's `__metadata__` (empty when it has none).
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }

    /// The F32 tensor `name`, which must have shape `shape`.
    pub fn f32(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, SafeTensorsError> {
        let info = self.tensors.get(name).ok_or_else(|| {
            SafeTensorsError::invalid(
                self.file.clone(),
                format!("tensor `{name}` missing ({} tensors in the file)", self.tensors.len()),
            )
        })?;
        if info.dtype != "F32" {
            return Err(SafeTensorsError::invalid(
                self.file.clone(),
                format!("tensor `{name}` is {}, expected F32", info.dtype),
            ));
        }
        if info.shape != shape {
            return Err(SafeTensorsError::invalid(
                self.file.clone(),
                format!("tensor `{name}` has shape {:?}, expected {shape:?}", info.shape),
            ));
        }
        Ok(self.data[info.begin..info.end]
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect())
    }
}

/// Serialises F32 tensors as a safetensors file (for tests and small tools).
pub fn to_bytes(tensors: &[(&str, &[usize], &[f32])]) -> Vec<u8> {
    to_bytes_with_metadata(tensors, &BTreeMap::new())
}

/// Serialises F32 tensors, in the order given, with `metadata` as the header's `__metadata__`
/// (left out when empty).
pub fn to_bytes_with_metadata(tensors: &[(&str, &[usize], &[f32])], metadata: &BTreeMap<String, String>) -> Vec<u8> {
    let mut header = serde_json::Map::new();
    if !metadata.is_empty() {
        header.insert("__metadata__".into(), serde_json::json!(metadata));
    }
    let mut data = Vec::with_capacity(tensors.iter().map(|t| 4 * t.2.len()).sum());
    for (name, shape, values) in tensors {
        let begin = data.len();
        for v in values.iter() {
            data.extend_from_slice(&v.to_le_bytes());
        }
        header.insert(
            name.to_string(),
            serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [begin, data.len()]}),
        );
    }
    let mut json = serde_json::to_vec(&serde_json::Value::Object(header)).unwrap();
    while !json.len().is_multiple_of(8) {
        json.push(b' ');
    }
    let mut out = (json.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(&json);
    out.extend_from_slice(&data);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<u8> {
        to_bytes(&[
            ("a.weight", &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, -6.5]),
            ("b", &[1], &[7.0]),
        ])
    }

    fn message(r: Result<impl Sized, SafeTensorsError>) -> String {
        match r {
            Ok(_) => panic!("expected an error"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn reads_f32_tensors_by_name_and_shape() {
        let st = SafeTensors::from_bytes("w.safetensors", sample()).unwrap();
        assert_eq!(
            st.f32("a.weight", &[2, 3]).unwrap(),
            vec![1.0, 2.0, 3.0, 4.0, 5.0, -6.5]
        );
        assert_eq!(st.f32("b", &[1]).unwrap(), vec![7.0]);
        assert_eq!(st.names().collect::<Vec<_>>(), vec!["a.weight", "b"]);
    }

    #[test]
    fn a_missing_tensor_or_a_wrong_shape_names_the_file_and_the_tensor() {
        let st = SafeTensors::from_bytes("w.safetensors", sample()).unwrap();
        let m = message(st.f32("c.bias", &[3]));
        assert!(m.contains("w.safetensors") && m.contains("`c.bias` missing"), "{m}");
        let m = message(st.f32("a.weight", &[3, 2]));
        assert!(
            m.contains("w.safetensors") && m.contains("`a.weight` has shape [2, 3], expected [3, 2]"),
            "{m}"
        );
    }

    #[test]
    fn a_truncated_file_or_a_bad_header_is_invalid_with_the_file_named() {
        let bytes = sample();
        let m = message(SafeTensors::from_bytes(
            "w.safetensors",
            bytes[..bytes.len() - 4].to_vec(),
        ));
        assert!(
            m.contains("w.safetensors") && m.contains("truncated") && m.contains("`b`"),
            "{m}"
        );
        let m = message(SafeTensors::from_bytes("w.safetensors", bytes[..20].to_vec()));
        assert!(m.contains("w.safetensors") && m.contains("truncated"), "{m}");
        let m = message(SafeTensors::from_bytes("w.safetensors", bytes[..5].to_vec()));
        assert!(m.contains("w.safetensors") && m.contains("truncated"), "{m}");
        let mut garbled = bytes.clone();
        garbled[8] = b'[';
        let m = message(SafeTensors::from_bytes("w.safetensors", garbled));
        assert!(m.contains("w.safetensors") && m.contains("not valid JSON"), "{m}");
    }

    #[test]
    fn metadata_round_trips_and_must_be_strings() {
        let meta = BTreeMap::from([
            ("format".to_string(), "x".to_string()),
            ("n".to_string(), "3".to_string()),
        ]);
        let bytes = to_bytes_with_metadata(&[("b", &[1], &[7.0])], &meta);
        let st = SafeTensors::from_bytes("m.safetensors", bytes).unwrap();
        assert_eq!(st.metadata(), &meta);
        assert_eq!(st.f32("b", &[1]).unwrap(), vec![7.0]);
        assert!(
            SafeTensors::from_bytes("w.safetensors", sample())
                .unwrap()
                .metadata()
                .is_empty()
        );
        let h = r#"{"__metadata__": {"n": 3}}"#;
        let m = message(SafeTensors::from_bytes("m.safetensors", with_header(h, 0)));
        assert!(
            m.contains("m.safetensors: `__metadata__` entry `n` is not a string"),
            "{m}"
        );
    }

    /// A file whose header is `header` (JSON) over `data_len` zero bytes.
    fn with_header(header: &str, data_len: usize) -> Vec<u8> {
        let mut out = (header.len() as u64).to_le_bytes().to_vec();
        out.extend_from_slice(header.as_bytes());
        out.resize(out.len() + data_len, 0);
        out
    }

    #[test]
    fn a_shape_whose_size_overflows_is_refused_with_the_tensor_and_shape_named() {
        // 2^62 * 4 bytes wraps to 0 without a checked product, matching empty offsets.
        let h = r#"{"w": {"dtype": "F32", "shape": [4611686018427387904], "data_offsets": [0, 0]}}"#;
        let m = message(SafeTensors::from_bytes("w.safetensors", with_header(h, 0)));
        assert!(
            m.contains("w.safetensors: tensor `w`: shape [4611686018427387904] of F32 has more bytes"),
            "{m}"
        );
        // (2^63 + 1) * 2 wraps to 2: one F8 of 2 bytes would match.
        let h = r#"{"w": {"dtype": "U8", "shape": [9223372036854775809, 2], "data_offsets": [0, 2]}}"#;
        let m = message(SafeTensors::from_bytes("w.safetensors", with_header(h, 2)));
        assert!(
            m.contains("tensor `w`") && m.contains("more bytes than this machine"),
            "{m}"
        );
    }

    #[test]
    fn offsets_outside_the_data_are_refused_with_the_tensor_and_offsets_named() {
        let h =
            r#"{"w": {"dtype": "F32", "shape": [1], "data_offsets": [18446744073709551612, 18446744073709551615]}}"#;
        let m = message(SafeTensors::from_bytes("w.safetensors", with_header(h, 4)));
        assert!(
            m.contains(
                "tensor `w`: data_offsets [18446744073709551612, 18446744073709551615] outside the 4 data bytes"
            ),
            "{m}"
        );
        let h = r#"{"w": {"dtype": "F32", "shape": [1], "data_offsets": [4, 0]}}"#;
        let m = message(SafeTensors::from_bytes("w.safetensors", with_header(h, 4)));
        assert!(m.contains("tensor `w`: data_offsets [4, 0] outside"), "{m}");
        let h = r#"{"w": {"dtype": "F32", "shape": [2], "data_offsets": [0, 4]}}"#;
        let m = message(SafeTensors::from_bytes("w.safetensors", with_header(h, 4)));
        assert!(
            m.contains("tensor `w`: shape [2] of F32 needs 8 bytes but data_offsets span 4"),
            "{m}"
        );
    }
}
