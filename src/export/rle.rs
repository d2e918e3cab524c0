//! Run-length encoding of binary masks exactly as pycocotools (`maskApi.c`) writes it, so that
//! `pycocotools.mask.decode` and every loader built on it read the COCO export: pixels are
//! visited column by column (Fortran order), runs alternate starting with a run of zeros (of
//! length 0 when the first pixel is set), and the compressed string form is pycocotools'
//! LEB128-like code of 5 bits per character offset by 48, where each run from the fourth on is
//! stored as its difference from the run two before it.
use super::error::ExportError;

/// The run lengths of `width x height` pixels for which `is_set(x, y)` holds, column-major,
/// starting with the run of unset pixels.
pub fn runs(width: u32, height: u32, mut is_set: impl FnMut(u32, u32) -> bool) -> Vec<u32> {
    let mut counts = Vec::new();
    let mut current = false;
    let mut run = 0u32;
    for x in 0..width {
        for y in 0..height {
            let set = is_set(x, y);
            if set != current {
                counts.push(run);
                run = 0;
                current = set;
            }
            run += 1;
        }
    }
    counts.push(run);
    counts
}

/// pycocotools' `rleToString`.
pub fn to_string(counts: &[u32]) -> String {
    let mut s = String::with_capacity(counts.len() * 2);
    for (i, &c) in counts.iter().enumerate() {
        let mut x = i64::from(c);
        // `i > 2`, not `i >= 2`: the third run is stored as it is, as pycocotools does.
        if i > 2 {
            x -= i64::from(counts[i - 2]);
        }
        loop {
            let mut c = (x & 0x1f) as u8;
            x >>= 5;
            let more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
            if more {
                c |= 0x20;
            }
            s.push(char::from(c + 48));
            if !more {
                break;
            }
        }
    }
    s
}

/// pycocotools' `rleFrString`: the runs of a compressed string (`at` names it in errors).
pub fn from_string(s: &str, at: &str) -> Result<Vec<u32>, ExportError> {
    let bad = |problem: String| ExportError::Rle {
        at: at.to_string(),
        problem,
    };
    let bytes = s.as_bytes();
    let mut counts: Vec<u32> = Vec::new();
    let mut p = 0;
    while p < bytes.len() {
        let mut x: i64 = 0;
        let mut k = 0u32;
        loop {
            let Some(&b) = bytes.get(p) else {
                return Err(bad(format!("the run code ends inside a number at character {p}")));
            };
            if !(48..48 + 64).contains(&b) {
                return Err(bad(format!(
                    "character {p} ({:?}) is not a run code character",
                    b as char
                )));
            }
            if k > 12 {
                return Err(bad(format!("the number ending at character {p} is too long")));
            }
            let c = i64::from(b - 48);
            x |= (c & 0x1f) << (5 * k);
            p += 1;
            k += 1;
            if c & 0x20 == 0 {
                if c & 0x10 != 0 {
                    x |= -1i64 << (5 * k);
                }
                break;
            }
        }
        if counts.len() > 2 {
            x += i64::from(counts[counts.len() - 2]);
        }
        let run = u32::try_from(x).map_err(|_| bad(format!("run {} decodes to {x}", counts.len())))?;
        counts.push(run);
    }
    Ok(counts)
}

/// The `width x height` mask (row-major, 1 = set) of column-major `counts`, checked to cover
/// every pixel exactly.
pub fn decode(counts: &[u32], width: u32, height: u32, at: &str) -> Result<Vec<u8>, ExportError> {
    let total = width as u64 * height as u64;
    let sum: u64 = counts.iter().map(|&c| u64::from(c)).sum();
    if sum != total {
        return Err(ExportError::Rle {
            at: at.to_string(),
            problem: format!("runs cover {sum} pixels, the image has {width} x {height} = {total}"),
        });
    }
    let mut mask = vec![0u8; total as usize];
    let mut k = 0u64;
    for (i, &c) in counts.iter().enumerate() {
        for _ in 0..c {
            if i % 2 == 1 {
                let (x, y) = (k / u64::from(height), k % u64::from(height));
                mask[(y * u64::from(width) + x) as usize] = 1;
            }
            k += 1;
        }
    }
    Ok(mask)
}

