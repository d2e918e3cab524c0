//! Frames of a capture's video (Stray Scanner records its colour as `rgb.mp4`, HEVC), decoded by
//! `ffmpeg` from PATH: the phone's codecs (HEVC, H.264) have no mature pure-Rust decoder, and
//! ffmpeg is one Debian package. Only the frames kept are converted and handed over, one at a time,
//! so a minute of 1920x1440 video never sits in memory decoded. The page has no ffmpeg: there a
//! video capture is refused with a message that says how to pack it.
use std::path::Path;

use crate::scene::error::{Result, SceneError};

/// What a video holds, from its header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct VideoInfo {
    pub size: (u32, u32),
    /// Frames in the first video stream (counted from its packets, not the header's claim).
    pub frames: u32,
}

#[cfg(not(target_arch = "wasm32"))]
pub(super) use native::{Decoder, probe};

#[cfg(target_arch = "wasm32")]
pub(super) use page::{Decoder, probe};

/// "`name`, a video: ..." for errors that are about the tools rather than the file.
fn video_error(path: &Path, why: impl Into<String>) -> SceneError {
    SceneError::invalid(path.display().to_string(), why)
}

#[cfg(not(target_arch = "wasm32"))]
mod native {
    use std::io::Read;
    use std::path::{Path, PathBuf};
    use std::process::{Child, ChildStdout, Command, Stdio};

    use image::RgbImage;

    use super::{VideoInfo, video_error};
    use crate::scene::archive::limits;
    use crate::scene::error::{Result, SceneError};

    /// How to get the tools, for the message when they are missing.
    const INSTALL: &str =
        "decoding a capture's video needs ffmpeg and ffprobe on PATH (Debian: apt-get install ffmpeg)";
    /// A video read from memory (the page's path, natively) is written here for ffmpeg, which
    /// needs to seek in an MP4.
    const LARGEST_IN_MEMORY: u64 = crate::scene::import::files::MAX_CAPTURE_BYTES;

    /// A probed size an image of the capture could have: within the archive's side limit, as an
    /// image file's header is checked.
    fn check_size(path: &Path, size: (u32, u32)) -> Result<()> {
        if size.0 == 0 || size.1 == 0 || size.0 > limits::MAX_SIDE || size.1 > limits::MAX_SIDE {
            return Err(video_error(
                path,
                format!(
                    "video frames of {}x{} are outside the sizes a capture's images may have (1 to {} a side)",
                    size.0,
                    size.1,
                    limits::MAX_SIDE
                ),
            ));
        }
        Ok(())
    }

    /// The video's frame size and frame count, from `ffprobe`.
    pub(in crate::scene::import) fn probe(path: &Path) -> Result<VideoInfo> {
        let local = Local::of(path)?;
        let out = Command::new("ffprobe")
            .args(["-v", "error", "-select_streams", "v:0", "-count_packets"])
            .args(["-show_entries", "stream=width,height,nb_read_packets", "-of", "csv=p=0"])
            .arg(&local.path)
            .stdin(Stdio::null())
            .output()
            .map_err(|e| video_error(path, format!("{INSTALL}: cannot run ffprobe: {e}")))?;
        let text = String::from_utf8_lossy(&out.stdout);
        let fields: Vec<&str> = text.trim().split(',').map(str::trim).collect();
        let parsed = match fields[..] {
            [w, h, n] => w.parse().ok().zip(h.parse().ok()).zip(n.parse().ok()),
            _ => None,
        };
        let Some(((w, h), frames)) = parsed.filter(|_| out.status.success()) else {
            let why = String::from_utf8_lossy(&out.stderr);
            let why = why.trim();
            return Err(video_error(
                path,
                format!(
                    "not a video ffprobe can read{}",
                    if why.is_empty() {
                        " (no video stream)".to_string()
                    } else {
                        format!(": {}", last_line(why))
                    }
                ),
            ));
        };
        check_size(path, (w, h))?;
        Ok(VideoInfo { size: (w, h), frames })
    }

    /// The last line of a tool's complaint, which says what went wrong (the first ones say
    /// where).
    fn last_line(text: &str) -> &str {
        text.lines().last().unwrap_or(text).trim()
    }

    /// A file ffmpeg can open: the path itself on disk, or a temporary copy of a file held in
    /// memory (removed when dropped).
    struct Local {
        path: PathBuf,
        temporary: bool,
    }

    impl Local {
        fn of(path: &Path) -> Result<Local> {
            if crate::scene::import::files::on_disk() {
                return Ok(Local {
                    path: path.to_path_buf(),
                    temporary: false,
                });
            }
            let bytes =
                crate::scene::import::files::read(path, LARGEST_IN_MEMORY).map_err(|e| SceneError::io(path, e))?;
            let name = format!(
                "scribblefield-video-{}-{:x}.mp4",
                std::process::id(),
                std::time::SystemTime::now()
                    .duration_since(std::time::UNIX_EPOCH)
                    .map_or(0, |d| d.as_nanos())
            );
            let local = std::env::temp_dir().join(name);
            std::fs::write(&local, bytes).map_err(|e| SceneError::io(&local, e))?;
            Ok(Local {
                path: local,
                temporary: true,
            })
        }
    }

