//! Precomputed per-frame feature maps from `.npy` files (NumPy's format: magic, a header dict,
//! raw little-endian data), any dimension and resolution. Little-endian f2/f4/f8 arrays of shape
//! (H, W, C) or (C, H, W), C order.
use std::path::{Path, PathBuf};

use half::f16;

use super::{FeatureError, FeatureMap};

/// Axis order of the arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NpyLayout {
    /// (height, width, channels): what most dense-feature scripts save.
    Hwc,
    /// (channels, height, width): PyTorch's order.
    Chw,
}

/// Reads the feature map of one frame from an `.npy` file.
pub fn read_npy_map(path: &Path, layout: NpyLayout) -> Result<FeatureMap, FeatureError> {
    let bytes = std::fs::read(path).map_err(|e| FeatureError::io(path, e))?;
    parse_npy_map(&bytes, &path.display().to_string(), layout)
}

/// The file of frame `index` (named `source` in its capture) in `dir`: `<source>.npy` when it
/// exists, else `<index:05>.npy`.
pub fn npy_path_of_frame(dir: &Path, index: usize, source: Option<&str>) -> Result<PathBuf, FeatureError> {
    let by_index = dir.join(format!("{index:05}.npy"));
    let by_source = source.map(|s| dir.join(format!("{s}.npy")));
    if let Some(p) = &by_source
        && p.is_file()
    {
        return Ok(p.clone());
    }
    if by_index.is_file() {
        return Ok(by_index);
    }
    let tried = match by_source {
        Some(s) => format!("{} or {}", s.display(), by_index.display()),
        None => by_index.display().to_string(),
    };
    Err(FeatureError::Missing {
        what: format!("feature map of frame {index}"),
        path: dir.to_path_buf(),
        hint: format!("expected {tried} (one .npy per frame, shape (H, W, C) or with --npy-layout chw (C, H, W))"),
    })
}

pub fn parse_npy_map(bytes: &[u8], file: &str, layout: NpyLayout) -> Result<FeatureMap, FeatureError> {
    let bad = |p: String| FeatureError::invalid(file, p);
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("not a .npy file (no \\x93NUMPY magic)".into()));
    }
    let major = bytes[6];
    let (header_len, start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad(format!("unsupported .npy version {v}"))),
    };
    let header_end = start
        .checked_add(header_len)
        .ok_or_else(|| bad("truncated header".into()))?;
    let header = bytes
        .get(start..header_end)
        .ok_or_else(|| bad("truncated header".into()))?;
    let header = std::str::from_utf8(header).map_err(|_| bad("header is not text".into()))?;
    let descr = dict_value(header, "descr").ok_or_else(|| bad(format!("no 'descr' in header {header:?}")))?;
    let descr = descr.trim_matches(['\'', '"']);
    if dict_value(header, "fortran_order").is_some_and(|v| v.trim() == "True") {
        return Err(bad(
            "Fortran-ordered arrays are not supported; save with np.ascontiguousarray".into(),
        ));
    }
    let shape = dict_value(header, "shape").ok_or_else(|| bad(format!("no 'shape' in header {header:?}")))?;
    let dims: Vec<usize> = shape
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| bad(format!("shape {shape}: {s:?} is not a size")))
        })
        .collect::<Result<_, _>>()?;
    let [a, b, c] = dims[..] else {
        return Err(bad(format!(
            "shape {shape} has {} axes; a feature map needs 3",
            dims.len()
        )));
    };
    let (h, w, d) = match layout {
        NpyLayout::Hwc => (a, b, c),
        NpyLayout::Chw => (b, c, a),
    };
    if h == 0 || w == 0 || d == 0 {
        return Err(bad(format!("shape {shape} is empty")));
    }
    // The shape comes from the file: its product is checked so that a huge shape is refused
    // instead of wrapping to a small one (or overflowing an index later).
    let too_big = || bad(format!("shape {shape} has more elements than this machine can address"));
    let count = a.checked_mul(b).and_then(|n| n.checked_mul(c)).ok_or_else(too_big)?;
    // Frames are addressed with u32 sides elsewhere.
    if u32::try_from(h).is_err() || u32::try_from(w).is_err() || u32::try_from(d).is_err() {
        return Err(bad(format!(
            "shape {shape}: a side exceeds {} (the largest feature map side)",
            u32::MAX
        )));
    }
    let size = match descr {
        "<f4" => 4,
        "<f2" => 2,
        "<f8" => 8,
        other => {
            return Err(bad(format!(
                "dtype {other:?} is not supported (use little-endian float16, float32 or float64)"
            )));
        }
    };
    let needed = count.checked_mul(size).ok_or_else(too_big)?;
    let data = &bytes[header_end..];
    // Exactly the array's bytes: less is a truncated file, more is not what the header says.
    if data.len() != needed {
        let relation = if data.len() < needed {
            "needs more data than the file holds"
        } else {
            "is shorter than the file's data"
        };
        return Err(bad(format!(
            "shape {shape} of {descr} {relation}: {needed} bytes expected, {} present",
            data.len()
        )));
    }
    let values: Vec<f32> = match size {
        4 => decode::<4>(data, |c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
        2 => decode::<2>(data, |c| f16::from_le_bytes([c[0], c[1]]).to_f32()),
        _ => decode::<8>(data, |c| {
            f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]) as f32
        }),
    };
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(bad(format!("value {i} is {} (features must be finite)", values[i])));
    }
    let data = match layout {
        NpyLayout::Hwc => values,
        NpyLayout::Chw => {
            let mut out = vec![0.0; count];
            for ch in 0..d {
                for p in 0..h * w {
                    out[p * d + ch] = values[ch * h * w + p];
                }
            }
            out
        }
    };
    Ok(FeatureMap {
        height: h as u32,
        width: w as u32,
        dim: d as u32,
        data,
    })
}

