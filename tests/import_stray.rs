//! The Stray Scanner importer on the YCB clip of ../shared/data written in the app's layout (no
//! phone capture is in ../shared/data): colour as an HEVC `rgb.mp4` (encoded here by ffmpeg),
//! depth at the LiDAR's 256x192 with confidence maps, ARKit poses in `odometry.csv`. It must pack
//! what the clip packs from its own folder, from disk and from memory, and name every bad file.
mod import_common;

use std::path::Path;
use std::process::Command;
use std::rc::Rc;

use glam::{DMat3, DMat4, DQuat};
use image::{GrayImage, ImageBuffer, Luma};
use import_common::*;
use scribblefield::pause::{NoPause, run_to_end};
use scribblefield::scene::Scene;
use scribblefield::scene::import::{ImportOptions, Imported, Layout, detect_layout, import, import_files};

const YCB: &str = "ycb-video-0000";
const FRAMES: usize = 10;
const LAST: usize = FRAMES - 1;
/// The LiDAR depth map's size in the app.
const DEPTH_SIZE: (u32, u32) = (256, 192);

/// How the colour video is encoded.
#[derive(Clone, Copy)]
enum Video {
    /// As the app records it: HEVC, 4:2:0, lossy.
    AsRecorded,
    /// Lossless HEVC of the RGB planes: decodes to the PNGs' exact pixels.
    Lossless,
    /// H.264, which every browser decodes, with each frame's number drawn in its corner
    /// ([`marker`]) so that a browser test can tell which frame it was given.
    Marked,
}

/// The colour of the block in the top-left corner of frame `i` of a [`Video::Marked`] video.
fn marker(i: usize) -> [u8; 3] {
    [(i * 25) as u8, 255 - (i * 25) as u8, 128]
}

/// Side of the corner block, pixels.
const MARKER: u32 = 48;

/// The YCB clip (and ffmpeg to encode it), or None with a loud message.
fn setup() -> Option<std::path::PathBuf> {
    let ycb = real_data(YCB)?;
    if Command::new("ffmpeg").arg("-version").output().is_err() {
        eprintln!(
            "\n!!! SKIPPING: ffmpeg is not installed (bash scripts/setup.sh installs it); this test checks nothing here !!!\n"
        );
        return None;
    }
    Some(ycb)
}

