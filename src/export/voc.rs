//! The CVAT / PASCAL VOC segmentation layout, as CVAT's "Segmentation mask" export writes it
//! and imports it: `labelmap.txt` (`# label:color_rgb:parts:actions`, one class a line),
//! `SegmentationClass/<frame>.png` and `ImageSets/Segmentation/default.txt` (the frames).
//! Each PNG is palette-indexed: the index of a pixel is its class id (what PASCAL VOC loaders
//! read) and the palette gives each id its class's colour (what CVAT and Datumaro read back to
//! a class through labelmap.txt), so classes must have colours of their own.
use std::borrow::Cow;

use image::GrayImage;

use super::error::ExportError;
use crate::labels::ClassInfo;

/// The layout's folder in an export.
pub const DIR: &str = "voc";
pub const LABELMAP: &str = "labelmap.txt";
pub const CLASS_DIR: &str = "SegmentationClass";
pub const SUBSET_LIST: &str = "ImageSets/Segmentation/default.txt";

/// Checks that `classes` can be written: distinct colours, names labelmap.txt can hold.
pub fn check_classes(classes: &[ClassInfo]) -> Result<(), ExportError> {
    for (i, c) in classes.iter().enumerate() {
        let problem = if c.name.is_empty() {
            Some("it is empty")
        } else if c.name.contains(':') {
            Some("':' separates its fields")
        } else if c.name.contains(',') {
            Some("',' separates parts and actions")
        } else if c.name.starts_with('#') {
            Some("a line starting with '#' is a comment")
        } else if c.name.chars().any(char::is_control) || c.name.trim() != c.name {
            Some("line breaks, control characters and surrounding spaces are lost")
        } else {
            None
        };
        if let Some(problem) = problem {
            return Err(ExportError::LabelmapName {
                name: c.name.clone(),
                problem,
            });
        }
        if let Some(other) = classes[..i].iter().find(|o| o.color == c.color) {
            return Err(ExportError::SharedColour {
                first: other.name.clone(),
                second: c.name.clone(),
                color: c.color,
            });
        }
    }
    Ok(())
}

/// `labelmap.txt` of `classes`, in class id order.
pub fn labelmap(classes: &[ClassInfo]) -> String {
    let mut s = String::from("# label:color_rgb:parts:actions\n");
    for c in classes {
        let [r, g, b] = c.color;
        s.push_str(&format!("{}:{r},{g},{b}::\n", c.name));
    }
    s
}

/// `mask` (class ids, each below `classes.len()`) as a palette-indexed PNG whose palette is
/// the class colours.
pub fn palette_png(mask: &GrayImage, classes: &[ClassInfo]) -> Vec<u8> {
    let palette: Vec<u8> = classes.iter().flat_map(|c| c.color).collect();
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, mask.width(), mask.height());
    encoder.set_color(png::ColorType::Indexed);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_palette(Cow::Owned(palette));
    let write = || -> Result<(), png::EncodingError> {
        let mut writer = encoder.write_header()?;
        writer.write_image_data(mask.as_raw())?;
        writer.finish()
    };
    write().expect("PNG encoding into memory cannot fail");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn class(name: &str, color: [u8; 3]) -> ClassInfo {
        ClassInfo {
            name: name.into(),
            color,
        }
    }

    #[test]
    fn the_palette_png_holds_class_ids_and_colours() {
        let classes = [
            class("floor", [10, 20, 30]),
            class("chair", [200, 0, 7]),
            class("cup", [0, 0, 0]),
        ];
        let mask = GrayImage::from_fn(7, 3, |x, y| image::Luma([((x + y) % 3) as u8]));
        let bytes = palette_png(&mask, &classes);
        let mut reader = png::Decoder::new(std::io::Cursor::new(&bytes)).read_info().unwrap();
        assert_eq!(reader.info().color_type, png::ColorType::Indexed);
        assert_eq!(
            reader.info().palette.as_deref(),
            Some(&[10, 20, 30, 200, 0, 7, 0, 0, 0][..])
        );
        let mut ids = vec![0; reader.output_buffer_size().unwrap()];
        reader.next_frame(&mut ids).unwrap();
        assert_eq!(ids, mask.as_raw().as_slice());
        // What a reader that expands the palette (CVAT, OpenCV) sees.
        let rgb = image::load_from_memory(&bytes).unwrap().into_rgb8();
        assert_eq!(rgb.get_pixel(1, 0).0, [200, 0, 7]);
    }

    #[test]
    fn labelmap_lines_and_refusals() {
        let classes = [class("background", [0, 0, 0]), class("mug", [255, 128, 1])];
        assert_eq!(
            labelmap(&classes),
            "# label:color_rgb:parts:actions\nbackground:0,0,0::\nmug:255,128,1::\n"
        );
        check_classes(&classes).unwrap();
        let err = check_classes(&[class("a", [1, 2, 3]), class("b", [1, 2, 3])])
            .unwrap_err()
            .to_string();
        assert!(err.contains("\"a\" and \"b\"") && err.contains("[1, 2, 3]"), "{err}");
        let err = check_classes(&[class("cup:red", [1, 2, 3])]).unwrap_err().to_string();
        assert!(err.contains("\"cup:red\"") && err.contains("':'"), "{err}");
        let err = check_classes(&[class("a\nb", [1, 2, 3])]).unwrap_err().to_string();
        assert!(err.contains("line breaks"), "{err}");
    }
}
