//! The share-link codec: annotations packed small enough to ride in a URL fragment.
//!
//! A link is `<page>#scene=<scene url>&labels=<code>`. The code is base64url (no padding) of
//! raw DEFLATE of a compact binary form of the [`LabelSet`]:
//!
//! ```text
//! u8 version (1)
//! varint class count, per class: varint name length, UTF-8 name, r, g, b
//! varint frame count, per frame: varint frame index minus the previous one, varint strokes,
//!   per stroke: varint class + 1 (0 = eraser), varint radius in 1/8 px, varint points,
//!   per point: zigzag varint x and y in 1/8 px, the first absolute, the rest as deltas
//! ```
//!
//! Coordinates and radii are kept in eighths of a pixel: the annotator snaps what it records to
//! that grid ([`snap`]), so its labels round-trip exactly; other coordinates are rounded to it.
//! Decoding bounds the inflated size and every count, so a hostile link cannot exhaust memory.
use std::io::{Read, Write};

use base64::alphabet;
use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use base64::{DecodeError, Engine as _};
use flate2::Compression;
use flate2::read::DeflateDecoder;
use flate2::write::DeflateEncoder;

use super::limits::{MAX_POINTS_PER_STROKE, MAX_TOTAL_POINTS};
use super::{ClassInfo, FrameLabels, LabelSet, Stroke};
use crate::scene::label_set::check_stroke;

const CODE_VERSION: u8 = 1;
/// Steps per pixel of coordinates and radii in the code.
pub const SUBPIXEL: f32 = 8.0;
/// Largest inflated code accepted (a few hundred thousand points); more is surely not a link
/// anyone made by hand.
const MAX_INFLATED: u64 = 8 << 20;
/// Longest fragment we hand out as a link. Browsers take far longer URLs, but chat programs,
/// mail clients and URL shorteners cut or refuse them well before; past this, share a file.
pub const MAX_LINK_FRAGMENT: usize = 8000;

/// `v` on the code's grid of eighths of a pixel.
pub fn snap(v: f32) -> f32 {
    (v * SUBPIXEL).round() / SUBPIXEL
}

/// Why a share code or fragment could not be read or made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ShareError {
    #[error("the annotations in the link are damaged: {0}")]
    Corrupt(String),
    /// Well formed, but over one of the label limits (`format::limits`).
    #[error("the annotations in the link are over a limit: {0}")]
    Limit(String),
    #[error("the link was made by a newer version (annotation code version {0})")]
    Version(u8),
    #[error(
        "the annotations make a link of {length} characters, more than the {MAX_LINK_FRAGMENT} that \
         survive being pasted around; share the annotations file instead"
    )]
    TooLong { length: usize },
    #[error(
        "the scene was opened from a local file, which a link cannot point to; share the scene file and the annotations file"
    )]
    LocalScene,
}

fn corrupt(what: impl Into<String>) -> ShareError {
    ShareError::Corrupt(what.into())
}

/// Packs `labels` into a share code (base64url text).
pub fn encode_labels(labels: &LabelSet) -> String {
    let mut raw = vec![CODE_VERSION];
    put_varint(&mut raw, labels.classes.len() as u64);
    for c in &labels.classes {
        put_varint(&mut raw, c.name.len() as u64);
        raw.extend_from_slice(c.name.as_bytes());
        raw.extend_from_slice(&c.color);
    }
    let frames: Vec<&FrameLabels> = labels.frames.iter().filter(|f| !f.strokes.is_empty()).collect();
    put_varint(&mut raw, frames.len() as u64);
    let mut previous = 0u64;
    for f in frames {
        // Frames are sorted in a LabelSet; a wrapping difference keeps any order decodable.
        put_varint(&mut raw, u64::from(f.frame).wrapping_sub(previous) & 0xffff_ffff);
        previous = u64::from(f.frame);
        put_varint(&mut raw, f.strokes.len() as u64);
        for s in &f.strokes {
            put_varint(&mut raw, s.class.map_or(0, |c| u64::from(c) + 1));
            put_varint(&mut raw, (s.radius * SUBPIXEL).round().max(1.0) as u64);
            put_varint(&mut raw, s.points.len() as u64);
            let mut last = [0i64; 2];
            for p in &s.points {
                for axis in 0..2 {
                    let q = (p[axis] * SUBPIXEL).round() as i64;
                    put_varint(&mut raw, zigzag(q - last[axis]));
                    last[axis] = q;
                }
            }
        }
    }
    let mut deflate = DeflateEncoder::new(Vec::new(), Compression::best());
    deflate.write_all(&raw).expect("compressing into memory cannot fail");
    base64url_encode(&deflate.finish().expect("compressing into memory cannot fail"))
}