/// The YCB clip in Stray Scanner's layout. The last frame's confidence map has a block of low
/// confidence (dropped) and one of medium (dropped too); every other reading is high.
fn write_stray(ycb: &Path, to: &Path, video: Video) {
    std::fs::create_dir_all(to).unwrap();
    let mut odometry = String::from("timestamp, frame, x, y, z, qx, qy, qz, qw\n");
    for i in 0..FRAMES {
        let from = format!("{i:05}");
        let name = format!("{i:06}");
        let depth = image::open(ycb.join(format!("depth/{from}.png")))
            .unwrap()
            .into_luma16();
        let small: ImageBuffer<Luma<u16>, Vec<u16>> =
            image::imageops::resize(&depth, DEPTH_SIZE.0, DEPTH_SIZE.1, image::imageops::FilterType::Nearest);
        save_gray16(&to.join(format!("depth/{name}.png")), &small);
        let confidence = GrayImage::from_fn(DEPTH_SIZE.0, DEPTH_SIZE.1, |x, y| {
            let low = i == LAST && (100..140).contains(&x) && (60..100).contains(&y);
            let medium = i == LAST && (10..30).contains(&x) && (10..30).contains(&y);
            Luma([if low {
                0
            } else if medium {
                1
            } else {
                2
            }])
        });
        save_gray8(&to.join(format!("confidence/{name}.png")), &confidence);
        // The clip's poses are world-to-camera in OpenCV axes; ARKit's are camera-to-world with
        // y up and z backward.
        let c2w = read_matrix(&ycb.join(format!("pose/{from}.txt"))).inverse();
        let arkit = c2w.0 * DMat4::from_diagonal(glam::DVec4::new(1.0, -1.0, -1.0, 1.0));
        let q = DQuat::from_mat3(&DMat3::from_mat4(arkit)).normalize();
        let t = arkit.w_axis;
        odometry += &format!(
            "{:.6}, {i}, {:.12}, {:.12}, {:.12}, {:.12}, {:.12}, {:.12}, {:.12}\n",
            1.5 + i as f64 / 60.0,
            t.x,
            t.y,
            t.z,
            q.x,
            q.y,
            q.z,
            q.w
        );
    }
    write(&to.join("odometry.csv"), odometry);
    write(
        &to.join("camera_matrix.csv"),
        "1066.778,0.0,312.9869\n0.0,1067.487,241.3109\n0.0,0.0,1.0\n",
    );
    write(
        &to.join("imu.csv"),
        "timestamp, a_x, a_y, a_z, alpha_x, alpha_y, alpha_z\n",
    );
    let codec: &[&str] = match video {
        Video::AsRecorded => &[
            "-c:v",
            "libx265",
            "-crf",
            "18",
            "-x265-params",
            "log-level=error",
            "-pix_fmt",
            "yuv420p",
            "-tag:v",
            "hvc1",
        ],
        Video::Lossless => &[
            "-c:v",
            "libx265",
            "-x265-params",
            "lossless=1:log-level=error",
            "-pix_fmt",
            "gbrp",
        ],
        Video::Marked => &["-c:v", "libx264", "-crf", "18", "-pix_fmt", "yuv420p"],
    };
    let frames = match video {
        Video::Marked => {
            let marked = to.with_extension("frames");
            for i in 0..FRAMES {
                let mut rgb = image::open(ycb.join(format!("rgb/{i:05}.png"))).unwrap().into_rgb8();
                for y in 0..MARKER {
                    for x in 0..MARKER {
                        rgb.put_pixel(x, y, image::Rgb(marker(i)));
                    }
                }
                save_rgb(&marked.join(format!("{i:05}.png")), &rgb);
            }
            marked
        }
        _ => ycb.join("rgb"),
    };
    let status = Command::new("ffmpeg")
        .args(["-v", "error", "-y", "-framerate", "60", "-i"])
        .arg(frames.join("%05d.png"))
        .args(codec)
        .arg(to.join("rgb.mp4"))
        .status()
        .unwrap();
    assert!(status.success(), "ffmpeg could not encode the clip");
}

fn imported(dir: &Path, opts: &ImportOptions) -> Imported {
    import(dir, opts, &mut |_, _| {}).unwrap_or_else(|e| panic!("{e}"))
}

/// Mean absolute difference of two colour images' channels.
fn colour_difference(a: &image::RgbImage, b: &image::RgbImage) -> f64 {
    let sum: u64 = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| x.abs_diff(*y) as u64)
        .sum();
    sum as f64 / a.as_raw().len() as f64
}

/// The same frames, camera and poses (within 1e-6: odometry goes through a quaternion), and
/// colour within `colour` of a channel on average (depth is checked on its own: the app's is
/// coarser).
fn assert_same_frames(stray: &Scene, own: &Scene, colour: f64) {
    assert_eq!(stray.frames.len(), own.frames.len());
    assert_eq!((stray.width, stray.height), (own.width, own.height));
    assert_eq!(stray.intrinsics, own.intrinsics);
    for (i, (s, o)) in stray.frames.iter().zip(&own.frames).enumerate() {
        assert!(
            s.pose.0.abs_diff_eq(o.pose.0, 1e-6),
            "frame {i}: {} vs {}",
            s.pose.0,
            o.pose.0
        );
        let d = colour_difference(&s.rgb, &o.rgb);
        assert!(d <= colour, "colour of frame {i} differs by {d} on average");
        assert!(s.gt.is_none());
    }
}