fn decode<const N: usize>(data: &[u8], f: impl Fn(&[u8]) -> f32) -> Vec<f32> {
    data.chunks_exact(N).map(f).collect()
}

/// The text after `'key':` up to the next top-level comma (a tuple counts as one value).
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = &header[at + key.len() + 2..];
    let rest = rest.trim_start().strip_prefix(':')?.trim_start();
    let mut depth = 0;
    for (i, ch) in rest.char_indices() {
        match ch {
            '(' => depth += 1,
            ')' => {
                depth -= 1;
                if depth == 0 {
                    return Some(&rest[..=i]);
                }
            }
            ',' | '}' if depth == 0 => return Some(rest[..i].trim()),
            _ => {}
        }
    }
    None
}

/// Writes a C-order little-endian f32 `.npy` of `shape` (tests and tools make inputs with it).
pub fn write_npy_f32(shape: &[usize], values: &[f32]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    // Data starts on a 64-byte boundary, as NumPy writes it.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hwc_and_chw_files_give_the_same_map() {
        let hwc: Vec<f32> = (0..2 * 3 * 4).map(|v| v as f32).collect();
        let map = parse_npy_map(&write_npy_f32(&[2, 3, 4], &hwc), "a.npy", NpyLayout::Hwc).unwrap();
        assert_eq!((map.height, map.width, map.dim), (2, 3, 4));
        assert_eq!(map.data, hwc);
        let mut chw = vec![0.0; hwc.len()];
        for p in 0..6 {
            for c in 0..4 {
                chw[c * 6 + p] = hwc[p * 4 + c];
            }
        }
        let map2 = parse_npy_map(&write_npy_f32(&[4, 2, 3], &chw), "b.npy", NpyLayout::Chw).unwrap();
        assert_eq!(map2, map);
    }

    #[test]
    fn bad_files_are_named_with_their_problem() {
        let err = |bytes: &[u8]| parse_npy_map(bytes, "f.npy", NpyLayout::Hwc).unwrap_err().to_string();
        assert!(err(b"PK\x03\x04 not numpy").contains("f.npy: not a .npy file"));
        let two_axes = write_npy_f32(&[2, 3], &[0.0; 6]);
        assert!(err(&two_axes).contains("has 2 axes"), "{}", err(&two_axes));
        let mut short = write_npy_f32(&[2, 2, 2], &[1.0; 8]);
        short.truncate(short.len() - 4);
        assert!(err(&short).contains("needs more data"), "{}", err(&short));
        let mut nan = write_npy_f32(&[1, 1, 2], &[1.0, f32::NAN]);
        assert!(err(&nan).contains("value 1 is NaN"), "{}", err(&nan));
        let at = nan.iter().position(|&b| b == b'4').unwrap();
        nan[at] = b'1';
        assert!(err(&nan).contains("dtype \"<f1\" is not supported"), "{}", err(&nan));
    }

    /// A header claiming `shape` over a few bytes of data.
    fn with_shape(shape: &str) -> Vec<u8> {
        let header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}\n");
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&[0; 16]);
        out
    }

    #[test]
    fn huge_shapes_are_refused_not_wrapped() {
        for layout in [NpyLayout::Hwc, NpyLayout::Chw] {
            let err = |shape: &str| {
                parse_npy_map(&with_shape(shape), "f.npy", layout)
                    .unwrap_err()
                    .to_string()
            };
            // 2^32 * 2^32 overflows 64 bits.
            let e = err("(4294967296, 4294967296, 1)");
            assert!(e.contains("f.npy: shape (4294967296, 4294967296, 1)"), "{e}");
            assert!(
                e.contains("more elements than this machine can address") || e.contains("exceeds"),
                "{e}"
            );
            // (2^63 + 1) * 2 wraps to 2 without the check.
            let e = err("(9223372036854775809, 2, 1)");
            assert!(e.contains("more elements than this machine can address"), "{e}");
            // Fits usize, but the byte count (x4) does not.
            let e = err("(4611686018427387904, 1, 1)");
            assert!(e.contains("more elements") || e.contains("exceeds"), "{e}");
        }
    }

    #[test]
    fn data_must_match_the_shape_exactly() {
        let mut long = write_npy_f32(&[1, 1, 2], &[1.0, 2.0]);
        long.extend_from_slice(&[0; 4]);
        let e = parse_npy_map(&long, "f.npy", NpyLayout::Hwc).unwrap_err().to_string();
        assert!(
            e.contains("is shorter than the file's data: 8 bytes expected, 12 present"),
            "{e}"
        );
        let e = parse_npy_map(&with_shape("(2, 2, 2)"), "f.npy", NpyLayout::Hwc)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("needs more data than the file holds: 32 bytes expected, 16 present"),
            "{e}"
        );
    }

    #[test]
    fn frames_are_found_by_source_name_then_by_index() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("00001.npy"), b"x").unwrap();
        std::fs::write(dir.path().join("frame-a.npy"), b"x").unwrap();
        assert!(
            npy_path_of_frame(dir.path(), 0, Some("frame-a"))
                .unwrap()
                .ends_with("frame-a.npy")
        );
        assert!(
            npy_path_of_frame(dir.path(), 1, Some("other"))
                .unwrap()
                .ends_with("00001.npy")
        );
        let e = npy_path_of_frame(dir.path(), 2, None).unwrap_err().to_string();
        assert!(e.contains("feature map of frame 2") && e.contains("00002.npy"), "{e}");
    }
}