/// Unpacks a share code. The result still has to be checked against the scene
/// ([`LabelSet::check`]): the code does not know how many frames the scene has.
pub fn decode_labels(code: &str) -> Result<LabelSet, ShareError> {
    let packed = base64url_decode(code.trim())?;
    let mut raw = Vec::new();
    DeflateDecoder::new(packed.as_slice())
        .take(MAX_INFLATED + 1)
        .read_to_end(&mut raw)
        .map_err(|e| corrupt(format!("cannot inflate: {e}")))?;
    if raw.len() as u64 > MAX_INFLATED {
        return Err(corrupt("it inflates to more than 8 MiB"));
    }
    let mut r = Reader { data: &raw, at: 0 };
    let version = r.byte()?;
    if version != CODE_VERSION {
        return Err(ShareError::Version(version));
    }
    let mut labels = LabelSet::default();
    let classes = r.count("classes")?;
    for _ in 0..classes {
        let len = r.count("name length")?;
        let name = std::str::from_utf8(r.bytes(len)?)
            .map_err(|_| corrupt("a class name is not UTF-8"))?
            .to_string();
        let rgb = r.bytes(3)?;
        labels.classes.push(ClassInfo {
            name,
            color: [rgb[0], rgb[1], rgb[2]],
        });
    }
    let frames = r.count("frames")?;
    let mut frame = 0u64;
    // Counted as they are read: the limits are checked before a stroke's points are allocated.
    // Class ids are left to `LabelSet::check`, like the frame count.
    let mut total_points = 0usize;
    let mut checked_points = 0usize;
    for _ in 0..frames {
        frame = (frame + r.varint()?) & 0xffff_ffff;
        let strokes = r.count("strokes")?;
        let mut fl = FrameLabels {
            frame: frame as u32,
            strokes: Vec::with_capacity(strokes),
        };
        for index in 0..strokes {
            let class = match r.varint()? {
                0 => None,
                c => Some(u16::try_from(c - 1).map_err(|_| corrupt(format!("class id {} is too large", c - 1)))?),
            };
            let radius = r.varint()? as f32 / SUBPIXEL;
            let points = r.count("points")?;
            let at = format!("frame {frame} stroke {index}");
            if points > MAX_POINTS_PER_STROKE {
                return Err(ShareError::Limit(format!(
                    "{at}: {points} points, more than the limit of {MAX_POINTS_PER_STROKE} per stroke"
                )));
            }
            total_points += points;
            if total_points > MAX_TOTAL_POINTS {
                return Err(ShareError::Limit(format!(
                    "{at}: brings the points of all strokes past the limit of {MAX_TOTAL_POINTS}"
                )));
            }
            let mut last = [0i64; 2];
            let mut pts = Vec::with_capacity(points);
            for _ in 0..points {
                let mut p = [0f32; 2];
                for (axis, v) in p.iter_mut().enumerate() {
                    last[axis] = last[axis]
                        .checked_add(unzigzag(r.varint()?))
                        .ok_or_else(|| corrupt("a coordinate overflows"))?;
                    *v = last[axis] as f32 / SUBPIXEL;
                }
                pts.push(p);
            }
            let stroke = Stroke {
                class,
                radius,
                points: pts,
            };
            check_stroke(&stroke, fl.frame, index, None, &mut checked_points).map_err(ShareError::Limit)?;
            fl.strokes.push(stroke);
        }
        labels.frames.push(fl);
    }
    if r.at != raw.len() {
        return Err(corrupt(format!("{} bytes left over", raw.len() - r.at)));
    }
    // A frame listed twice (the code allows it) keeps all its strokes in order, in one entry,
    // as a label set must have it; the stable sort keeps each frame's strokes in code order.
    labels.frames.sort_by_key(|f| f.frame);
    let mut merged: Vec<FrameLabels> = Vec::with_capacity(labels.frames.len());
    for fl in labels.frames.drain(..) {
        match merged.last_mut() {
            Some(last) if last.frame == fl.frame => last.strokes.extend(fl.strokes),
            _ => merged.push(fl),
        }
    }
    labels.frames = merged;
    Ok(labels)
}