/// pycocotools' `toBbox` of the set pixels: `[x, y, width, height]`, all 0 when none is set.
pub fn bbox(width: u32, height: u32, mut is_set: impl FnMut(u32, u32) -> bool) -> [u32; 4] {
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
    for y in 0..height {
        for x in 0..width {
            if is_set(x, y) {
                x0 = x0.min(x);
                y0 = y0.min(y);
                x1 = x1.max(x);
                y1 = y1.max(y);
            }
        }
    }
    if x0 == u32::MAX {
        [0; 4]
    } else {
        [x0, y0, x1 - x0 + 1, y1 - y0 + 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Masks and the strings pycocotools 2.0.11 gives for them (`mask.encode` of the
    /// Fortran-ordered array; `toBbox`): a mask whose first pixel is set, long runs, negative
    /// differences, a run longer than 2^15, every pixel set and none.
    #[test]
    fn strings_match_pycocotools() {
        // 3 x 4 (w x h), rows 110 / 101 / 011 / 001; columns 1100, 1010, 0111.
        let rows = ["110", "101", "011", "001"];
        let set = |x: u32, y: u32| rows[y as usize].as_bytes()[x as usize] == b'1';
        let counts = runs(3, 4, set);
        assert_eq!(counts, [0, 2, 2, 1, 1, 1, 2, 3]);
        assert_eq!(to_string(&counts), "022OO012");
        assert_eq!(
            decode(&counts, 3, 4, "t").unwrap(),
            [1, 1, 0, 1, 0, 1, 0, 1, 1, 0, 0, 1]
        );
        assert_eq!(bbox(3, 4, set), [0, 0, 3, 4]);
        // 100 x 60: a 30 x 20 block at (40, 10) and a single pixel at (99, 59).
        let set = |x: u32, y: u32| ((40..70).contains(&x) && (10..30).contains(&y)) || (x, y) == (99, 59);
        let counts = runs(100, 60, set);
        let s = to_string(&counts);
        assert_eq!(
            s,
            "Z[2d0X1000000000000000000000000000000000000000000000000000000000mg1]O"
        );
        assert_eq!(from_string(&s, "t").unwrap(), counts);
        assert_eq!(bbox(100, 60, set), [40, 10, 60, 50]);
        // 300 x 300: the corners and a line down column 150.
        let set = |x: u32, y: u32| (x, y) == (0, 0) || (x, y) == (299, 299) || (x == 150 && (5..200).contains(&y));
        let counts = runs(300, 300, set);
        assert_eq!(to_string(&counts), "01\\n[1R6cInI");
        assert_eq!(from_string("01\\n[1R6cInI", "t").unwrap(), counts);
        assert_eq!(counts.iter().skip(1).step_by(2).sum::<u32>(), 197);
        assert_eq!(to_string(&runs(3, 4, |_, _| true)), "0<");
        assert_eq!(to_string(&runs(5, 5, |_, _| false)), "i0");
        assert_eq!(bbox(5, 5, |_, _| false), [0; 4]);
    }

    #[test]
    fn random_masks_round_trip() {
        let mut state = 12345u64;
        for trial in 0..200 {
            let (w, h) = (1 + trial % 17, 1 + (trial * 7) % 23);
            let bits: Vec<bool> = (0..w * h)
                .map(|_| {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    // Long and short runs: most pixels copy their neighbour.
                    (state >> 60) < 3
                })
                .scan(false, |prev, flip| {
                    *prev ^= flip;
                    Some(*prev)
                })
                .collect();
            let set = |x: u32, y: u32| bits[(y * w + x) as usize];
            let counts = runs(w, h, set);
            let back = from_string(&to_string(&counts), "t").unwrap();
            assert_eq!(back, counts);
            let mask = decode(&back, w, h, "t").unwrap();
            let want: Vec<u8> = bits.iter().map(|&b| u8::from(b)).collect();
            assert_eq!(mask, want);
        }
    }

    #[test]
    fn bad_strings_are_named() {
        let err = from_string("0 2", "coco.json annotation 3").unwrap_err().to_string();
        assert!(err.contains("annotation 3") && err.contains("character 1"), "{err}");
        let err = from_string("0b", "a").unwrap_err().to_string();
        assert!(err.contains("ends inside"), "{err}");
        let err = decode(&[1, 2], 2, 2, "a").unwrap_err().to_string();
        assert!(err.contains("3 pixels") && err.contains("2 x 2 = 4"), "{err}");
    }
}