#[test]
fn the_ycb_clip_packs_the_same_from_stray_scanner_layout() {
    let Some(ycb) = setup() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("71de12f9");
    write_stray(&ycb, &dir, Video::Lossless);
    assert_eq!(detect_layout(&dir).unwrap(), Layout::StrayScanner);

    let stray = imported(&dir, &ImportOptions::default());
    assert_eq!(stray.layout, Layout::StrayScanner);
    assert!(stray.warnings.is_empty(), "{:?}", stray.warnings);
    let own = imported(&ycb, &ImportOptions::default());
    // Lossless video: every pixel as in the clip's PNGs.
    assert_same_frames(&stray.scene, &own.scene, 0.0);
    let s = &stray.scene;
    assert_eq!(s.frames[0].source.as_deref(), Some("000000"));
    assert_eq!(s.frames[9].source.as_deref(), Some("000009"));
    assert_eq!(s.provenance.importer, "stray-scanner");
    let notes = s.provenance.notes.join("\n");
    assert!(
        notes.contains("confidence below 2") && notes.contains("rgb.mp4 (10 frames of 640x480"),
        "{notes}"
    );

    // Depth: 256x192 readings spread onto the 640x480 frames, the same millimetres where the
    // confidence was high; none left where it was low or medium.
    let (depth, clip) = (
        s.frames[LAST].depth.as_ref().unwrap(),
        own.scene.frames[LAST].depth.as_ref().unwrap(),
    );
    let scale = 640.0 / DEPTH_SIZE.0 as f64;
    let dropped = |x: u32, y: u32| {
        let (u, v) = ((x as f64 / scale) as u32, (y as f64 / scale) as u32);
        ((100..140).contains(&u) && (60..100).contains(&v)) || ((10..30).contains(&u) && (10..30).contains(&v))
    };
    let (mut kept, mut close) = (0, 0);
    for (x, y, d) in depth.enumerate_pixels() {
        if dropped(x, y) {
            assert_eq!(d.0[0], 0, "a low-confidence reading at ({x}, {y}) was kept");
        } else if d.0[0] != 0 {
            kept += 1;
            close += usize::from(d.0[0].abs_diff(clip.get_pixel(x, y).0[0]) <= 10);
        }
    }
    assert!(
        close as f64 > 0.9 * kept as f64,
        "{close} of {kept} readings within 1 cm of the clip's"
    );

    // --every and --max-frames pick the same frames as for the clip's own folder, and only
    // those are decoded from the video.
    let opts = ImportOptions {
        every: 2,
        max_frames: Some(3),
        max_size: Some(320),
        ..Default::default()
    };
    let stray = imported(&dir, &opts);
    let own = imported(&ycb, &opts);
    let names: Vec<_> = stray.scene.frames.iter().map(|f| f.source.clone().unwrap()).collect();
    assert_eq!(names, ["000000", "000002", "000004"]);
    // Both downscaled the same pixels the same way.
    assert_same_frames(&stray.scene, &own.scene, 0.0);

    // The page's path (files held in memory) reads the same scene.
    let memory = run_to_end(import_files(
        Rc::new(folder_in_memory(&dir)),
        &opts,
        &mut |_, _| {},
        &mut NoPause,
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(memory.layout, Layout::StrayScanner);
    assert_same_frames(&memory.scene, &own.scene, 0.0);
}

/// As the app records it (lossy HEVC, 4:2:0): frame 0's ground truth carried to frames 1-9
/// through the packing's depth, intrinsics and poses labels them as well as through the clip's
/// own folder (mean IoU within 0.02), and the colours are close.
#[test]
fn a_recorded_video_gives_the_clips_geometry_and_colours() {
    let Some(ycb) = setup() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("recorded");
    write_stray(&ycb, &dir, Video::AsRecorded);
    let opts = ImportOptions {
        max_size: Some(160),
        ..Default::default()
    };
    let own = imported(&ycb, &opts).scene;
    let stray = imported(&dir, &opts).scene;
    assert_same_frames(&stray, &own, 4.0);
    let source = own.frames[0].gt.as_ref().unwrap();
    let classes = own.classes.len();
    let (s, o) = (
        carried_ground_truth_iou(&stray, source, &own, classes),
        carried_ground_truth_iou(&own, source, &own, classes),
    );
    eprintln!(
        "mean IoU of frame 0's ground truth carried to frames 1-9: Stray Scanner layout {s:.4}, own folder {o:.4}"
    );
    assert!(o > 0.5, "frame 0 carries too little to compare: {o}");
    assert!((s - o).abs() <= 0.02, "{s} vs {o}");
}

#[test]
fn bad_captures_are_refused_naming_the_file() {
    let Some(ycb) = setup() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let base = tmp.path().join("base");
    write_stray(&ycb, &base, Video::AsRecorded);
    let fresh = |name: &str| {
        let dir = tmp.path().join(name);
        copy_tree(&base, &dir);
        dir
    };
    let odometry = std::fs::read_to_string(base.join("odometry.csv")).unwrap();

    let dir = fresh("bad-odometry");
    write(&dir.join("odometry.csv"), odometry.replacen(", 3, ", ", 3.5, ", 1));
    let e = error_naming(&dir, "odometry.csv");
    assert!(
        e.contains("line 5") && e.contains("frame = 3.5 is not a frame number"),
        "{e}"
    );
    let mut lines: Vec<&str> = odometry.lines().collect();
    lines[4] = "0.1, 3, 1, 2, 3, 0, 0, 0, 0.5";
    write(&dir.join("odometry.csv"), lines.join("\n"));
    let e = error_naming(&dir, "odometry.csv");
    assert!(e.contains("line 5") && e.contains("not a rotation"), "{e}");

    // Poses of frames the video does not have.
    let dir = fresh("short-video");
    write(
        &dir.join("odometry.csv"),
        format!("{odometry}9.9, 12, 0, 0, 0, 0, 0, 0, 1\n"),
    );
    copy_file(&dir.join("depth/000009.png"), &dir.join("depth/000012.png"));
    copy_file(&dir.join("confidence/000009.png"), &dir.join("confidence/000012.png"));
    let e = error_naming(&dir, "rgb.mp4");
    assert!(e.contains("has 10 frames, but frame 12 is asked for"), "{e}");

    let dir = fresh("not-a-video");
    write(&dir.join("rgb.mp4"), "not a video at all");
    let e = error_naming(&dir, "rgb.mp4");
    assert!(e.contains("not a video ffprobe can read"), "{e}");

    let dir = fresh("no-depth");
    std::fs::remove_file(dir.join("depth/000003.png")).unwrap();
    let e = error_naming(&dir, "depth/000003.png");
    assert!(e.contains("missing") && e.contains("10 poses, depth/ 9 images"), "{e}");

    let dir = fresh("no-confidence");
    std::fs::remove_file(dir.join("confidence/000000.png")).unwrap();
    assert!(error_naming(&dir, "confidence/000000.png").contains("missing"));

    let dir = fresh("bad-confidence");
    save_gray8(&dir.join("confidence/000002.png"), &GrayImage::new(128, 96));
    let e = error_naming(&dir, "confidence/000002.png");
    assert!(e.contains("128x96") && e.contains("256x192"), "{e}");

    let dir = fresh("portrait-camera");
    write(
        &dir.join("camera_matrix.csv"),
        "1066.8,0,241.3\n0,1067.5,512.9\n0,0,1\n",
    );
    let e = error_naming(&dir, "camera_matrix.csv");
    assert!(e.contains("outside the video's 640x480 frames"), "{e}");

    let dir = fresh("no-camera");
    std::fs::remove_file(dir.join("camera_matrix.csv")).unwrap();
    assert!(error_naming(&dir, "camera_matrix.csv").contains("missing"));

    // Without confidence maps every reading is kept, and the user is told.
    let dir = fresh("without-confidence");
    std::fs::remove_dir_all(dir.join("confidence")).unwrap();
    let got = imported(&dir, &ImportOptions::default());
    assert!(
        got.warnings
            .join("\n")
            .contains("no confidence/ folder: every depth reading kept")
    );

    // Depth images beyond the poses (tracking not started) are skipped with a warning.
    let dir = fresh("late-tracking");
    let later: String = odometry
        .lines()
        .take(1)
        .chain(odometry.lines().skip(3))
        .map(|l| format!("{l}\n"))
        .collect();
    write(&dir.join("odometry.csv"), later);
    let got = imported(&dir, &ImportOptions::default());
    assert_eq!(got.scene.frames.len(), 8);
    assert_eq!(got.scene.frames[0].source.as_deref(), Some("000002"));
    assert!(got.warnings.join("\n").contains("skipped 2 depth images with no pose"));
}

/// The browser test's captures (tests/e2e/run.sh): the YCB clip in Stray Scanner's layout as
/// `$STRAY_FIXTURE/ycb-stray` with an H.264 video whose frames carry their number in a corner
/// block of colour (R, 255 - R, 128), R = 25 x the frame's number, which every browser decodes,
/// and as `$STRAY_FIXTURE/ycb-stray-hevc` as the app records it (HEVC).
#[test]
#[ignore = "writes the browser test's captures; run by tests/e2e/run.sh"]
fn write_browser_fixture() {
    let Some(ycb) = setup() else { return };
    let out = std::path::PathBuf::from(std::env::var("STRAY_FIXTURE").expect("STRAY_FIXTURE: where to write"));
    write_stray(&ycb, &out.join("ycb-stray"), Video::Marked);
    write_stray(&ycb, &out.join("ycb-stray-hevc"), Video::AsRecorded);
    assert_eq!(marker(3), [75, 180, 128], "tests/e2e/stray.mjs expects these colours");
}

/// Without ffmpeg on PATH, `pack` says what it needs and how to get it.
#[test]
fn packing_without_ffmpeg_names_it() {
    let Some(ycb) = setup() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("capture");
    write_stray(&ycb, &dir, Video::AsRecorded);
    let out = Command::new(env!("CARGO_BIN_EXE_scribblefield"))
        .arg("pack")
        .arg(&dir)
        .arg("-o")
        .arg(tmp.path().join("x.scene.zip"))
        .env("PATH", tmp.path().join("nothing-here"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("rgb.mp4") && e.contains("needs ffmpeg and ffprobe on PATH") && e.contains("apt-get install ffmpeg"),
        "{e}"
    );
}

/// The page seeks frame `n` by the time the MP4's index gives it: those times must be where
/// ffmpeg shows each frame, B-frames and edit lists included, for H.264 (what the browser test
/// encodes) and HEVC (what the app records).
#[test]
fn mp4_frame_times_agree_with_ffprobe() {
    let Some(ycb) = setup() else { return };
    let tmp = tempfile::tempdir().unwrap();
    for (codec, params) in [("libx264", "-x264-params"), ("libx265", "-x265-params")] {
        let video = tmp.path().join(format!("{codec}.mp4"));
        let status = Command::new("ffmpeg")
            .args(["-v", "error", "-y", "-framerate", "30", "-i"])
            .arg(ycb.join("rgb/%05d.png"))
            .args([
                "-c:v",
                codec,
                params,
                "log-level=error:bframes=3",
                "-pix_fmt",
                "yuv420p",
            ])
            .arg(&video)
            .status()
            .unwrap();
        assert!(status.success());
        let out = Command::new("ffprobe")
            .args([
                "-v",
                "error",
                "-select_streams",
                "v:0",
                "-show_entries",
                "frame=best_effort_timestamp_time",
            ])
            .args(["-of", "csv=p=0"])
            .arg(&video)
            .output()
            .unwrap();
        let shown: Vec<f64> = String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter_map(|l| l.trim().trim_end_matches(',').parse().ok())
            .collect();
        let (size, times) =
            scribblefield::scene::import::text_checks::mp4_video(&std::fs::read(&video).unwrap()).unwrap();
        assert_eq!(size, (640, 480), "{codec}");
        assert_eq!(times.len(), FRAMES, "{codec}");
        assert_eq!(shown.len(), FRAMES, "{codec}: {shown:?}");
        for (i, (t, s)) in times.iter().zip(&shown).enumerate() {
            assert!(
                (t - s).abs() < 1e-3,
                "{codec} frame {i}: {t} s from the index, {s} s by ffprobe"
            );
        }
    }
}

fn copy_tree(from: &Path, to: &Path) {
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let dst = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_tree(&path, &dst);
        } else {
            copy_file(&path, &dst);
        }
    }
}