    impl Drop for Local {
        fn drop(&mut self) {
            if self.temporary {
                let _ = std::fs::remove_file(&self.path);
            }
        }
    }

    /// The kept frames of one video, decoded in order by one ffmpeg process.
    pub(in crate::scene::import) struct Decoder {
        name: PathBuf,
        child: Child,
        out: ChildStdout,
        size: (u32, u32),
        /// The frames still to come, by index in the video.
        left: std::collections::VecDeque<u32>,
        _local: Local,
    }

    impl Decoder {
        /// Starts decoding frames `keep` (ascending indices) of the video at `path` of `info`.
        pub(in crate::scene::import) fn start(path: &Path, info: VideoInfo, keep: &[u32]) -> Result<Decoder> {
            let local = Local::of(path)?;
            // `select` passes the frames whose index is in `keep`; `passthrough` keeps ffmpeg from
            // duplicating or dropping frames to hold a frame rate. `-noautorotate`: the camera
            // matrix and the depth are for the frames as stored, not as a player turns them.
            let picked: Vec<String> = keep.iter().map(|n| format!("eq(n\\,{n})")).collect();
            let filter = format!("select='{}'", picked.join("+"));
            let mut child = Command::new("ffmpeg")
                .args(["-v", "error", "-nostdin", "-noautorotate", "-i"])
                .arg(&local.path)
                .args(["-map", "0:v:0", "-vf", &filter, "-fps_mode", "passthrough"])
                .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"])
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .map_err(|e| video_error(path, format!("{INSTALL}: cannot run ffmpeg: {e}")))?;
            let out = child
                .stdout
                .take()
                .ok_or_else(|| video_error(path, "ffmpeg gave no output pipe"))?;
            Ok(Decoder {
                name: path.to_path_buf(),
                child,
                out,
                size: info.size,
                left: keep.iter().copied().collect(),
                _local: local,
            })
        }

        /// The next kept frame.
        pub(in crate::scene::import) fn next(&mut self) -> Result<RgbImage> {
            let Some(index) = self.left.pop_front() else {
                return Err(video_error(&self.name, "asked for more frames than were kept"));
            };
            let (w, h) = self.size;
            let mut bytes = vec![0u8; w as usize * h as usize * 3];
            if let Err(e) = self.out.read_exact(&mut bytes) {
                let _ = self.child.kill();
                let mut why = String::new();
                if let Some(mut err) = self.child.stderr.take() {
                    let _ = err.read_to_string(&mut why);
                }
                let _ = self.child.wait();
                let why = if why.trim().is_empty() {
                    e.to_string()
                } else {
                    last_line(&why).to_string()
                };
                return Err(video_error(
                    &self.name,
                    format!("ffmpeg stopped before frame {index} of the video: {why}"),
                ));
            }
            RgbImage::from_raw(w, h, bytes).ok_or_else(|| video_error(&self.name, "a frame of the wrong size"))
        }
    }

    impl Drop for Decoder {
        fn drop(&mut self) {
            // Frames not asked for (an import that stopped on an error) are not waited for.
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[cfg(target_arch = "wasm32")]
mod page {
    use std::path::Path;

    use image::RgbImage;

    use super::{VideoInfo, video_error};
    use crate::scene::error::Result;

    /// The page has no video decoder of its own yet.
    pub(in crate::scene::import) fn probe(path: &Path) -> Result<VideoInfo> {
        Err(video_error(
            path,
            "this page cannot decode a capture's video yet: pack the capture with the command line \
             (`scribblefield pack CAPTURE -o scene.scene.zip`, which needs ffmpeg) and open the archive here",
        ))
    }

    pub(in crate::scene::import) struct Decoder;

    impl Decoder {
        pub(in crate::scene::import) fn start(path: &Path, _info: VideoInfo, _keep: &[u32]) -> Result<Decoder> {
            probe(path).map(|_| Decoder)
        }

        pub(in crate::scene::import) fn next(&mut self) -> Result<RgbImage> {
            Err(video_error(
                Path::new("rgb.mp4"),
                "this page cannot decode a capture's video yet",
            ))
        }
    }
}

/// Every frame of a kept set is needed, in order: `keep` must be ascending and inside the video.
pub(super) fn check_keep(path: &Path, info: VideoInfo, keep: &[u32]) -> Result<()> {
    if let Some(&last) = keep.iter().max()
        && last >= info.frames
    {
        return Err(video_error(
            path,
            format!(
                "has {} frames, but frame {last} is asked for (the poses name frames the video does not have)",
                info.frames
            ),
        ));
    }
    Ok(())
}