/// The parts of a page fragment the annotator reads.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Fragment {
    /// `scene=`, percent-decoded.
    pub scene: Option<String>,
    /// `labels=`, the raw share code.
    pub labels: Option<String>,
}

/// Reads `#scene=...&labels=...` (the leading `#` optional; unknown keys ignored).
pub fn parse_fragment(fragment: &str) -> Fragment {
    let fragment = fragment.strip_prefix('#').unwrap_or(fragment);
    let mut out = Fragment::default();
    for pair in fragment.split('&') {
        if let Some(v) = pair.strip_prefix("scene=") {
            let url = percent_decode(v);
            out.scene = (!url.trim().is_empty()).then_some(url);
        } else if let Some(v) = pair.strip_prefix("labels=") {
            out.labels = (!v.is_empty()).then(|| v.to_string());
        }
    }
    out
}

/// The percent-decoded value of `key` in a fragment (`#a=1&b=2`), for the page's other options.
pub fn fragment_value(fragment: &str, key: &str) -> Option<String> {
    let fragment = fragment.strip_prefix('#').unwrap_or(fragment);
    fragment
        .split('&')
        .find_map(|pair| pair.strip_prefix(key)?.strip_prefix('='))
        .map(percent_decode)
}

/// The fragment (without `#`) of a link to `scene_url` with `labels`, or why there is none.
pub fn share_fragment(scene_url: &str, labels: &LabelSet) -> Result<String, ShareError> {
    let mut fragment = format!("scene={}", percent_encode(scene_url));
    if labels.frames.iter().any(|f| !f.strokes.is_empty()) || !labels.classes.is_empty() {
        fragment.push_str("&labels=");
        fragment.push_str(&encode_labels(labels));
    }
    if fragment.len() > MAX_LINK_FRAGMENT {
        return Err(ShareError::TooLong { length: fragment.len() });
    }
    Ok(fragment)
}

// The page's fragment uses the crate's one percent codec; these names are what the page calls.
pub use crate::percent::{decode_lenient as percent_decode, encode as percent_encode};

fn zigzag(v: i64) -> u64 {
    ((v << 1) ^ (v >> 63)) as u64
}

fn unzigzag(v: u64) -> i64 {
    ((v >> 1) as i64) ^ -((v & 1) as i64)
}

fn put_varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn byte(&mut self) -> Result<u8, ShareError> {
        let b = *self.data.get(self.at).ok_or_else(|| corrupt("it ends early"))?;
        self.at += 1;
        Ok(b)
    }

    fn bytes(&mut self, n: usize) -> Result<&[u8], ShareError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.data.len());
        let end = end.ok_or_else(|| corrupt("it ends early"))?;
        let out = &self.data[self.at..end];
        self.at = end;
        Ok(out)
    }

    fn varint(&mut self) -> Result<u64, ShareError> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = self.byte()?;
            v |= u64::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
        }
        Err(corrupt("a number is too long"))
    }

    /// A count of things that follow, each at least one byte: more than the bytes left is
    /// corrupt, which also bounds every allocation by the inflated size.
    fn count(&mut self, what: &str) -> Result<usize, ShareError> {
        let n = self.varint()?;
        if n > (self.data.len() - self.at) as u64 {
            return Err(corrupt(format!("{what}: count {n} is more than the data holds")));
        }
        Ok(n as usize)
    }
}

