//! Distinct display colours, one rule for every place that needs "a colour for item i": classes
//! imported without colours, classes added in the app, ids a scene does not name, plot lines.
//! The first ones are hand-picked to stay tellable apart on photos and from each other.
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

/// Colour `i`: the palette first, then hues spaced by the golden angle (never repeating).
pub fn distinct_color(i: usize) -> [u8; 3] {
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

/// The first distinct colour that none of `taken` uses (for a class added next to others).
pub fn unused_color(taken: &[[u8; 3]]) -> [u8; 3] {
    (0..)
        .map(distinct_color)
        .find(|c| !taken.contains(c))
        .expect("the golden-angle hues never run out")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_distinct() {
        let colors: Vec<[u8; 3]> = (0..64).map(distinct_color).collect();
        for (i, a) in colors.iter().enumerate() {
            for b in &colors[..i] {
                assert_ne!(a, b);
            }
        }
    }

    #[test]
    fn unused_colour_skips_taken_ones() {
        assert_eq!(unused_color(&[]), distinct_color(0));
        assert_eq!(unused_color(&[distinct_color(0), distinct_color(2)]), distinct_color(1));
    }
}
