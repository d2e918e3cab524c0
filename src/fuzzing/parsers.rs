//! Entry points for the parsers added after the first fuzzing round: PyTorch checkpoints (the
//! zip and the pickle in it), COLMAP's binary model, ScanNet's text files, trainer checkpoints,
//! `--config` JSON and a capture zip as the page packs it. As in the parent module, a refusal is
//! `Err` and a panic or a broken limit is a finding.
use std::rc::Rc;

use super::{Outcome, assert_scene_within_limits, split_on};
use crate::features::pth::{Pth, PthLimits};
use crate::field::{ParamLayout, Preset};
use crate::pause::{NoPause, run_to_end};
use crate::saved_field::{Checkpoint, MAX_PARAMS, TrainedOn};
use crate::scene::import::{ImportOptions, MemoryFiles, import_files, text_checks};

/// Limits of the `.pth` targets: far below the defaults, so a fuzzed input that reaches them is
/// refused in microseconds, and far above what the seeds need.
fn pth_limits() -> PthLimits {
    PthLimits {
        pickle_bytes: 1 << 20,
        storage_bytes: 16 << 20,
        pickle: crate::features::pth::PickleLimits {
            built_bytes: 16 << 20,
            depth: 64,
        },
    }
}

/// Every tensor of an opened checkpoint read at its own shape, within the storage budget.
fn read_all(p: &Pth, limits: &PthLimits) -> Outcome {
    let names: Vec<String> = p.names().map(String::from).collect();
    let mut refused = Vec::new();
    let mut values = 0usize;
    for name in &names {
        let shape = p.shape(name).map(<[usize]>::to_vec).unwrap_or_default();
        match p.f32(name, &shape) {
            Ok(v) => values += v.len(),
            Err(e) => refused.push(e.to_string()),
        }
    }
    // Each value costs at least one byte of storage read, and reads stop at the budget.
    assert!(values as u64 <= limits.storage_bytes, "{values} values read");
    if refused.is_empty() {
        Ok(())
    } else {
        Err(refused.join("; "))
    }
}

/// A `.pth` file as `torch.save` writes it (a zip), opened and every tensor read.
pub fn pth(data: &[u8]) -> Outcome {
    let limits = pth_limits();
    let p = Pth::from_bytes_with("fuzz.pth", data.to_vec(), limits).map_err(|e| e.to_string())?;
    read_all(&p, &limits)
}

/// Storages every [`pickle`] input can name: keys `0` to `3`, 64 bytes each.
const PICKLE_STORAGES: usize = 4;

/// Limits of the `pickle` target: lower again than [`pth_limits`], since its inputs reach the
/// pickle machine's budgets far more often than whole zips do.
fn pickle_limits() -> PthLimits {
    PthLimits {
        pickle_bytes: 1 << 20,
        storage_bytes: 1 << 16,
        pickle: crate::features::pth::PickleLimits {
            built_bytes: 1 << 20,
            depth: 64,
        },
    }
}

/// The pickle of a `.pth` (`data.pkl`), zipped here with [`PICKLE_STORAGES`] storages: mutations
/// of a zip's bytes mostly break it, these reach the pickle machine and the state dict.
pub fn pickle(data: &[u8]) -> Outcome {
    use std::io::Write;
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let mut entries: Vec<(String, &[u8])> = vec![("archive/data.pkl".into(), data)];
    let storage = [0u8; 64];
    for key in 0..PICKLE_STORAGES {
        entries.push((format!("archive/data/{key}"), &storage));
    }
    for (name, bytes) in entries {
        zip.start_file(name, stored).map_err(|e| format!("zip writer: {e}"))?;
        zip.write_all(bytes).map_err(|e| format!("zip writer: {e}"))?;
    }
    let bytes = zip.finish().map_err(|e| format!("zip writer: {e}"))?.into_inner();
    let limits = pickle_limits();
    let p = Pth::from_bytes_with("fuzz.pth", bytes, limits).map_err(|e| e.to_string())?;
    read_all(&p, &limits)
}

/// Marks the start of the next file in a multi-file binary input (COLMAP's three files).
pub const NEXT_FILE: &[u8] = b"--next-file--";

