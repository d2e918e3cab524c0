//! Class lists for imported ground truth and labels, with distinct display colours.
use crate::labels::ClassInfo;

/// Hand-picked colours that stay tellable apart on photos and from each other.
const PALETTE: [[u8; 3]; 12] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [188, 189, 34],
    [23, 190, 207],
    [127, 127, 127],
    [255, 221, 51],
    [0, 92, 49],
];

/// A distinct colour for class `i`: the palette first, then hues spaced by the golden angle.
pub(super) fn class_color(i: usize) -> [u8; 3] {
    if let Some(c) = PALETTE.get(i) {
        return *c;
    }
    let hue = (i as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (s, v) = (0.75, 0.9);
    let f = hue.fract();
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match hue as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    [
        (r * 255.0).round() as u8,
        (g * 255.0).round() as u8,
        (b * 255.0).round() as u8,
    ]
}

pub(super) fn class_infos(names: impl IntoIterator<Item = String>) -> Vec<ClassInfo> {
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| ClassInfo {
            name,
            color: class_color(i),
        })
        .collect()
}

/// Placeholder names for `count` classes known only by id.
pub(super) fn numbered(count: usize) -> Vec<String> {
    (0..count).map(|i| format!("class {i}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_distinct() {
        let colors: Vec<[u8; 3]> = (0..64).map(class_color).collect();
        for (i, a) in colors.iter().enumerate() {
            for b in &colors[..i] {
                assert_ne!(a, b);
            }
        }
    }
}
