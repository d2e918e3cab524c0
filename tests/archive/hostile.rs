//! Archives crafted to exhaust memory or to slip past the checks: each is small on disk and
//! refused with an error that names the entry and the limit.
use super::*;
use scribblefield::scene::archive::limits;

/// A scene like the tiny one at `w` x `h` with zero feature codes of `dim` on the full grid.
fn scene_with_zero_features(w: u32, h: u32, dim: u32) -> Scene {
    let mut scene = tiny_scene();
    scene.width = w;
    scene.height = h;
    for f in &mut scene.frames {
        f.rgb = RgbImage::new(w, h);
        f.depth = Some(ImageBuffer::new(w, h));
        f.gt = Some(GrayImage::new(w, h));
    }
    let features = scene.features.as_mut().unwrap();
    features.width = w;
    features.height = h;
    features.dim = dim;
    features.pca.mean = vec![0.0; dim as usize];
    features.pca.components = std::array::from_fn(|_| vec![0.0; dim as usize]);
    features.data = vec![f16::ZERO; (3 * w * h * dim) as usize];
    scene.labels = None;
    scene
}

#[test]
fn duplicate_entry_names_are_refused_naming_the_entry() {
    let mut e = entries(&write_archive_bytes(&tiny_scene()).unwrap());
    let copy = e.iter().find(|(n, _)| n == "rgb/00000.png").unwrap().1.clone();
    e.push(("rgb/0000X.png".into(), copy));
    // The zip writer refuses duplicate names, so the name is changed in the bytes afterwards
    // (local header and central directory alike; the CRC covers only the data).
    let mut bytes = repack(&e);
    let (from, to) = (b"rgb/0000X.png", b"rgb/00000.png");
    let mut i = 0;
    while i + from.len() <= bytes.len() {
        if &bytes[i..i + from.len()] == from {
            bytes[i..i + from.len()].copy_from_slice(to);
        }
        i += 1;
    }
    let err = read_archive(&bytes, "dup.scene.zip").unwrap_err().to_string();
    assert_mentions(
        &err,
        &["dup.scene.zip", "entry \"rgb/00000.png\" appears more than once"],
    );
}

#[test]
fn frames_sharing_one_image_entry_are_refused_naming_both() {
    // The case first reported: many large frames decoding one small image.
    let err = error_after(|e| {
        edit_manifest(e, |m| {
            m["frames"][2]["rgb"] = "rgb/00000.png".into();
        })
    });
    assert_mentions(
        &err,
        &[
            "scene.json",
            "entry \"rgb/00000.png\" is used as both the colour of frame 0 and the colour of frame 2",
        ],
    );
    let err = error_after(|e| edit_manifest(e, |m| m["frames"][1]["gt"] = "depth/00001.png".into()));
    assert_mentions(
        &err,
        &[
            "depth/00001.png",
            "the depth of frame 1 and the ground truth of frame 1",
        ],
    );
    let err = error_after(|e| edit_manifest(e, |m| m["labels"] = "scene.json".into()));
    assert_mentions(&err, &["the labels is entry \"scene.json\", the manifest itself"]);
}

#[test]
fn the_decoded_size_budget_is_checked_from_the_manifest_before_reading() {
    // 8 frames of 8192 x 8192 with depth and ground truth (3 GiB) and 2 GiB of feature codes:
    // only scene.json is in the archive, so the refusal must come before any image is read.
    let err = error_after(|e| {
        edit_manifest(e, |m| {
            m["width"] = 8192.into();
            m["height"] = 8192.into();
            let frames: Vec<serde_json::Value> = (0..8)
                .map(|i| {
                    let mut f = m["frames"][0].clone();
                    f["rgb"] = format!("rgb/{i}.png").into();
                    f["depth"] = format!("depth/{i}.png").into();
                    f["gt"] = format!("gt/{i}.png").into();
                    f
                })
                .collect();
            m["frames"] = frames.into();
            m["frame_count"] = 8.into();
            m["features"]["width"] = 1024.into();
            m["features"]["height"] = 1024.into();
            m["features"]["dim"] = 128.into();
            m["features"]["pca"]["mean"] = serde_json::json!(vec![0.0; 128]);
            m["features"]["pca"]["components"] = serde_json::json!(vec![vec![0.0; 128]; 3]);
        });
        e.retain(|(n, _)| n == "scene.json");
    });
    let budget = limits::MAX_DECODED_BYTES.to_string();
    assert_mentions(
        &err,
        &[
            "scene.json",
            "decodes to 5368709120 bytes (3221225472 of images, 2147483648 of feature codes)",
            &format!("budget of {budget} bytes"),
        ],
    );
}

#[test]
fn an_image_entry_that_inflates_over_the_ratio_cap_is_refused_naming_it() {
    // 4 MiB of zeros deflate to about 4 KB: a ratio over 1000:1, refused before any decoding.
    // The frames are 1024 x 1024 so that 4 MiB is within what a frame's PNG may take.
    let mut e = entries(&write_archive_bytes(&scene_with_zero_features(1024, 1024, 1)).unwrap());
    let rgb = e.iter_mut().find(|(n, _)| n == "rgb/00001.png").unwrap();
    rgb.1 = vec![0; 4 << 20];
    let err = read_archive(&repack(&e), "bad.scene.zip").unwrap_err().to_string();
    assert_mentions(
        &err,
        &[
            "bad.scene.zip:rgb/00001.png",
            "4194304 bytes from",
            "over the limit of 1000:1",
        ],
    );
}