/// A COLMAP binary model: `cameras.bin`, `images.bin`, `points3D.bin` separated by
/// [`NEXT_FILE`] (missing parts are empty files, which are refused).
pub fn colmap_binary(data: &[u8]) -> Outcome {
    let mut parts = split_on(data, NEXT_FILE);
    let cameras = parts.next().unwrap_or(&[]);
    let images = parts.next().unwrap_or(&[]);
    let points = parts.next().unwrap_or(&[]);
    text_checks::colmap_binary(cameras, images, points)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// One ScanNet text file, read as a pose (`pose/N.txt`) and as colour intrinsics for 640 x 480
/// frames.
pub fn scannet_text(data: &[u8]) -> Outcome {
    let pose = text_checks::scannet_pose(data).map_err(|e| e.to_string());
    if let Ok(Some(p)) = &pose {
        assert!(
            p.to_row_major().iter().all(|v| (*v as f32).is_finite()),
            "accepted a pose that is infinite as f32"
        );
    }
    let k = text_checks::scannet_intrinsics(data, (640, 480)).map_err(|e| e.to_string());
    if let Ok(k) = &k {
        for v in [k.fx, k.fy, k.cx, k.cy] {
            assert!((v as f32).is_finite(), "intrinsics {v} not finite as f32");
        }
    }
    match (pose, k) {
        (Err(a), Err(b)) => Err(format!("{a}; {b}")),
        _ => Ok(()),
    }
}

/// A Stray Scanner text file, read as `odometry.csv` and as `camera_matrix.csv`.
pub fn stray_text(data: &[u8]) -> Outcome {
    let rows = text_checks::stray_odometry(data).map_err(|e| e.to_string());
    if let Ok(rows) = &rows {
        for (_, pose) in rows {
            assert!(
                pose.check().is_ok(),
                "accepted a pose that is not rigid or not finite as f32"
            );
        }
    }
    let k = text_checks::stray_camera_matrix(data).map_err(|e| e.to_string());
    if let Ok(k) = &k {
        for v in [k.fx, k.fy, k.cx, k.cy] {
            assert!((v as f32).is_finite(), "intrinsics {v} not finite as f32");
        }
    }
    match (rows, k) {
        (Err(a), Err(b)) => Err(format!("{a}; {b}")),
        _ => Ok(()),
    }
}

/// The `mp4` target's frame cap: far below a capture's (two million), so that inputs whose few
/// bytes of `stts` claim the whole cap are refused in microseconds; the same code checks both.
const MP4_FRAMES: u64 = 4096;

/// An MP4's index as the page reads it to seek a capture's video (with [`MP4_FRAMES`] as the
/// frame cap): the frame size and the time of each frame, in order.
pub fn mp4(data: &[u8]) -> Outcome {
    let (size, times) = text_checks::mp4_video_capped(data, MP4_FRAMES).map_err(|e| e.to_string())?;
    assert!(size.0 > 0 && size.1 > 0, "accepted frames of {size:?}");
    // Run-length coding lets a few bytes claim many frames: the index's frame cap bounds them.
    assert!(times.len() as u64 <= MP4_FRAMES, "{} frames accepted", times.len());
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "frame times out of order");
    Ok(())
}

/// A trainer checkpoint as `export` reads it: the safetensors file, its metadata (config, what
/// it was trained on) and every tensor.
pub fn checkpoint(data: &[u8]) -> Outcome {
    let c = Checkpoint::from_bytes("fuzz.safetensors", data.to_vec()).map_err(|e| e.to_string())?;
    let total = ParamLayout::new(&c.config).total;
    assert!(total <= MAX_PARAMS, "accepted a config of {total} parameters");
    for part in [&c.state.params, &c.state.first_moment, &c.state.second_moment] {
        assert_eq!(part.len(), total, "a tensor part of another size than the layout");
        assert!(
            part.iter().all(|v| v.is_finite()),
            "accepted a value that is not finite"
        );
    }
    TrainedOn::from_checkpoint("fuzz.safetensors", &c)
        .map(|_| ())
        .map_err(|e| e.to_string())
}

/// A `--config` JSON applied to the `budget` preset and validated, as the commands do.
pub fn field_config(data: &[u8]) -> Outcome {
    let changes: serde_json::Value = serde_json::from_slice(data).map_err(|e| e.to_string())?;
    let base = Preset::parse("budget").ok_or("no budget preset")?.config();
    let config = base.with_changes(&changes)?;
    config.validate().map_err(|e| e.to_string())
}

/// A zip of a capture folder, as the page packs one: unpacked in memory, the layout detected and
/// imported at most 4 frames of at most 64 px.
pub fn pack_zip(data: &[u8]) -> Outcome {
    let files = MemoryFiles::from_zip("capture.zip", data).map_err(|e| e.to_string())?;
    let opts = ImportOptions {
        max_size: Some(64),
        max_frames: Some(4),
        ..ImportOptions::default()
    };
    let imported =
        run_to_end(import_files(Rc::new(files), &opts, &mut |_, _| {}, &mut NoPause)).map_err(|e| e.to_string())?;
    assert_scene_within_limits(&imported.scene);
    assert!(
        !imported.scene.provenance.source.contains(['/', '\\']),
        "provenance names a path, not the capture's folder: {}",
        imported.scene.provenance.source
    );
    Ok(())
}
