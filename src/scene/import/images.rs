//! Decoding a capture's image files with size limits, checking each is the kind of image its
//! role needs (colour, 16-bit depth, 8-bit class ids) and naming the file when it is not.
use std::path::Path;

use image::{DynamicImage, GrayImage, ImageReader, RgbImage};

use super::Background;
use super::resize::Mask16;
use crate::scene::DepthImage;
use crate::scene::archive::limits;
use crate::scene::error::{Result, SceneError};

/// Bytes searched at the end of a JPEG for its end-of-image marker.
const JPEG_TAIL: usize = 1024;
/// Largest image file read: as an archive's image entry, the largest frame at 8 bytes a pixel
/// (16-bit RGBA, stored) and 1 MiB of headers.
pub(super) const MAX_IMAGE_FILE_BYTES: u64 = limits::MAX_SIDE as u64 * limits::MAX_SIDE as u64 * 8 + (1 << 20);

fn name(path: &Path) -> String {
    path.display().to_string()
}

/// An image file's bytes, through the cap; an empty file is named as such.
fn read_image_file(path: &Path) -> Result<Vec<u8>> {
    let bytes = super::files::read(path, MAX_IMAGE_FILE_BYTES).map_err(|e| SceneError::io(path, e))?;
    if bytes.is_empty() {
        return Err(SceneError::invalid(name(path), "image file is empty"));
    }
    Ok(bytes)
}

/// Decodes any supported image, refusing absurd sizes before allocating.
pub(super) fn decode(path: &Path) -> Result<DynamicImage> {
    let bytes = read_image_file(path)?;
    let mut reader = ImageReader::new(std::io::Cursor::new(&bytes[..]))
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?;
    if reader.format() == Some(image::ImageFormat::Jpeg) {
        check_jpeg_complete(&bytes, path)?;
    }
    let mut lim = image::Limits::default();
    lim.max_image_width = Some(limits::MAX_SIDE);
    lim.max_image_height = Some(limits::MAX_SIDE);
    lim.max_alloc = Some(limits::MAX_SIDE as u64 * limits::MAX_SIDE as u64 * 8);
    reader.limits(lim);
    reader.decode().map_err(|source| SceneError::Image {
        file: name(path),
        source,
    })
}

/// The JPEG decoder fills a cut-off file with grey instead of failing, so a truncated JPEG
/// (a copy interrupted half way) would be imported silently; its missing end marker gives it away.
fn check_jpeg_complete(bytes: &[u8], path: &Path) -> Result<()> {
    let tail = &bytes[bytes.len().saturating_sub(JPEG_TAIL)..];
    if tail.windows(2).any(|w| w == [0xFF, 0xD9]) {
        Ok(())
    } else {
        Err(SceneError::invalid(
            name(path),
            "JPEG is truncated (no end-of-image marker)",
        ))
    }
}

/// Width and height from the image header, without decoding the pixels.
pub(super) fn dimensions(path: &Path) -> Result<(u32, u32)> {
    let bytes = read_image_file(path)?;
    let reader = ImageReader::new(std::io::Cursor::new(&bytes[..]))
        .with_guessed_format()
        .map_err(|e| SceneError::io(path, e))?;
    reader.into_dimensions().map_err(|source| SceneError::Image {
        file: name(path),
        source,
    })
}

/// Colour image as 8-bit RGB, and whether the file had an alpha channel; transparent pixels are
/// composited on `background` (NeRF's synthetic scenes have transparent backgrounds).
pub(super) fn load_rgb(path: &Path, background: Background) -> Result<(RgbImage, bool)> {
    let img = decode(path)?;
    if !img.color().has_alpha() {
        return Ok((img.into_rgb8(), false));
    }
    let rgba = img.into_rgba8();
    let b = background.value() as u32;
    Ok((
        RgbImage::from_fn(rgba.width(), rgba.height(), |x, y| {
            let p = rgba.get_pixel(x, y).0;
            let a = p[3] as u32;
            let over = |c: u8| ((c as u32 * a + b * (255 - a) + 127) / 255) as u8;
            image::Rgb([over(p[0]), over(p[1]), over(p[2])])
        }),
        true,
    ))
}

/// Depth must be a 16-bit single-channel image: an 8-bit one has lost its millimetres.
pub(super) fn load_depth(path: &Path) -> Result<DepthImage> {
    match decode(path)? {
        DynamicImage::ImageLuma16(d) => Ok(d),
        other => Err(SceneError::invalid(
            name(path),
            format!(
                "depth must be a 16-bit single-channel PNG (millimetres), got {:?}",
                other.color()
            ),
        )),
    }
}

/// Dense ground truth: 8-bit single-channel class ids.
pub(super) fn load_gt(path: &Path) -> Result<GrayImage> {
    match decode(path)? {
        DynamicImage::ImageLuma8(g) => Ok(g),
        other => Err(SceneError::invalid(
            name(path),
            format!(
                "ground truth must be an 8-bit single-channel PNG of class ids, got {:?}",
                other.color()
            ),
        )),
    }
}

/// A label mask of 8- or 16-bit single-channel values, widened to u16.
pub(super) fn load_mask(path: &Path) -> Result<Mask16> {
    match decode(path)? {
        DynamicImage::ImageLuma8(g) => Ok(image::ImageBuffer::from_fn(g.width(), g.height(), |x, y| {
            image::Luma([g.get_pixel(x, y).0[0] as u16])
        })),
        DynamicImage::ImageLuma16(g) => Ok(g),
        other => Err(SceneError::invalid(
            name(path),
            format!(
                "label mask must be an 8- or 16-bit single-channel PNG, got {:?}",
                other.color()
            ),
        )),
    }
}