/// base64url without padding, as links are written; padding is accepted when decoding, and so
/// are leftover bits in the last character (the codec this replaced ignored them).
const URL_SAFE: GeneralPurpose = GeneralPurpose::new(
    &alphabet::URL_SAFE,
    GeneralPurposeConfig::new()
        .with_encode_padding(false)
        .with_decode_padding_mode(DecodePaddingMode::Indifferent)
        .with_decode_allow_trailing_bits(true),
);
/// Standard base64, decoded too: a link that went through a tool that rewrote it still opens.
const STANDARD: GeneralPurpose = GeneralPurpose::new(
    &alphabet::STANDARD,
    GeneralPurposeConfig::new()
        .with_decode_padding_mode(DecodePaddingMode::Indifferent)
        .with_decode_allow_trailing_bits(true),
);

fn base64url_encode(data: &[u8]) -> String {
    URL_SAFE.encode(data)
}

fn base64url_decode(text: &str) -> Result<Vec<u8>, ShareError> {
    let engine = if text.contains(['+', '/']) {
        &STANDARD
    } else {
        &URL_SAFE
    };
    engine.decode(text).map_err(|e| match e {
        DecodeError::InvalidByte(_, c) => corrupt(format!("{:?} is not a base64url character", c as char)),
        DecodeError::InvalidLength(_) => corrupt("its base64 has a stray character at the end"),
        DecodeError::InvalidLastSymbol(_, c) => {
            corrupt(format!("its base64 ends in {:?}, which no code ends in", c as char))
        }
        DecodeError::InvalidPadding => corrupt("its base64 padding is wrong"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE64URL: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";

    fn labels() -> LabelSet {
        let mut l = LabelSet::new(vec![
            ClassInfo {
                name: "background".into(),
                color: [90, 90, 100],
            },
            ClassInfo {
                name: "tasse à café ☕".into(),
                color: [50, 110, 240],
            },
        ]);
        l.push_stroke(
            7,
            Stroke {
                class: Some(1),
                radius: 3.5,
                points: vec![[10.125, 20.5], [11.0, 19.875], [140.25, 0.5]],
            },
        );
        l.push_stroke(
            2,
            Stroke {
                class: None,
                radius: 12.0,
                points: vec![[0.0, 0.0]],
            },
        );
        l.push_stroke(
            7,
            Stroke {
                class: Some(0),
                radius: 0.5,
                points: vec![[5.5, 5.5], [4.5, 6.5]],
            },
        );
        l
    }

    #[test]
    fn labels_round_trip_exactly_on_the_grid() {
        let l = labels();
        let code = encode_labels(&l);
        assert!(code.bytes().all(|b| BASE64URL.contains(&b)), "{code}");
        assert_eq!(decode_labels(&code).unwrap(), l);
        let empty = LabelSet::default();
        assert_eq!(decode_labels(&encode_labels(&empty)).unwrap(), empty);
    }

    #[test]
    fn off_grid_values_round_to_eighths() {
        let mut l = LabelSet::new(vec![]);
        l.push_stroke(
            0,
            Stroke {
                class: None,
                radius: 1.01,
                points: vec![[1.06, 2.3]],
            },
        );
        let back = decode_labels(&encode_labels(&l)).unwrap();
        let s = &back.frames[0].strokes[0];
        assert_eq!((s.radius, s.points[0]), (1.0, [snap(1.06), snap(2.3)]));
        assert_eq!(snap(2.3), 2.25);
    }

    #[test]
    fn a_long_scribble_compresses() {
        // A wobbly stroke of 2000 points as a hand draws it: deltas of a few eighths.
        let mut l = LabelSet::new(vec![ClassInfo {
            name: "a".into(),
            color: [0, 0, 0],
        }]);
        let points: Vec<[f32; 2]> = (0..2000)
            .map(|i| {
                let t = i as f32 * 0.01;
                [snap(80.0 + 60.0 * t.cos()), snap(60.0 + 40.0 * (1.3 * t).sin())]
            })
            .collect();
        l.push_stroke(
            3,
            Stroke {
                class: Some(0),
                radius: 4.0,
                points,
            },
        );
        let code = encode_labels(&l);
        assert!(code.len() < 2000 * 3, "{} characters for 2000 points", code.len());
        assert_eq!(decode_labels(&code).unwrap(), l);
    }

    #[test]
    fn damaged_codes_are_errors_not_panics() {
        let code = encode_labels(&labels());
        for cut in [0, 1, 5, code.len() / 2, code.len() - 1] {
            assert!(decode_labels(&code[..cut]).is_err(), "cut at {cut}");
        }
        assert!(matches!(decode_labels("a*b"), Err(ShareError::Corrupt(_))));
        // Valid deflate of a wrong version byte.
        let mut d = DeflateEncoder::new(Vec::new(), Compression::fast());
        d.write_all(&[9]).unwrap();
        let code = base64url_encode(&d.finish().unwrap());
        assert_eq!(decode_labels(&code), Err(ShareError::Version(9)));
        // A count far beyond the data: rejected before allocating.
        let mut d = DeflateEncoder::new(Vec::new(), Compression::fast());
        let mut raw = vec![CODE_VERSION];
        put_varint(&mut raw, u64::MAX >> 1);
        d.write_all(&raw).unwrap();
        let err = decode_labels(&base64url_encode(&d.finish().unwrap())).unwrap_err();
        assert!(err.to_string().contains("count"), "{err}");
    }

    #[test]
    fn zip_bombs_are_refused() {
        let mut d = DeflateEncoder::new(Vec::new(), Compression::best());
        d.write_all(&vec![0u8; (MAX_INFLATED + 10) as usize]).unwrap();
        let code = base64url_encode(&d.finish().unwrap());
        let err = decode_labels(&code).unwrap_err();
        assert!(err.to_string().contains("8 MiB"), "{err}");
    }

    #[test]
    fn base64_matches_the_standard_alphabet() {
        for data in [
            &b""[..],
            b"f",
            b"fo",
            b"foo",
            b"foob",
            b"fooba",
            b"foobar",
            &[0xfb, 0xff, 0xfe],
        ] {
            let e = base64url_encode(data);
            assert_eq!(base64url_decode(&e).unwrap(), data);
        }
        assert_eq!(base64url_encode(b"foobar"), "Zm9vYmFy");
        assert_eq!(base64url_encode(&[0xfb, 0xff]), "-_8");
        assert_eq!(base64url_decode("+/8=").unwrap(), [0xfb, 0xff]);
    }

    #[test]
    fn fragments_carry_scene_and_labels() {
        let l = labels();
        let url = "https://example.org/scans/room 1.scene.zip?v=2&x=%41";
        let fragment = share_fragment(url, &l).unwrap();
        assert!(
            !fragment[6..].split("&labels=").next().unwrap().contains('&'),
            "{fragment}"
        );
        let parsed = parse_fragment(&format!("#{fragment}"));
        assert_eq!(parsed.scene.as_deref(), Some(url));
        assert_eq!(decode_labels(parsed.labels.as_deref().unwrap()).unwrap(), l);
        assert_eq!(
            parse_fragment("scene=demo.scene.zip&zoom=2"),
            Fragment {
                scene: Some("demo.scene.zip".into()),
                labels: None
            }
        );
        assert_eq!(parse_fragment("").scene, None);
        assert_eq!(fragment_value("#scene=a&model=tiny", "model").as_deref(), Some("tiny"));
        assert_eq!(fragment_value("#models=x", "model"), None);
        assert_eq!(percent_decode("a%2"), "a%2");
        assert_eq!(percent_decode("%E2%98%95%zz"), "☕%zz");
        assert_eq!(
            share_fragment("demo.scene.zip", &LabelSet::default()).unwrap(),
            "scene=demo.scene.zip"
        );
    }

    #[test]
    fn too_long_links_are_refused() {
        let mut l = LabelSet::new(vec![ClassInfo {
            name: "a".into(),
            color: [0, 0, 0],
        }]);
        // Random-looking points do not compress.
        let mut state = 12345u64;
        let points = (0..5000)
            .map(|_| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                [(state >> 40) as f32 / 1024.0, (state >> 20 & 0xfffff) as f32 / 1024.0]
            })
            .map(|p| [snap(p[0]), snap(p[1])])
            .collect();
        l.push_stroke(
            0,
            Stroke {
                class: Some(0),
                radius: 1.0,
                points,
            },
        );
        assert!(matches!(
            share_fragment("demo.scene.zip", &l),
            Err(ShareError::TooLong { .. })
        ));
    }
}
