//! Frames of a capture's video (Stray Scanner records its colour as `rgb.mp4`, HEVC), decoded by
//! `ffmpeg` from PATH: the phone's codecs (HEVC, H.264) have no mature pure-Rust decoder, and
//! ffmpeg is one Debian package. Only the frames kept are converted and handed over, one at a time,
//! so a minute of 1920x1440 video never sits in memory decoded. The page has no ffmpeg: there the
//! browser decodes, a `<video>` element sought frame by frame by the times the MP4's index gives
//! (`mp4.rs`); which codecs it can decode is the browser's (H.264 everywhere, HEVC where the
//! hardware decodes it: Safari, and Chrome on such machines).
use std::path::Path;

use crate::scene::archive::limits;
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

#[cfg(not(target_arch = "wasm32"))]
mod native {
    use std::io::Read;
    use std::path::{Path, PathBuf};
    use std::process::{Child, ChildStdout, Command, Stdio};

    use image::RgbImage;

    use super::{VideoInfo, check_size, video_error};
    use crate::scene::error::{Result, SceneError};

    /// How to get the tools, for the message when they are missing.
    const INSTALL: &str =
        "decoding a capture's video needs ffmpeg and ffprobe on PATH (Debian: apt-get install ffmpeg)";
    /// A video read from memory (the page's path, natively) is written here for ffmpeg, which
    /// needs to seek in an MP4.
    const LARGEST_IN_MEMORY: u64 = crate::scene::import::files::MAX_CAPTURE_BYTES;

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
        pub(in crate::scene::import) async fn next(&mut self) -> Result<RgbImage> {
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
    use wasm_bindgen::{JsCast, JsValue};
    use wasm_bindgen_futures::JsFuture;
    use web_sys::{AddEventListenerOptions, CanvasRenderingContext2d, HtmlCanvasElement, HtmlVideoElement};

    use super::{VideoInfo, check_size, video_error};
    use crate::scene::error::{Result, SceneError};
    use crate::scene::import::files::{MAX_CAPTURE_BYTES, read};
    use crate::scene::import::mp4;

    fn bytes(path: &Path) -> Result<Vec<u8>> {
        read(path, MAX_CAPTURE_BYTES).map_err(|e| SceneError::io(path, e))
    }

    /// The video's frame size and frame count, from its MP4 index.
    pub(in crate::scene::import) fn probe(path: &Path) -> Result<VideoInfo> {
        let video = mp4::parse(&bytes(path)?, &path.display().to_string())?;
        check_size(path, video.size)?;
        Ok(VideoInfo {
            size: video.size,
            frames: video.frame_times.len() as u32,
        })
    }

    /// The kept frames of one video, decoded by the browser: a `<video>` element sought to each
    /// frame's time and drawn onto a canvas.
    pub(in crate::scene::import) struct Decoder {
        name: std::path::PathBuf,
        bytes: Option<Vec<u8>>,
        /// Where to seek for each kept frame, in order: the middle of the time it is shown, so
        /// rounding in the player's clock lands on it.
        targets: std::collections::VecDeque<(u32, f64)>,
        size: (u32, u32),
        player: Option<Player>,
    }

    struct Player {
        video: HtmlVideoElement,
        url: String,
        context: CanvasRenderingContext2d,
    }

    impl Drop for Player {
        fn drop(&mut self) {
            self.video.remove_attribute("src").ok();
            web_sys::Url::revoke_object_url(&self.url).ok();
        }
    }

    /// What the browser said, as text.
    fn said(e: JsValue) -> String {
        e.dyn_ref::<js_sys::Error>()
            .map(|e| String::from(e.message()))
            .or_else(|| e.as_string())
            .unwrap_or_else(|| {
                "no decoder for its codec here (Chrome and Safari decode HEVC only where the hardware does)".into()
            })
    }

    /// How often, and how long apart, a frame is drawn again while it has no picture.
    const PICTURE_TRIES: u32 = 200;
    const PICTURE_WAIT_MS: u32 = 25;

    /// Waits for `event` on `video`; its `error` event instead is an error.
    async fn event(video: &HtmlVideoElement, event: &str) -> std::result::Result<(), JsValue> {
        let promise = js_sys::Promise::new(&mut |resolve, reject| {
            let once = AddEventListenerOptions::new();
            once.set_once(true);
            video
                .add_event_listener_with_callback_and_add_event_listener_options(event, &resolve, &once)
                .ok();
            video
                .add_event_listener_with_callback_and_add_event_listener_options("error", &reject, &once)
                .ok();
        });
        JsFuture::from(promise).await.map(|_| ())
    }

    impl Decoder {
        /// Prepares decoding frames `keep` (ascending indices) of the video at `path`.
        pub(in crate::scene::import) fn start(path: &Path, info: VideoInfo, keep: &[u32]) -> Result<Decoder> {
            let bytes = bytes(path)?;
            let video = mp4::parse(&bytes, &path.display().to_string())?;
            let times = &video.frame_times;
            let targets = keep
                .iter()
                .map(|&n| {
                    let i = n as usize;
                    let start = times.get(i).copied().unwrap_or(0.0);
                    let end = times.get(i + 1).copied().unwrap_or(start + video.last_duration);
                    (n, (start + end) / 2.0)
                })
                .collect();
            Ok(Decoder {
                name: path.to_path_buf(),
                bytes: Some(bytes),
                targets,
                size: info.size,
                player: None,
            })
        }

        fn failed(&self, why: impl std::fmt::Display) -> SceneError {
            video_error(&self.name, format!("the browser could not decode this video: {why}"))
        }

        async fn player(&mut self) -> Result<&Player> {
            if self.player.is_none() {
                let bytes = self.bytes.take().ok_or_else(|| self.failed("it was already opened"))?;
                let player = self.open(bytes).await?;
                self.player = Some(player);
            }
            self.player.as_ref().ok_or_else(|| self.failed("no player"))
        }

        async fn open(&self, bytes: Vec<u8>) -> Result<Player> {
            let document = web_sys::window()
                .and_then(|w| w.document())
                .ok_or_else(|| self.failed("no document"))?;
            let parts = js_sys::Array::of1(&js_sys::Uint8Array::from(&bytes[..]));
            drop(bytes);
            let options = web_sys::BlobPropertyBag::new();
            options.set_type("video/mp4");
            let blob = web_sys::Blob::new_with_u8_array_sequence_and_options(&parts, &options)
                .map_err(|e| self.failed(said(e)))?;
            let url = web_sys::Url::create_object_url_with_blob(&blob).map_err(|e| self.failed(said(e)))?;
            let video: HtmlVideoElement = document
                .create_element("video")
                .map_err(|e| self.failed(said(e)))?
                .unchecked_into();
            video.set_muted(true);
            video.set_preload("auto");
            let loaded = event(&video, "loadeddata");
            video.set_src(&url);
            loaded.await.map_err(|e| self.failed(said(e)))?;
            let shown = (video.video_width(), video.video_height());
            if shown != self.size {
                return Err(self.failed(format!(
                    "the browser shows its frames as {}x{}, its index says {}x{} (turned by rotation metadata?); \
                     pack the capture on the command line",
                    shown.0, shown.1, self.size.0, self.size.1
                )));
            }
            let canvas: HtmlCanvasElement = document
                .create_element("canvas")
                .map_err(|e| self.failed(said(e)))?
                .unchecked_into();
            canvas.set_width(self.size.0);
            canvas.set_height(self.size.1);
            let context: CanvasRenderingContext2d = canvas
                .get_context("2d")
                .ok()
                .flatten()
                .ok_or_else(|| self.failed("no 2D canvas"))?
                .unchecked_into();
            Ok(Player { video, url, context })
        }

        /// The next kept frame.
        pub(in crate::scene::import) async fn next(&mut self) -> Result<RgbImage> {
            let (index, time) = self
                .targets
                .pop_front()
                .ok_or_else(|| self.failed("asked for more frames than were kept"))?;
            let (w, h) = self.size;
            let name = self.name.clone();
            let player = self.player().await?;
            let sought = event(&player.video, "seeked");
            player.video.set_current_time(time);
            let fail = |why: String| video_error(&name, format!("the browser could not show frame {index}: {why}"));
            sought.await.map_err(|e| fail(said(e)))?;
            // A seek can end before the browser has the frame's picture (seen on a loaded
            // machine: the first frame after loading drew nothing). Drawing then leaves the
            // canvas as it was, so it is cleared first and a picture is known by its opaque
            // pixels: a video frame draws opaque.
            let mut tries = 0;
            let rgba = loop {
                player.context.clear_rect(0.0, 0.0, f64::from(w), f64::from(h));
                player
                    .context
                    .draw_image_with_html_video_element(&player.video, 0.0, 0.0)
                    .map_err(|e| fail(said(e)))?;
                let rgba = player
                    .context
                    .get_image_data(0.0, 0.0, f64::from(w), f64::from(h))
                    .map_err(|e| fail(said(e)))?
                    .data()
                    .0;
                if rgba.chunks_exact(4).any(|p| p[3] != 0) {
                    break rgba;
                }
                tries += 1;
                if tries > PICTURE_TRIES {
                    return Err(fail(format!(
                        "no picture {} ms after seeking to it",
                        PICTURE_TRIES * PICTURE_WAIT_MS
                    )));
                }
                crate::pause::sleep_ms(PICTURE_WAIT_MS).await;
            };
            let rgb: Vec<u8> = rgba.chunks_exact(4).flat_map(|p| [p[0], p[1], p[2]]).collect();
            RgbImage::from_raw(w, h, rgb).ok_or_else(|| fail("a frame of the wrong size".into()))
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
