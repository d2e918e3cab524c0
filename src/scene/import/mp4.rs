//! What the page needs of an MP4 before a browser decodes it: the video track's frame size,
//! frame count and the time at which each frame is shown, so that frame `n` of a capture can be
//! sought by time in a `<video>` element. Read from the boxes (ISO/IEC 14496-12): `moov/trak`
//! whose `mdia/hdlr` is `vide`; `mdhd` (timescale), `stsd` (the sample entry's width and
//! height), `stts` (decoding times), `ctts` (presentation offsets, B-frames) and `edts/elst`
//! (the edit that starts presentation, which players apply). Every count and size is checked
//! against the bytes there are before anything is allocated.
use crate::scene::error::{Result, SceneError};

/// The video track of an MP4.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Mp4Video {
    pub size: (u32, u32),
    /// Seconds on the player's clock at which each frame starts being shown, in presentation
    /// order (frame `n` of the capture is the `n`-th).
    pub frame_times: Vec<f64>,
    /// Seconds the last frame is shown for.
    pub last_duration: f64,
}

/// Frames in a phone's recording: over nine hours at 60 Hz.
const MAX_SAMPLES: u64 = 2_000_000;

/// One box: its type and its payload.
struct Mp4Box<'a> {
    kind: [u8; 4],
    body: &'a [u8],
}

/// The boxes directly inside `data`.
fn boxes<'a>(data: &'a [u8], file: &str) -> Result<Vec<Mp4Box<'a>>> {
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < data.len() {
        let bad = |why: &str| SceneError::invalid(file, format!("not an MP4 video: at byte {at}, {why}"));
        let header = data.get(at..at + 8).ok_or_else(|| bad("a box header is cut off"))?;
        let size32 = u32::from_be_bytes([header[0], header[1], header[2], header[3]]);
        let kind = [header[4], header[5], header[6], header[7]];
        let (start, size) = match size32 {
            0 => (at + 8, (data.len() - at) as u64),
            1 => {
                let large = data
                    .get(at + 8..at + 16)
                    .ok_or_else(|| bad("a large box's size is cut off"))?;
                (at + 16, u64::from_be_bytes(large.try_into().unwrap_or([0; 8])))
            }
            n => (at + 8, n as u64),
        };
        let header_len = (start - at) as u64;
        if size < header_len || size > (data.len() - at) as u64 {
            return Err(bad(&format!(
                "box {:?} of {size} bytes does not fit the {} bytes left",
                String::from_utf8_lossy(&kind),
                data.len() - at
            )));
        }
        let end = at + size as usize;
        out.push(Mp4Box {
            kind,
            body: &data[start..end],
        });
        at = end;
    }
    Ok(out)
}

fn child<'a>(list: &[Mp4Box<'a>], kind: &[u8; 4]) -> Option<&'a [u8]> {
    list.iter().find(|b| &b.kind == kind).map(|b| b.body)
}