#[test]
fn near_constant_feature_codes_read_back_however_well_they_compress() {
    // 24 MiB of zero codes deflate to about 25 KB, a ratio over 1000:1; their size is fixed by
    // scene.json and inside the budget, so they are no bomb, and what `pack` wrote must read.
    let scene = scene_with_zero_features(64, 64, 1024);
    let bytes = write_archive_bytes(&scene).unwrap();
    assert!(bytes.len() < 1 << 20, "{} bytes", bytes.len());
    assert_eq!(read_archive(&bytes, "zeros.scene.zip").unwrap(), scene);
}

#[test]
fn feature_codes_round_trip_through_the_streaming_decoder() {
    // Non-zero codes across several read blocks, including an odd split.
    let mut scene = scene_with_zero_features(40, 30, 64);
    let features = scene.features.as_mut().unwrap();
    for (i, v) in features.data.iter_mut().enumerate() {
        *v = f16::from_f32((i % 977) as f32 * 0.01 - 4.0);
    }
    let back = read_archive(&write_archive_bytes(&scene).unwrap(), "codes").unwrap();
    assert_eq!(back.features, scene.features);
    let err = error_after(|e| {
        let f = e.iter_mut().find(|(n, _)| n == "features.f16").unwrap();
        f.1[6..8].copy_from_slice(&f16::NAN.to_le_bytes());
    });
    assert_mentions(&err, &["features.f16", "non-finite"]);
}

/// CRC-32 of PNG chunks.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= b as u32;
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A PNG whose header claims `w` x `h` (8-bit grey) with one tiny, useless data chunk.
fn png_header_only(w: u32, h: u32) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut chunk = |kind: &[u8], data: &[u8]| {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    let mut ihdr = w.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
    chunk(b"IHDR", &ihdr);
    chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
    chunk(b"IEND", &[]);
    out
}

#[test]
fn image_headers_are_checked_before_pixels_are_decoded() {
    let err = error_after(|e| {
        e.iter_mut().find(|(n, _)| n == "gt/00001.png").unwrap().1 = png_header_only(8192, 8192);
    });
    assert_mentions(
        &err,
        &[
            "gt/00001.png",
            "image is 8192 x 8192, but the scene's frames are 12 x 9",
        ],
    );
    // The right size but the wrong pixel type is refused from the header too.
    let err = error_after(|e| {
        e.iter_mut().find(|(n, _)| n == "depth/00001.png").unwrap().1 = png_header_only(W, H);
    });
    assert_mentions(
        &err,
        &["depth/00001.png", "depth must be a 16-bit single-channel PNG, got L8"],
    );
}

#[test]
fn ground_truth_ids_are_checked_against_the_classes() {
    let bad_gt = {
        let mut g = GrayImage::from_pixel(W, H, image::Luma([1]));
        g.put_pixel(4, 5, image::Luma([200]));
        let mut out = Cursor::new(Vec::new());
        g.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    };
    let err = error_after(|e| e.iter_mut().find(|(n, _)| n == "gt/00002.png").unwrap().1 = bad_gt);
    assert_mentions(
        &err,
        &[
            "gt/00002.png",
            "frame 2: ground-truth class id 200 at pixel (4, 5), but the scene has 3 classes",
        ],
    );
    // The writer (and so pack) refuses them too.
    let mut scene = tiny_scene();
    scene.frames[1].gt.as_mut().unwrap().put_pixel(0, 3, image::Luma([3]));
    let err = write_archive_bytes(&scene).unwrap_err().to_string();
    assert_mentions(
        &err,
        &["frame 1: ground-truth class id 3 at pixel (0, 3), but the scene has 3 classes"],
    );
}

#[test]
fn values_that_overflow_or_vanish_as_f32_are_refused_naming_the_field() {
    let err = error_after(|e| edit_manifest(e, |m| m["intrinsics"]["fx"] = 1e-300.into()));
    assert_mentions(
        &err,
        &["scene.json", "intrinsics fx = 1e-300 is too small for a 32-bit float"],
    );
    let err = error_after(|e| edit_manifest(e, |m| m["intrinsics"]["cy"] = 1e300.into()));
    assert_mentions(&err, &["intrinsics cy = 1e300 is outside the 32-bit float range"]);
    let err = error_after(|e| edit_manifest(e, |m| m["bounds"]["max"][2] = 1e301.into()));
    assert_mentions(
        &err,
        &["scene.json", "bounds max.z = 1e301 is outside the 32-bit float range"],
    );
    let err = error_after(|e| {
        edit_manifest(e, |m| {
            m["bounds"]["min"][0] = 1.0.into();
            m["bounds"]["max"][0] = (1.0 + 1e-12).into();
        })
    });
    assert_mentions(
        &err,
        &["bounds min.x = 1 and max.x = 1.000000000001 are equal as 32-bit floats"],
    );
    let err = error_after(|e| edit_manifest(e, |m| m["depth_scale"] = 1e-300.into()));
    assert_mentions(&err, &["depth_scale = 1e-300 is too small for a 32-bit float"]);
    let err = error_after(|e| edit_manifest(e, |m| m["depth_scale"] = 1e300.into()));
    assert_mentions(&err, &["scene depth_scale = 1e300 is outside the 32-bit float range"]);
}