/// Big-endian reads that name the box when it is too short.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
    what: &'static str,
    file: &'a str,
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8], what: &'static str, file: &'a str) -> Reader<'a> {
        Reader {
            data,
            at: 0,
            what,
            file,
        }
    }
    fn bytes(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| {
                SceneError::invalid(self.file, format!("not an MP4 video: its {} box is cut off", self.what))
            })?;
        let out = &self.data[self.at..end];
        self.at = end;
        Ok(out)
    }
    fn u8(&mut self) -> Result<u8> {
        Ok(self.bytes(1)?[0])
    }
    fn u16(&mut self) -> Result<u16> {
        let b = self.bytes(2)?;
        Ok(u16::from_be_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Result<u32> {
        let b = self.bytes(4)?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self) -> Result<u64> {
        let b = self.bytes(8)?;
        Ok(u64::from_be_bytes(b.try_into().unwrap_or([0; 8])))
    }
    /// A count of `entry` byte entries that the rest of the box must hold.
    fn count(&mut self, entry: usize) -> Result<usize> {
        let n = self.u32()? as usize;
        if n as u64 > MAX_SAMPLES || n.saturating_mul(entry) > self.data.len() - self.at {
            return Err(SceneError::invalid(
                self.file,
                format!(
                    "not an MP4 video: its {} box claims {n} entries it does not hold",
                    self.what
                ),
            ));
        }
        Ok(n)
    }
}

/// The video track of the MP4 `data` (`file` names it in errors).
pub(super) fn parse(data: &[u8], file: &str) -> Result<Mp4Video> {
    parse_capped(data, file, MAX_SAMPLES)
}

/// [`parse`] refusing a track of over `max_samples` frames: the fuzzer sets a low cap, so that
/// an input whose few bytes of `stts` claim the whole cap costs microseconds, not a second.
pub(super) fn parse_capped(data: &[u8], file: &str, max_samples: u64) -> Result<Mp4Video> {
    let top = boxes(data, file)?;
    let moov = child(&top, b"moov")
        .ok_or_else(|| SceneError::invalid(file, "not an MP4 video: no moov box (a fragmented or cut-off file?)"))?;
    let movie = boxes(moov, file)?;
    let movie_timescale = child(&movie, b"mvhd").map(|b| timescale(b, "mvhd", file)).transpose()?;
    for trak in movie.iter().filter(|b| &b.kind == b"trak") {
        let track = boxes(trak.body, file)?;
        let Some(mdia) = child(&track, b"mdia") else { continue };
        let media = boxes(mdia, file)?;
        let is_video = child(&media, b"hdlr").is_some_and(|h| h.get(8..12) == Some(b"vide"));
        if !is_video {
            continue;
        }
        return video_track(&track, &media, movie_timescale, max_samples, file);
    }
    Err(SceneError::invalid(file, "an MP4 without a video track"))
}

/// `mdhd`'s or `mvhd`'s timescale (ticks a second).
fn timescale(body: &[u8], what: &'static str, file: &str) -> Result<u32> {
    let mut r = Reader::new(body, what, file);
    let version = r.u8()?;
    r.bytes(3)?;
    // Creation and modification times: 4 bytes each in version 0, 8 in version 1.
    r.bytes(if version == 1 { 16 } else { 8 })?;
    let scale = r.u32()?;
    if scale == 0 {
        return Err(SceneError::invalid(
            file,
            format!("not an MP4 video: its {what} timescale is 0"),
        ));
    }
    Ok(scale)
}

fn video_track(
    track: &[Mp4Box],
    media: &[Mp4Box],
    movie_timescale: Option<u32>,
    max_samples: u64,
    file: &str,
) -> Result<Mp4Video> {
    let missing =
        |what: &str| SceneError::invalid(file, format!("not an MP4 video: its video track has no {what} box"));
    let scale = timescale(child(media, b"mdhd").ok_or_else(|| missing("mdhd"))?, "mdhd", file)? as f64;
    let minf = boxes(child(media, b"minf").ok_or_else(|| missing("minf"))?, file)?;
    let stbl = boxes(child(&minf, b"stbl").ok_or_else(|| missing("stbl"))?, file)?;
    let size = sample_entry_size(child(&stbl, b"stsd").ok_or_else(|| missing("stsd"))?, file)?;

    // Decoding times from the run-length deltas of stts.
    let mut r = Reader::new(child(&stbl, b"stts").ok_or_else(|| missing("stts"))?, "stts", file);
    r.bytes(4)?;
    let runs = r.count(8)?;
    let mut dts: Vec<i64> = Vec::new();
    let mut deltas: Vec<i64> = Vec::new();
    let mut t: i64 = 0;
    for _ in 0..runs {
        let (n, delta) = (r.u32()? as u64, r.u32()? as i64);
        if dts.len() as u64 + n > max_samples {
            return Err(SceneError::invalid(
                file,
                format!("not a capture's video: over {max_samples} frames"),
            ));
        }
        for _ in 0..n {
            dts.push(t);
            deltas.push(delta);
            t = t.saturating_add(delta);
        }
    }
    if dts.is_empty() {
        return Err(SceneError::invalid(file, "an MP4 whose video track has no frames"));
    }
    // Presentation offsets (B-frames), run-length coded as well.
    let mut pts = dts.clone();
    if let Some(ctts) = child(&stbl, b"ctts") {
        let mut r = Reader::new(ctts, "ctts", file);
        r.bytes(4)?;
        let runs = r.count(8)?;
        let mut i = 0usize;
        for _ in 0..runs {
            let n = r.u32()? as usize;
            let raw = r.u32()?;
            // Version 1 offsets are signed; version 0 ones are unsigned in the standard but
            // written as signed by some muxers: both are read as signed.
            let offset = raw as i32 as i64;
            for p in pts.iter_mut().skip(i).take(n) {
                *p = p.saturating_add(offset);
            }
            i = i.saturating_add(n);
        }
    }
    // The edit list: an empty edit delays presentation; the first real edit's media time is
    // where presentation starts (players show that sample at the start).
    let mut shift = 0.0;
    let mut start_ticks: i64 = pts.iter().copied().min().unwrap_or(0);
    if let Some(edts) = child(track, b"edts")
        && let Some(elst) = child(&boxes(edts, file)?, b"elst")
    {
        let mut r = Reader::new(elst, "elst", file);
        let version = r.u8()?;
        r.bytes(3)?;
        let entries = r.count(if version == 1 { 20 } else { 12 })?;
        for _ in 0..entries {
            let (duration, media_time) = if version == 1 {
                (r.u64()? as f64, r.u64()? as i64)
            } else {
                (r.u32()? as f64, r.u32()? as i32 as i64)
            };
            r.bytes(4)?;
            if media_time == -1 {
                shift += duration / movie_timescale.unwrap_or(scale as u32) as f64;
            } else {
                start_ticks = media_time;
                break;
            }
        }
    }
    let mut order: Vec<usize> = (0..pts.len()).collect();
    order.sort_by_key(|&i| (pts[i], i));
    let frame_times: Vec<f64> = order
        .iter()
        .map(|&i| (pts[i] - start_ticks) as f64 / scale + shift)
        .collect();
    let last = order[order.len() - 1];
    Ok(Mp4Video {
        size,
        frame_times,
        last_duration: deltas[last].max(1) as f64 / scale,
    })
}

/// Width and height of the first sample entry of `stsd` (a visual sample entry: avc1, hvc1, ...).
fn sample_entry_size(stsd: &[u8], file: &str) -> Result<(u32, u32)> {
    let mut r = Reader::new(stsd, "stsd", file);
    r.bytes(4)?;
    if r.u32()? == 0 {
        return Err(SceneError::invalid(
            file,
            "not an MP4 video: its video track describes no codec",
        ));
    }
    // Entry header (size, format), 6 reserved bytes, data reference index, 16 bytes of
    // pre-defined and reserved fields, then width and height.
    r.bytes(8 + 6 + 2 + 16)?;
    let (w, h) = (r.u16()? as u32, r.u16()? as u32);
    if w == 0 || h == 0 {
        return Err(SceneError::invalid(file, format!("a video of {w}x{h} frames")));
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mp4_box(kind: &[u8; 4], body: &[u8]) -> Vec<u8> {
        let mut out = ((body.len() + 8) as u32).to_be_bytes().to_vec();
        out.extend_from_slice(kind);
        out.extend_from_slice(body);
        out
    }

    fn full(version: u8, rest: &[u8]) -> Vec<u8> {
        let mut out = vec![version, 0, 0, 0];
        out.extend_from_slice(rest);
        out
    }

    fn be(words: &[u32]) -> Vec<u8> {
        words.iter().flat_map(|w| w.to_be_bytes()).collect()
    }

    /// An MP4 of `frames` frames of 1/30 s (timescale 3000), the given presentation offsets
    /// (one per frame) and edit list start.
    fn movie(frames: u32, offsets: Option<&[u32]>, edit_start: Option<u32>) -> Vec<u8> {
        let mdhd = mp4_box(b"mdhd", &full(0, &be(&[0, 0, 3000, frames * 100, 0])));
        let hdlr = mp4_box(b"hdlr", &full(0, &[&be(&[0])[..], b"vide", &[0; 13]].concat()));
        let mut entry = vec![0u8; 6 + 2 + 16];
        entry.extend_from_slice(&640u16.to_be_bytes());
        entry.extend_from_slice(&480u16.to_be_bytes());
        entry.extend_from_slice(&[0; 50]);
        let stsd = mp4_box(b"stsd", &full(0, &[&be(&[1])[..], &mp4_box(b"avc1", &entry)].concat()));
        let stts = mp4_box(b"stts", &full(0, &be(&[1, frames, 100])));
        let mut stbl = [stsd, stts].concat();
        if let Some(o) = offsets {
            let runs: Vec<u32> = o.iter().flat_map(|&x| [1, x]).collect();
            stbl.extend(mp4_box(
                b"ctts",
                &full(0, &[&be(&[o.len() as u32])[..], &be(&runs)].concat()),
            ));
        }
        let minf = mp4_box(b"minf", &mp4_box(b"stbl", &stbl));
        let mdia = mp4_box(b"mdia", &[mdhd, hdlr, minf].concat());
        let mut trak = Vec::new();
        if let Some(start) = edit_start {
            let elst = mp4_box(b"elst", &full(0, &be(&[1, frames * 100, start, 0x0001_0000])));
            trak.extend(mp4_box(b"edts", &elst));
        }
        trak.extend(mdia);
        let mvhd = mp4_box(b"mvhd", &full(0, &be(&[0, 0, 1000, 0])));
        let moov = mp4_box(b"moov", &[mvhd, mp4_box(b"trak", &trak)].concat());
        [mp4_box(b"ftyp", b"isom\0\0\0\0"), moov].concat()
    }

    #[test]
    fn frames_are_timed_in_presentation_order() {
        let v = parse(&movie(4, None, None), "v.mp4").unwrap();
        assert_eq!(v.size, (640, 480));
        let t: Vec<f64> = v.frame_times.iter().map(|t| (t * 3000.0).round()).collect();
        assert_eq!(t, [0.0, 100.0, 200.0, 300.0]);
        assert!((v.last_duration - 1.0 / 30.0).abs() < 1e-12);
        // B-frames: decoded I P B B, shown I B B P; the edit list starts at the first shown.
        let v = parse(&movie(4, Some(&[200, 400, 100, 100]), Some(200)), "v.mp4").unwrap();
        let t: Vec<f64> = v.frame_times.iter().map(|t| (t * 3000.0).round()).collect();
        assert_eq!(t, [0.0, 100.0, 200.0, 300.0]);
    }

    #[test]
    fn broken_files_are_named() {
        let err = |data: &[u8]| parse(data, "cap/rgb.mp4").unwrap_err().to_string();
        let e = err(b"not a video at all");
        assert!(e.contains("cap/rgb.mp4") && e.contains("not an MP4 video"), "{e}");
        let good = movie(4, None, None);
        for cut in [10, good.len() / 2, good.len() - 3] {
            let e = err(&good[..cut]);
            assert!(e.contains("not an MP4 video"), "{cut}: {e}");
        }
        let e = err(&mp4_box(b"ftyp", b"isom"));
        assert!(e.contains("no moov box"), "{e}");
        // A sample count far beyond the box.
        let mut lying = good.clone();
        let at = lying.windows(4).position(|w| w == b"stts").unwrap() + 8;
        lying[at..at + 4].copy_from_slice(&u32::MAX.to_be_bytes());
        let e = err(&lying);
        assert!(e.contains("stts box claims"), "{e}");
    }
}
